/* What the kernel holds of an answer on a TCP socket (sockq.h). */
#include "sockq.h"

#include <linux/sockios.h>
#include <linux/tcp.h>
#include <netinet/in.h>
#include <stddef.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>

int64_t vx_sockq_acked_while_waiting(int fd)
{
    /* unsent bytes, not the sent but unacknowledged ones: those are the
     * network's time, not the client's */
    int unsent = 0;
    if (ioctl(fd, SIOCOUTQNSD, &unsent) != 0 || unsent <= 0) return -1;
    return vx_sockq_acked(fd);
}

int64_t vx_sockq_acked_while_outstanding(int fd)
{
    return vx_sockq_queued(fd) > 0 ? vx_sockq_acked(fd) : -1;
}

int64_t vx_sockq_queued(int fd)
{
    int queued = 0;
    return ioctl(fd, SIOCOUTQ, &queued) == 0 ? queued : -1;
}

int64_t vx_sockq_acked(int fd)
{
    struct tcp_info ti;
    socklen_t tl = sizeof ti;
    memset(&ti, 0, sizeof ti);
    if (getsockopt(fd, IPPROTO_TCP, TCP_INFO, &ti, &tl) != 0 ||
        tl < offsetof(struct tcp_info, tcpi_bytes_acked) + sizeof ti.tcpi_bytes_acked)
        return -1;
    return (int64_t)ti.tcpi_bytes_acked;
}
