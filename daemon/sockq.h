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
/* The bytes the client has acknowledged on fd (the whole connection's,
 * heads included); -1 when fd is not TCP. */
int64_t vx_sockq_acked(int fd);

#endif
