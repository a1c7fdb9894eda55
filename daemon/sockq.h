/* What the kernel holds of an answer on a TCP socket (sockq.c): kept apart
 * from conns.c because Linux's own <linux/tcp.h>, whose tcp_info has the
 * acknowledged byte count, cannot be included beside glibc's
 * <netinet/tcp.h>. */
#ifndef VX_SOCKQ_H
#define VX_SOCKQ_H

#include <stdint.h>

/* The bytes the client has acknowledged on fd (the whole connection's)
 * while bytes of the answer wait unsent in the kernel (the client's
 * receive window is full); -1 when none wait, or fd is not TCP. */
int64_t vx_sockq_acked_while_waiting(int fd);
/* The same while any byte of the answer is unacknowledged, sent or not
 * (a client gone without a word: what is in flight is never acknowledged);
 * -1 when none is. */
int64_t vx_sockq_acked_while_outstanding(int fd);
/* The bytes fd's kernel still holds to send or to see acknowledged; -1 on
 * an error. */
int64_t vx_sockq_queued(int fd);
/* The bytes the client has acknowledged on fd (the whole connection's,
 * heads included); -1 when fd is not TCP. */
int64_t vx_sockq_acked(int fd);

#endif
