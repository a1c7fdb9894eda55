/* Slow clients (issue #10): every connection, from accept to close.
 *
 * libmicrohttpd 0.9.75's connection timeout only measures inactivity, so a
 * head sent a byte a second would hold its slot forever. Every connection is tracked from accept
 * (NOTIFY_CONNECTION) in one of four phases: HEAD (the request head is arriving: from accept, or
 * from the first byte after the previous answer), BODY (the access handler
 * has the head and a body is arriving), BUSY (we are answering, or the
 * request is held by ?wait) and IDLE (keep-alive, no byte since the last
 * answer). A sweeper thread, every 100 ms:
 *   - answers a HEAD older than --header-timeout, and a BODY whose rate over
 *     a 2 s window (after a 2 s grace) is under --min-body-rate, with a
 *     canned JSON 408 written straight to the socket. libmicrohttpd only
 *     reads in those phases, and the handler's phase changes and the
 *     sweeper's writes share one lock (a killed connection never gets a
 *     response queued), so the two never write at once. The socket is then
 *     shut for writing, and for reading half a second later: libmicrohttpd
 *     reads EOF and closes it, and the client has had time to read the 408
 *     before the close resets the connection. Neither deadline is applied
 *     while bytes wait unread in the kernel: then libmicrohttpd's thread is
 *     busy (a handler parsing a large mesh), not the client slow.
 *   - cuts a BUSY connection whose client acknowledged none of the answer
 *     for --connection-timeout while bytes of it were outstanding (unsent,
 *     or sent to a client gone without a word): the
 *     libmicrohttpd timeout is off while an answer is sent (vx_resp_queue),
 *     as it measures its own writes, and the kernel wakes a writer only
 *     when a third of the send buffer has drained (minutes at 30 KB/s).
 *   - closes a connection idle between requests for --connection-timeout
 *     while that timeout is still off (the answer's last bytes were in
 *     the kernel when libmicrohttpd was done: its clock, put back then,
 *     closed a steady reader's connection before it had read them),
 *     counted from when the kernel held nothing of the answer.
 *   - cuts a BUSY connection whose answer the client reads slower than
 *     --min-send-rate over a 10 s window during which unsent bytes of it
 *     always waited in the kernel (the client's receive window full: a
 *     client that keeps up, an event stream between events and a ?wait
 *     hold never start one). libmicrohttpd is writing then, so no answer
 *     can be written behind it: the socket is shut with SO_LINGER 0 and
 *     libmicrohttpd's close resets it (sockq.c reads the kernel's counts).
 *   - keeps headroom: when the open connections reach 90% of
 *     --max-connections, it closes the oldest HEAD (with a 408) and IDLE
 *     connections until they are down to 80%, then if need be the slowest
 *     BODY under 16 x --min-body-rate (408), then the slowest readers of
 *     answers under 16 x --min-send-rate (cut as above), sweep after sweep
 *     until 80% is reached. A client that sends its head
 *     at once is BUSY within a millisecond and is never a victim, so
 *     however many addresses drip heads, a fresh client finds a slot (or
 *     waits in the listen backlog, ahead of the victims' reconnections,
 *     for at most one sweep) and is served.
 * An answer that libmicrohttpd sent before the body was read (401, 413,
 * 415 from the head alone) is followed by its close; closing a socket with
 * unread bytes resets it, and the reset can reach the client before the
 * answer. Such a connection is marked (vx_conns_linger); at its close a
 * copy of the descriptor keeps the socket open, and the sweeper reads and
 * drops what arrives until the client closes, for DRAIN_S at most and
 * DRAIN_IDLE_S without a byte (as many sockets at once as
 * --max-connections where the descriptor limit leaves room, else a
 * quarter of them, the one drained longest closed to make room).
 * When the server stops (SIGTERM), vx_conns_shutdown answers every HEAD
 * and BODY still arriving after the grace with a JSON 503 shutting_down
 * the same way, so a client is told to send it again rather than cut off.
 * A connection opened while its address has --max-connections-per-ip
 * open is counted here at accept (libmicrohttpd's own per-IP limit closed
 * it without a word) and its request answered 503 too_many_connections,
 * Connection: close, by the access handler (vx_conns_over_ip).
 * A request line longer than --max-uri-bytes gets a JSON 414 the same way
 * (from the URI log callback, in the connection's own thread), and a head
 * larger than --max-header-bytes a JSON 431 from the access handler. What
 * libmicrohttpd still answers itself, with its own HTML body, is listed in
 * the README (Limits) and api/openapi.yaml: a request line or head too long
 * for the connection's 256 KiB buffer (414, 431; about 60 bytes of it per
 * header line too), a malformed header line or Content-Length (400), a
 * chunk size over 64 bits (413), a bad chunk (400), a chunk line too long
 * for the buffer (500) and HTTP versions other than 1.x (505). */
#include "conns.h"

#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "metrics.h"
#include "request.h"
#include "sockq.h"
#include "util/fsutil.h"
#include "util/log.h"

/* The phases of a connection (see the top of the file). */
typedef enum cphase { P_HEAD, P_BODY, P_BUSY, P_IDLE } cphase;

/* One open connection, from accept to close; all fields under vx_conns.lock. */
struct vx_conn {
    struct vx_conn *prev, *next;
    int fd;
    cphase phase;
    double t_phase;      /* monotonic: when the phase began */
    uint64_t body_bytes; /* BODY: received so far */
    double t_body;       /* BODY: when bytes of it last came (0: none yet) */
    int win_started;     /* BODY: the rate window is running */
    double win_t0;
    uint64_t win_bytes;
    double last_rate; /* BODY: bytes/s over the last whole window (-1: none yet) */
    /* BUSY: the answer's window, while it waits on the client (see sweep) */
    int out_started;
    double out_t0;
    uint64_t out_acked;
    double out_rate; /* bytes/s over the last whole window (-1: none, or keeping up) */
    /* BUSY: the acknowledged count last seen while bytes of the answer
     * were outstanding (-1: none were), and since when it has not moved */
    int64_t stall_acked;
    double stall_t;
    /* libmicrohttpd's idle timeout is off (vx_conns_own_idle; set and
     * cleared by the connection's thread) while a POST body comes and an
     * answer goes; IDLE or HEAD: since when the kernel has held no byte of
     * the last answer */
    _Atomic int own_idle;
    double quiet_t;
    int killed;      /* answered (or closed) by us behind libmicrohttpd's back */
    int kill_status; /* the status we wrote, 0 for none */
    int rd_closed;   /* shutdown(SHUT_RD) done */
    double t_killed;
    char rid[72];     /* BODY: the request's id; else the id of the answer written here */
    char origin[256]; /* BODY: the request's origin when CORS allows it, else "" */
    int path_escape;  /* the current request's path has %00 or %2F (see vx_conns_on_uri) */
    int target_bad;   /* ... its target a raw space or control character */
    const char *uri;  /* ... its target in libmicrohttpd's buffer, as first seen */
    size_t uri_len;
    int linger;             /* answered before its body was read: drain it after the close */
    unsigned char peer[17]; /* the client's address family and address (0s: unknown) */
    int over_ip;            /* opened past --max-connections-per-ip: its request gets a 503 */
    /* BUSY, a file sent as it is (vx_conns_watch_file): a descriptor of
     * it (owned; -1 when none) and the size the answer needs */
    int watch_fd;
    uint64_t watch_need;
};

/* A socket answered before its body was read, kept open after
 * libmicrohttpd closed its descriptor (see vx_conns_linger). */
typedef struct lingerer {
    int fd;
    double t0, last; /* when it began, when a byte last came */
} lingerer;

struct vx_conns {
    const vx_config *cfg;
    pthread_mutex_t lock;
    vx_conn *list;
    size_t n;
    pthread_t sweeper;
    int sweeper_started;
    int stop;
    /* The sockets being drained (at most cap_ling), under ling_lock, never
     * taken with lock held: a close that adds one waits for one pass. */
    pthread_mutex_t ling_lock;
    lingerer *ling;
    size_t nling, cap_ling;
    /* Set when the open connections reach the headroom mark, cleared when
     * they are down to 80%: a victim whose rate is not known yet at the
     * first sweep over the mark goes at a later one. */
    int shedding;
    /* Files found cut short by the last sweep (bytes, the size needed),
     * logged by the sweeper once it let go of lock; ncut may pass 8. */
    uint64_t cut[8][2];
    size_t ncut;
    double last_sweep; /* monotonic: when sweep last ran (0: never) */
};

#define BODY_GRACE_S 2.0   /* a body is not rated before this */
#define BODY_WINDOW_S 2.0  /* then each window must carry min_body_rate * window */
#define SEND_WINDOW_S 10.0 /* an answer must be read at min_send_rate over this */
#define KILL_LINGER_S 0.5  /* between our answer and closing the read side */
#define SWEEP_US 100000
#define EVICT_MIN_AGE_S 0.25 /* a head or idle time this young is nobody's attack */
#define PRESSURE_RATE_X 16   /* at the headroom mark, bodies under 16 x --min-body-rate go */
#define DRAIN_S 5.0          /* the longest an answered socket's body is read and dropped */
#define DRAIN_IDLE_S 1.0     /* ... or until nothing came for this long */

vx_conn *vx_conns_of(struct MHD_Connection *c)
{
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
    return ci ? ci->socket_context : NULL;
}

/* s as the inside of a JSON string into out (n bytes, cut short at a
 * character: out is always valid): quotes, backslashes and control bytes
 * escaped, the rest (UTF-8 from vx_resp_err_text, or ASCII) as it is. */
static const char *json_inside(const char *s, char *out, size_t n)
{
    size_t o = 0;
    int cut = 0;
    for (; *s; s++) {
        unsigned char ch = (unsigned char)*s;
        char e[8];
        int k = ch == '"' || ch == '\\' ? snprintf(e, sizeof e, "\\%c", ch)
                : ch < 0x20             ? snprintf(e, sizeof e, "\\u%04x", ch)
                                        : (e[0] = (char)ch, 1);
        if (o + (size_t)k >= n) {
            cut = 1;
            break;
        }
        memcpy(out + o, e, (size_t)k);
        o += (size_t)k;
    }
    if (cut) { /* never half a UTF-8 character: the last one goes whole */
        while (o > 0 && ((unsigned char)out[o - 1] & 0xc0) == 0x80)
            o--;
        if (o > 0 && (unsigned char)out[o - 1] >= 0xc0) o--;
    }
    out[o] = 0;
    return out;
}

/* Answers a connection behind libmicrohttpd's back: writes a canned JSON
 * error (status 0: none), shuts the socket for writing, and for reading
 * too when rd (else the sweeper does it after KILL_LINGER_S; libmicrohttpd
 * then reads EOF and closes it). Only while libmicrohttpd is reading the
 * socket, with s->lock held. Returns the bytes written. */
/* Stops watching vc's file (vx_conns_watch_file); lock held. */
static void unwatch(vx_conn *vc)
{
    if (vc->watch_fd >= 0) close(vc->watch_fd);
    vc->watch_fd = -1;
}

/* When data last came in on fd (the kernel knows; libmicrohttpd may have
 * read it already), on the clock of now; -1 when it cannot say. */
static double data_came(int fd, double now)
{
    struct tcp_info ti;
    socklen_t tl = sizeof ti;
    if (getsockopt(fd, IPPROTO_TCP, TCP_INFO, &ti, &tl) != 0) return -1;
    return now - ti.tcpi_last_data_recv / 1000.0;
}

/* Origins are allowed (--cors-origin): every answer varies by Origin, the
 * canned ones too (set at start). */
static int g_vary_origin;

static size_t kill_conn(vx_conn *vc, int status, const char *code, const char *message, int rd)
{
    char body[1400], msg[2400], date[64], cors[512] = "", qc[128], qm[1200];
    int n = 0;
    if (status) {
        int bn = snprintf(body, sizeof body, "{\"error\":{\"code\":\"%s\",\"message\":\"%s\"}}",
                          json_inside(code, qc, sizeof qc), json_inside(message, qm, sizeof qm));
        /* A body's request has its id (and origin); before the head is
         * read there is no client id to echo: a new one. */
        int body_phase = vc->phase == P_BODY && vc->rid[0];
        if (!body_phase) vx_req_new_id(vc->rid);
        if (body_phase && vc->origin[0])
            snprintf(cors, sizeof cors,
                     "Access-Control-Allow-Origin: %s\r\nAccess-Control-Expose-Headers: %s\r\n"
                     "Vary: Origin\r\n",
                     vc->origin, VX_CORS_EXPOSE);
        else if (g_vary_origin)
            snprintf(cors, sizeof cors, "Vary: Origin\r\n");
        time_t now = time(NULL);
        struct tm tm;
        strftime(date, sizeof date, "%a, %d %b %Y %H:%M:%S GMT", gmtime_r(&now, &tm));
        n = snprintf(msg, sizeof msg,
                     "HTTP/1.1 %d %s\r\nDate: %s\r\nContent-Type: application/json\r\n"
                     "Cache-Control: no-store\r\nX-Request-Id: %s\r\n%s%sConnection: close\r\n"
                     "Content-Length: %d\r\n\r\n%s",
                     status,
                     status == 408   ? "Request Timeout"
                     : status == 503 ? "Service Unavailable"
                     : status == 413 ? "Content Too Large"
                     : status == 414 ? "URI Too Long"
                     : status == 507 ? "Insufficient Storage"
                                     : "Internal Server Error",
                     date, vc->rid, status == 503 ? "Retry-After: 1\r\n" : "", cors, bn, body);
        if (n >= (int)sizeof msg) n = (int)sizeof msg - 1; /* (never: the parts are bounded) */
        if (send(vc->fd, msg, (size_t)n, MSG_NOSIGNAL | MSG_DONTWAIT) < 0) n = 0;
    }
    shutdown(vc->fd, rd ? SHUT_RDWR : SHUT_WR);
    vc->killed = 1;
    vc->kill_status = status;
    vc->rd_closed = rd;
    vc->t_killed = vx_mono();
    return (size_t)n;
}

/* An answer given by kill_conn before the head was read (no request, so
 * on_completed never sees it): what its log line says. */
typedef struct head_kill {
    char rid[72];
    int status;
    double dt;
    size_t bytes;
    const char *why;
} head_kill;

/* Logs and counts k. Never with s->lock held: a log write that stalls
 * (a slow disk) would hold every thread that accepts or closes a
 * connection. */
static void note_head_kill(const head_kill *k)
{
    vx_metrics_request(vx_req_route_name(VX_R_UNKNOWN), "other", k->status, k->dt, 0, k->bytes);
    VX_INFO("http.request",
            "request_id=%s method=- route=unmatched status=%d ms=%.2f bytes_in=0 bytes_out=%zu "
            "reason=%s",
            k->rid, k->status, k->dt * 1e3, k->bytes, k->why);
}

/* Keeps vc's kill in ks (room for cap) for note_head_kill after the lock;
 * without room, logs it at once. */
static void head_killed(head_kill *ks, size_t *nk, size_t cap, const vx_conn *vc, int status,
                        double dt, size_t bytes, const char *why)
{
    head_kill k = {.status = status, .dt = dt, .bytes = bytes, .why = why};
    snprintf(k.rid, sizeof k.rid, "%s", vc->rid);
    if (ks && *nk < cap)
        ks[(*nk)++] = k;
    else
        note_head_kill(&k);
}

/* With every drain slot taken, the socket drained longest makes room (its
 * client has had the most time to read its answer; the newest, closed at
 * once, was the one most likely to be reset first): what waits on it is
 * read once more, then it closes. With s->ling_lock held. */
static void evict_oldest(vx_conns *s)
{
    size_t old = 0;
    for (size_t i = 1; i < s->nling; i++)
        if (s->ling[i].t0 < s->ling[old].t0) old = i;
    char sink[16384];
    while (recv(s->ling[old].fd, sink, sizeof sink, MSG_DONTWAIT) > 0)
        ;
    close(s->ling[old].fd);
    s->ling[old] = s->ling[--s->nling];
}

/* The client's address of c into peer (family, then the IPv4 or IPv6
 * address); 0 when unknown. */
static int peer_of(struct MHD_Connection *c, unsigned char peer[17])
{
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
    memset(peer, 0, 17);
    if (!ci || !ci->client_addr) return 0;
    const struct sockaddr *sa = ci->client_addr;
    peer[0] = (unsigned char)sa->sa_family;
    if (sa->sa_family == AF_INET)
        memcpy(peer + 1, &((const struct sockaddr_in *)sa)->sin_addr, 4);
    else if (sa->sa_family == AF_INET6)
        memcpy(peer + 1, &((const struct sockaddr_in6 *)sa)->sin6_addr, 16);
    else
        return 0;
    return 1;
}

void vx_conns_notify(void *cls, struct MHD_Connection *c, void **socket_context,
                     enum MHD_ConnectionNotificationCode code)
{
    vx_conns *s = cls;
    if (code == MHD_CONNECTION_NOTIFY_STARTED) {
        const union MHD_ConnectionInfo *ci =
            MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
        vx_conn *vc = ci ? calloc(1, sizeof *vc) : NULL;
        if (!vc) return; /* untracked: only libmicrohttpd's timeouts apply */
        vc->fd = ci->connect_fd;
        vc->watch_fd = -1;
        vc->phase = P_HEAD;
        vc->t_phase = vx_mono();
        vc->out_rate = -1;
        vc->stall_acked = -1;
        int known = peer_of(c, vc->peer);
        pthread_mutex_lock(&s->lock);
        uint64_t same = 1, max = s->cfg->max_connections_per_ip;
        for (const vx_conn *o = s->list; known && max && o && same <= max; o = o->next)
            same += !memcmp(o->peer, vc->peer, sizeof vc->peer);
        vc->over_ip = known && max && same > max;
        vc->next = s->list;
        if (s->list) s->list->prev = vc;
        s->list = vc;
        s->n++;
        pthread_mutex_unlock(&s->lock);
        *socket_context = vc;
        return;
    }
    vx_conn *vc = *socket_context;
    if (!vc) return;
    pthread_mutex_lock(&s->lock);
    int linger = vc->linger && !vc->killed;
    if (vc->prev)
        vc->prev->next = vc->next;
    else
        s->list = vc->next;
    if (vc->next) vc->next->prev = vc->prev;
    s->n--;
    pthread_mutex_unlock(&s->lock);
    /* libmicrohttpd has written the answer and shut the socket for writing;
     * its close would reset the connection while the body still arrives,
     * and the client could lose the answer. A copy of the descriptor keeps
     * the socket open until the sweeper has drained it. */
    if (linger) {
        pthread_mutex_lock(&s->ling_lock);
        if (s->nling && s->nling == s->cap_ling) evict_oldest(s);
        int fd = s->nling < s->cap_ling ? fcntl(vc->fd, F_DUPFD_CLOEXEC, 0) : -1;
        if (fd >= 0) {
            shutdown(fd, SHUT_WR);
            double now = vx_mono();
            s->ling[s->nling++] = (lingerer){fd, now, now};
        }
        pthread_mutex_unlock(&s->ling_lock);
    }
    unwatch(vc);
    free(vc);
    *socket_context = NULL;
}

int vx_mhd_in_place(void)
{
    static _Atomic int in_place = -1;
    if (in_place < 0) {
        unsigned a = 0, b = 0, m = 0;
        const char *v = MHD_get_version();
        in_place =
            v && sscanf(v, "%u.%u.%u", &a, &b, &m) == 3 && a == 0 && (b < 9 || (b == 9 && m <= 75));
    }
    return in_place;
}

/* URI log callback: runs when the request line is in, before the headers. */
void *vx_conns_on_uri(void *cls, const char *uri, struct MHD_Connection *c)
{
    vx_conns *s = cls;
    vx_conn *vc = vx_conns_of(c);
    if (vc) {
        /* libmicrohttpd decodes the path before routing: %00 cut it short
         * there and %2F made a separator, so "/v1/jobs/ID%00x" was job ID. */
        size_t plen = strcspn(uri, "?");
        int esc = 0;
        for (size_t i = 0; i + 2 < plen && !esc; i++)
            esc = uri[i] == '%' && ((uri[i + 1] == '0' && uri[i + 2] == '0') ||
                                    (uri[i + 1] == '2' && (uri[i + 2] | 0x20) == 'f'));
        vc->path_escape = esc;
        int bad = 0;
        for (const unsigned char *p = (const unsigned char *)uri; *p && !bad; p++)
            bad = *p <= 0x20 || *p == 0x7f;
        vc->target_bad = bad;
        vc->uri = uri;
        vc->uri_len = strlen(uri);
        /* A request line is in: a head has begun. One pipelined behind
         * the last request came before its answer, so the sweeper saw no
         * byte after it and kept the connection idle (no 408, a silent
         * close at the idle timeout). */
        pthread_mutex_lock(&s->lock);
        if (vc->phase == P_IDLE) {
            vc->phase = P_HEAD;
            vc->t_phase = vx_mono();
        }
        pthread_mutex_unlock(&s->lock);
    }
    if (strlen(uri) <= s->cfg->max_uri_bytes || !vc) return NULL;
    pthread_mutex_lock(&s->lock);
    size_t n = vc->killed ? 0
                          : kill_conn(vc, 414, "uri_too_long",
                                      "the request target is longer than max-uri-bytes", 0);
    head_kill k = {.status = 414, .dt = vx_mono() - vc->t_phase, .bytes = n, .why = "uri_too_long"};
    snprintf(k.rid, sizeof k.rid, "%s", vc->rid);
    pthread_mutex_unlock(&s->lock);
    if (n) note_head_kill(&k);
    return NULL;
}

/* 1 when bytes wait in the kernel that libmicrohttpd has not read yet: its
 * thread is busy (a long handler), so a slow head or body is not the
 * client's doing and is not held against it. */
static int unread(const vx_conn *vc)
{
    int n = 0;
    return ioctl(vc->fd, FIONREAD, &n) == 0 && n > 0;
}

static int by_phase_time(const void *a, const void *b)
{
    double x = (*(vx_conn *const *)a)->t_phase, y = (*(vx_conn *const *)b)->t_phase;
    return x < y ? -1 : x > y;
}

static int by_rate(const void *a, const void *b)
{
    double x = (*(vx_conn *const *)a)->last_rate, y = (*(vx_conn *const *)b)->last_rate;
    return x < y ? -1 : x > y;
}

static int by_out_rate(const void *a, const void *b)
{
    double x = (*(vx_conn *const *)a)->out_rate, y = (*(vx_conn *const *)b)->out_rate;
    return x < y ? -1 : x > y;
}

/* Cuts a connection while libmicrohttpd sends its answer (nothing can be
 * written behind it then): the close that follows resets it (SO_LINGER 0,
 * so the unsent answer is not kept in the kernel), and libmicrohttpd's next
 * send fails and closes it. With s->lock held. */
static void cut_reader(vx_conn *vc, double rate, const char *why)
{
    struct linger lg = {1, 0};
    setsockopt(vc->fd, SOL_SOCKET, SO_LINGER, &lg, sizeof lg);
    shutdown(vc->fd, SHUT_RDWR);
    vc->killed = 1;
    vc->kill_status = 0;
    vc->rd_closed = 1;
    vc->t_killed = vx_mono();
    VX_WARN("http.slow_reader", "fd=%d rate=%.0f why=%s", vc->fd, rate, why);
}

/* Reads and drops what waits on each lingering socket, without blocking;
 * closes it at the client's end of file, an error, after DRAIN_S, or when
 * nothing came for DRAIN_IDLE_S (the body was all in already, and the
 * client keeps its socket). Takes s->ling_lock, not s->lock. */
static void drain(vx_conns *s)
{
    char sink[16384];
    pthread_mutex_lock(&s->ling_lock);
    double now = vx_mono();
    for (size_t i = 0; i < s->nling;) {
        lingerer *l = &s->ling[i];
        ssize_t got = 0;
        for (int k = 0; k < 256; k++) { /* at most 4 MiB a sweep per socket */
            if ((got = recv(l->fd, sink, sizeof sink, MSG_DONTWAIT)) <= 0) break;
            l->last = now;
        }
        int open = got > 0 || (got < 0 && (errno == EAGAIN || errno == EWOULDBLOCK));
        if (open && now - l->t0 < DRAIN_S && now - l->last < DRAIN_IDLE_S) {
            i++;
            continue;
        }
        close(l->fd);
        *l = s->ling[--s->nling];
    }
    pthread_mutex_unlock(&s->ling_lock);
}

/* One pass of the sweeper, with s->lock held; the heads it answers go
 * into ks (room for cap, as cand), for the caller to log. */
static void sweep(vx_conns *s, vx_conn **cand, head_kill *ks, size_t *nk, size_t cap)
{
    const vx_config *cfg = s->cfg;
    double now = vx_mono();
    /* A sweep a second after the last: the daemon did not run (SIGSTOP, a
     * paused VM), and what clients sent meanwhile waits to be read, by
     * libmicrohttpd's threads as they wake (a read of it can come after
     * this sweep): no body is idle from before now. */
    const int resumed = s->last_sweep > 0 && now - s->last_sweep > 1.0;
    s->last_sweep = now;
    size_t live = 0, ncand = 0;
    for (vx_conn *vc = s->list; vc; vc = vc->next) {
        if (vc->killed) {
            if (!vc->rd_closed && now - vc->t_killed >= KILL_LINGER_S) {
                shutdown(vc->fd, SHUT_RD);
                vc->rd_closed = 1;
            }
            continue;
        }
        /* Idle between requests while libmicrohttpd's timeout is off
         * (after a large answer whose bytes the kernel still held when it
         * was done: its own clock, put back then, closed a steady reader's
         * keep-alive connection before the client had read the answer). */
        if (atomic_load(&vc->own_idle) && (vc->phase == P_IDLE || vc->phase == P_HEAD) &&
            cfg->connection_timeout_s > 0) {
            if (vx_sockq_queued(vc->fd) != 0) vc->quiet_t = now;
            const double got = data_came(vc->fd, now);
            if (now - vc->quiet_t >= cfg->connection_timeout_s && got >= 0 &&
                now - got >= cfg->connection_timeout_s) {
                kill_conn(vc, 0, NULL, NULL, 1);
                continue;
            }
        }
        if (vc->phase == P_IDLE) {
            /* A client that shut its side after its request (nc -N, a
             * half-close): libmicrohttpd read that EOF with the request and
             * waits for the next one until --connection-timeout, the
             * socket in CLOSE-WAIT. Nothing unread and EOF: closed here. */
            char b;
            if (recv(vc->fd, &b, 1, MSG_PEEK | MSG_DONTWAIT) == 0) {
                kill_conn(vc, 0, NULL, NULL, 1);
                continue;
            }
            /* Has a byte of the next request come in since the answer? The
             * kernel knows when data last arrived; libmicrohttpd has
             * already read it into its buffer. */
            const double last = data_came(vc->fd, now);
            if (last >= 0 && last > vc->t_phase + 0.02) {
                vc->phase = P_HEAD;
                vc->t_phase = last;
            }
        }
        if (vc->phase == P_HEAD && cfg->header_timeout_s > 0 &&
            now - vc->t_phase > cfg->header_timeout_s && !unread(vc)) {
            char m[96];
            snprintf(m, sizeof m, "the request head did not arrive within %g s",
                     cfg->header_timeout_s);
            size_t n = kill_conn(vc, 408, "request_timeout", m, 0);
            head_killed(ks, nk, cap, vc, 408, now - vc->t_phase, n, "header_timeout");
            continue;
        }
        /* A body none of whose bytes came for --connection-timeout, while
         * libmicrohttpd's timeout is off (http.c): its clock, stale after
         * the daemon was stopped (SIGSTOP, a paused VM), closed uploads
         * whose bytes were waiting in the socket. Bytes unread or read
         * since are not idle. */
        if (resumed && vc->phase == P_BODY) vc->t_body = now;
        if (atomic_load(&vc->own_idle) && vc->phase == P_BODY && cfg->connection_timeout_s > 0 &&
            now - (vc->t_body > vc->t_phase ? vc->t_body : vc->t_phase) >=
                cfg->connection_timeout_s) {
            /* (the socket asked only then, not at every sweep) */
            const double got = data_came(vc->fd, now);
            if (got >= 0 && now - got >= cfg->connection_timeout_s && !unread(vc)) {
                char m[96];
                snprintf(m, sizeof m, "no byte of the body came for %g s",
                         cfg->connection_timeout_s);
                kill_conn(vc, 408, "request_timeout", m, 0); /* on_completed logs it */
                continue;
            }
        }
        if (vc->phase == P_BODY && cfg->min_body_rate && now - vc->t_phase >= BODY_GRACE_S) {
            if (!vc->win_started) {
                vc->win_started = 1;
                vc->win_t0 = now;
                vc->win_bytes = vc->body_bytes;
            } else if (now - vc->win_t0 >= BODY_WINDOW_S) {
                double rate = (double)(vc->body_bytes - vc->win_bytes) / (now - vc->win_t0);
                if (rate < (double)cfg->min_body_rate && !unread(vc)) {
                    char m[96];
                    snprintf(m, sizeof m, "the body arrived slower than %llu bytes/s",
                             (unsigned long long)cfg->min_body_rate);
                    kill_conn(vc, 408, "request_timeout", m, 0); /* on_completed logs it */
                    continue;
                }
                vc->last_rate = rate;
                vc->win_t0 = now;
                vc->win_bytes = vc->body_bytes;
            }
        }
        /* A file sent as it is, cut short behind the daemon: libmicrohttpd
         * waits for bytes that never come (until --connection-timeout);
         * the client learns at once from the close that the answer is
         * short. */
        struct stat fst;
        if (vc->phase == P_BUSY && vc->watch_fd >= 0 && fstat(vc->watch_fd, &fst) == 0 &&
            (uint64_t)fst.st_size < vc->watch_need) {
            if (s->ncut < 8) {
                s->cut[s->ncut][0] = (uint64_t)fst.st_size;
                s->cut[s->ncut][1] = vc->watch_need;
            }
            s->ncut++;
            unwatch(vc);
            kill_conn(vc, 0, NULL, NULL, 1);
            continue;
        }
        /* An answer the client reads slower than --min-send-rate over a
         * window during which it always waited on the client (a reader
         * that keeps up, an event stream between events, a ?wait hold and
         * a handler still working never start one). */
        /* An answer of which the client acknowledged nothing for
         * --connection-timeout while bytes of it were outstanding (unsent
         * or in flight: a client gone without a word acknowledges nothing
         * that was sent): libmicrohttpd's own idle timeout is off while an
         * answer is sent (vx_resp_queue). */
        int64_t held = vc->phase == P_BUSY && cfg->connection_timeout_s > 0
                           ? vx_sockq_acked_while_outstanding(vc->fd)
                           : -1;
        if (held < 0 || held != vc->stall_acked) {
            vc->stall_acked = held;
            vc->stall_t = now;
        } else if (now - vc->stall_t >= cfg->connection_timeout_s) {
            cut_reader(vc, 0, "connection_timeout");
            continue;
        }
        int64_t acked =
            vc->phase == P_BUSY && cfg->min_send_rate ? vx_sockq_acked_while_waiting(vc->fd) : -1;
        if (acked < 0) {
            vc->out_started = 0;
            vc->out_rate = -1;
        } else if (!vc->out_started) {
            vc->out_started = 1;
            vc->out_t0 = now;
            vc->out_acked = (uint64_t)acked;
        } else if (now - vc->out_t0 >= SEND_WINDOW_S) {
            double rate = (double)((uint64_t)acked - vc->out_acked) / (now - vc->out_t0);
            if (rate < (double)cfg->min_send_rate) {
                cut_reader(vc, rate, "min_send_rate");
                continue;
            }
            vc->out_rate = rate;
            vc->out_t0 = now;
            vc->out_acked = (uint64_t)acked;
        }
        live++;
        if ((vc->phase == P_HEAD || vc->phase == P_IDLE) && cand) cand[ncand++] = vc;
    }
    /* Headroom: from 90% of the connections down to 80%, oldest first. */
    size_t max = (size_t)cfg->max_connections;
    size_t high = max >= 10 ? max - max / 10 : max, low = max >= 10 ? max - max / 5 : max - 1;
    if (live >= high) s->shedding = 1;
    if (live <= low) s->shedding = 0;
    if (!s->shedding || !cand) return;
    qsort(cand, ncand, sizeof *cand, by_phase_time);
    for (size_t i = 0; i < ncand && live > low; i++) {
        vx_conn *vc = cand[i];
        if (now - vc->t_phase < EVICT_MIN_AGE_S || unread(vc)) continue;
        live--;
        if (vc->phase == P_HEAD) {
            size_t n = kill_conn(vc, 408, "request_timeout",
                                 "the server is busy and the request head was not complete", 1);
            head_killed(ks, nk, cap, vc, 408, now - vc->t_phase, n, "evicted");
        } else {
            kill_conn(vc, 0, NULL, NULL, 1);
        }
    }
    /* Still over: the slowest bodies, under PRESSURE_RATE_X times
     * --min-body-rate (one trickled just over the floor held its slot for
     * as long as the body lasted: days, for a large upload). */
    size_t nslow = 0;
    double floor_rate = (double)cfg->min_body_rate * PRESSURE_RATE_X;
    for (vx_conn *vc = s->list; vc && live > low && floor_rate > 0; vc = vc->next)
        if (!vc->killed && vc->phase == P_BODY && vc->last_rate >= 0 && vc->last_rate < floor_rate)
            cand[nslow++] = vc; /* (cand holds every connection) */
    qsort(cand, nslow, sizeof *cand, by_rate);
    for (size_t i = 0; i < nslow && live > low; i++) {
        if (unread(cand[i])) continue;
        live--;
        char m[120];
        snprintf(m, sizeof m, "the server is busy and the body arrived slower than %.0f bytes/s",
                 floor_rate);
        kill_conn(cand[i], 408, "request_timeout", m, 1); /* on_completed logs it */
    }
    /* Then the slowest readers of answers, under PRESSURE_RATE_X times
     * --min-send-rate (a reader with a small receive window held its slot
     * for as long as the answer lasted). */
    nslow = 0;
    floor_rate = (double)cfg->min_send_rate * PRESSURE_RATE_X;
    for (vx_conn *vc = s->list; vc && live > low && floor_rate > 0; vc = vc->next)
        if (!vc->killed && vc->phase == P_BUSY && vc->out_rate >= 0 && vc->out_rate < floor_rate)
            cand[nslow++] = vc;
    qsort(cand, nslow, sizeof *cand, by_out_rate);
    for (size_t i = 0; i < nslow && live > low; i++, live--)
        cut_reader(cand[i], cand[i]->out_rate, "evicted");
    if (live <= low) s->shedding = 0;
    for (vx_conn *vc = s->list; vc; vc = vc->next) /* free the victims' slots now */
        if (vc->killed && !vc->rd_closed) {
            shutdown(vc->fd, SHUT_RD);
            vc->rd_closed = 1;
        }
}

static void *sweeper_main(void *arg)
{
    vx_conns *s = arg;
    size_t cap = 0, kcap = 0;
    vx_conn **cand = NULL;
    head_kill *ks = NULL;
    while (!__atomic_load_n(&s->stop, __ATOMIC_ACQUIRE)) {
        usleep(SWEEP_US);
        drain(s);
        pthread_mutex_lock(&s->lock);
        if (s->n > cap) {
            size_t ncap = s->n * 2;
            vx_conn **nc = realloc(cand, ncap * sizeof *nc);
            if (nc) {
                cand = nc;
                cap = ncap;
            }
        }
        if (s->n > kcap) {
            size_t ncap = s->n * 2;
            head_kill *nk = realloc(ks, ncap * sizeof *nk);
            if (nk) {
                ks = nk;
                kcap = ncap;
            }
        }
        size_t nk = 0;
        sweep(s, s->n <= cap ? cand : NULL, ks, &nk, kcap);
        uint64_t cut[8][2];
        size_t ncut = s->ncut;
        memcpy(cut, s->cut, sizeof cut);
        s->ncut = 0;
        pthread_mutex_unlock(&s->lock);
        for (size_t i = 0; i < nk; i++)
            note_head_kill(&ks[i]);
        for (size_t i = 0; i < ncut && i < 8; i++)
            VX_WARN("http.file_cut_short", "bytes=%llu need=%llu", (unsigned long long)cut[i][0],
                    (unsigned long long)cut[i][1]);
    }
    free(cand);
    free(ks);
    return NULL;
}

/* How many sockets may be drained at once: descriptors beyond the
 * connections, not slots. As many as the connections where the descriptor
 * limit leaves room for both (a burst of early answers as large as
 * --max-connections then loses none; at a quarter, 2-3 of 40 concurrent
 * 413s at --max-connections 32 were reset), else a quarter of them. */
static size_t ling_cap(uint64_t max_connections)
{
    size_t quarter = (size_t)max_connections / 4 + 1, all = (size_t)max_connections + 1;
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl) != 0) return quarter;
    if (rl.rlim_cur == RLIM_INFINITY || rl.rlim_cur >= 2 * (rlim_t)max_connections + 256)
        return all;
    return quarter;
}

vx_conns *vx_conns_start(const vx_config *cfg)
{
    vx_conns *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->cfg = cfg;
    g_vary_origin = cfg->cors_origin[0] != 0;
    size_t cap = ling_cap(cfg->max_connections);
    s->ling = calloc(cap, sizeof *s->ling);
    if (s->ling) s->cap_ling = cap;
    pthread_mutex_init(&s->lock, NULL);
    pthread_mutex_init(&s->ling_lock, NULL);
    if (pthread_create(&s->sweeper, NULL, sweeper_main, s) == 0) s->sweeper_started = 1;
    return s;
}

void vx_conns_stop(vx_conns *s)
{
    __atomic_store_n(&s->stop, 1, __ATOMIC_RELEASE);
    if (s->sweeper_started) pthread_join(s->sweeper, NULL);
    s->sweeper_started = 0;
}

static size_t count_phase(vx_conns *s, int busy_only)
{
    size_t n = 0;
    pthread_mutex_lock(&s->lock);
    for (const vx_conn *vc = s->list; vc; vc = vc->next)
        n += !vc->killed && (busy_only ? vc->phase == P_BUSY : vc->phase != P_IDLE);
    pthread_mutex_unlock(&s->lock);
    return n;
}

size_t vx_conns_pending(vx_conns *s)
{
    return count_phase(s, 0);
}

size_t vx_conns_answering(vx_conns *s)
{
    return count_phase(s, 1);
}

int vx_conns_shutdown(vx_conns *s)
{
    int n = 0;
    double now = vx_mono();
    pthread_mutex_lock(&s->lock);
    size_t nk = 0, cap = s->n;
    head_kill *ks = malloc(cap * sizeof *ks + 1);
    for (vx_conn *vc = s->list; vc; vc = vc->next) {
        if (vc->killed || (vc->phase != P_HEAD && vc->phase != P_BODY)) continue;
        int head = vc->phase == P_HEAD;
        size_t bytes = kill_conn(vc, 503, "shutting_down",
                                 "the server is shutting down; send the request again", 0);
        if (head) head_killed(ks, &nk, cap, vc, 503, now - vc->t_phase, bytes, "shutting_down");
        n++;
    }
    pthread_mutex_unlock(&s->lock);
    for (size_t i = 0; i < nk; i++)
        note_head_kill(&ks[i]);
    free(ks);
    return n;
}

void vx_conns_free(vx_conns *s)
{
    if (!s) return;
    vx_conns_stop(s);
    for (size_t i = 0; i < s->nling; i++)
        close(s->ling[i].fd);
    free(s->ling);
    pthread_mutex_destroy(&s->ling_lock);
    pthread_mutex_destroy(&s->lock);
    free(s);
}

int vx_conns_head_in(vx_conns *s, vx_conn *vc)
{
    if (!vc) return 0;
    pthread_mutex_lock(&s->lock);
    int dead = vc->killed;
    vc->phase = P_BUSY;
    vc->t_phase = vx_mono();
    vc->linger = 0; /* a new request: only its own early answer lingers */
    pthread_mutex_unlock(&s->lock);
    return dead;
}

void vx_conns_body_begins(vx_conns *s, vx_conn *vc, const char *rid, const char *origin)
{
    if (!vc) return;
    pthread_mutex_lock(&s->lock);
    snprintf(vc->rid, sizeof vc->rid, "%s", rid);
    /* an origin too long for the buffer goes without CORS, never cut */
    snprintf(vc->origin, sizeof vc->origin, "%s",
             origin && strlen(origin) < sizeof vc->origin && !strpbrk(origin, "\r\n") ? origin
                                                                                      : "");
    vc->phase = P_BODY;
    vc->t_phase = vx_mono();
    vc->t_body = 0;
    vc->body_bytes = 0;
    vc->win_started = 0;
    vc->last_rate = -1;
    pthread_mutex_unlock(&s->lock);
}

int vx_conns_body(vx_conns *s, vx_conn *vc, size_t n)
{
    if (!vc) return 0;
    pthread_mutex_lock(&s->lock);
    int dead = vc->killed;
    if (n) {
        vc->body_bytes += n;
        vc->t_body = vx_mono();
    } else if (vc->phase == P_BODY) {
        vc->phase = P_BUSY;
        vc->t_phase = vx_mono();
    }
    pthread_mutex_unlock(&s->lock);
    return dead;
}

int vx_conns_done(vx_conns *s, vx_conn *vc)
{
    if (!vc) return 0;
    int status = 0;
    pthread_mutex_lock(&s->lock);
    if (vc->killed)
        status = vc->kill_status;
    else { /* keep-alive: the next head starts with its first byte */
        vc->phase = P_IDLE;
        vc->t_phase = vc->quiet_t = vx_mono();
    }
    unwatch(vc);
    pthread_mutex_unlock(&s->lock);
    return status;
}

void vx_conns_own_idle(vx_conn *vc, int on)
{
    if (vc) atomic_store(&vc->own_idle, on);
}

int vx_conns_owns_idle(const vx_conn *vc)
{
    return vc && atomic_load(&vc->own_idle);
}

void vx_conns_watch_file(vx_conns *s, vx_conn *vc, int fd, uint64_t need)
{
    if (!vc) return;
    int copy = fcntl(fd, F_DUPFD_CLOEXEC, 0);
    pthread_mutex_lock(&s->lock);
    unwatch(vc);
    vc->watch_fd = copy;
    vc->watch_need = need;
    pthread_mutex_unlock(&s->lock);
}

void vx_conns_linger(vx_conns *s, vx_conn *vc)
{
    if (!vc) return;
    pthread_mutex_lock(&s->lock);
    vc->linger = 1;
    pthread_mutex_unlock(&s->lock);
}

void vx_conns_refuse(vx_conns *s, vx_conn *vc, int status, const char *code, const char *message)
{
    if (!vc) return;
    pthread_mutex_lock(&s->lock);
    if (!vc->killed && vc->phase == P_BODY) kill_conn(vc, status, code, message, 0);
    pthread_mutex_unlock(&s->lock);
}

int vx_conns_over_ip(const vx_conn *vc)
{
    return vc && vc->over_ip;
}

int vx_conns_line_cut(const vx_conn *vc, const char *method, const char *version)
{
    if (!vc || !vc->uri || !method || !version || !vx_mhd_in_place()) return 0;
    return method + strlen(method) + 1 != vc->uri || vc->uri + vc->uri_len + 1 != version;
}

int vx_conns_target_bad(const vx_conn *vc)
{
    return vc && vc->target_bad;
}

int vx_conns_peer_gone(struct MHD_Connection *c)
{
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
    if (!ci) return 0;
    char b;
    ssize_t n = recv(ci->connect_fd, &b, 1, MSG_PEEK | MSG_DONTWAIT);
    return n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR);
}

int vx_conns_path_escape(const vx_conn *vc)
{
    return vc && vc->path_escape;
}
