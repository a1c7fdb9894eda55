/* Structured logging to stderr: one line per event, key=value pairs, with
 * the "<N>" syslog priority prefix that journald understands, e.g.
 *   <6>ts=2026-11-21T10:00:00.123Z level=info event=http.request status=200
 * Thread-safe: any thread may log. */
#ifndef VX_LOG_H
#define VX_LOG_H

#include <pthread.h>

typedef enum vx_log_level {
    VX_LOG_ERR = 3,
    VX_LOG_WARN = 4,
    VX_LOG_INFO = 6,
    VX_LOG_DEBUG = 7,
} vx_log_level;

/* Messages above this level are dropped. Default VX_LOG_INFO. */
void vx_log_set_level(vx_log_level level);
/* A plain message on stderr (what the command line or the start met, for
 * a person to read), starting with its priority where stderr is the
 * journal as vx_log's lines do (journalctl -p warning shows it then). */
void vx_log_plain(vx_log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
vx_log_level vx_log_get_level(void);
/* Parses "error|warn|info|debug"; returns 0 or -1. */
int vx_log_parse_level(const char *s, vx_log_level *out);

/* Logs event=EVENT followed by the caller's already formatted key=value pairs.
 * Values with spaces must be quoted by the caller (see vx_log_quote). */
void vx_log(vx_log_level level, const char *event, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* Writes s into buf as a log value: bare if it has no space/quote/=, else
 * double-quoted with escapes. Returns buf. */
const char *vx_log_quote(char *buf, unsigned long size, const char *s);

/* A value quoted for the log in a buffer of its own, for use inside a VX_*
 * call's arguments (a path, a name an operator chose: a blank in it would
 * split the key=value pair). */
#define VX_Q(s) vx_log_quote((char[1024]){0}, 1024, (s))

/* At most a burst of lines a second from one noisy source (a driver's
 * debug messages, libmicrohttpd's: the same line at every draw or accept).
 * Static, initialised with VX_LOG_RATE_INIT. */
typedef struct vx_log_rate {
    pthread_mutex_t lock;
    double window;
    unsigned shown, dropped;
} vx_log_rate;
#define VX_LOG_RATE_INIT                                                                           \
    {                                                                                              \
        PTHREAD_MUTEX_INITIALIZER, 0, 0, 0                                                         \
    }
/* 1 when one more line may go out now; *dropped: the lines left out in the
 * second that just ended (for a line of the caller's saying so), else 0. */
int vx_log_rate_ok(vx_log_rate *r, unsigned burst, unsigned *dropped);

#define VX_ERROR(ev, ...) vx_log(VX_LOG_ERR, ev, __VA_ARGS__)
#define VX_WARN(ev, ...) vx_log(VX_LOG_WARN, ev, __VA_ARGS__)
#define VX_INFO(ev, ...) vx_log(VX_LOG_INFO, ev, __VA_ARGS__)
#define VX_DEBUG(ev, ...) vx_log(VX_LOG_DEBUG, ev, __VA_ARGS__)

#endif
