/* Routes of api/openapi.yaml on libmicrohttpd 0.9.75 (http.h).
 *
 * Request lifecycle: the first call of the access handler allocates a
 * `req`, routes it and answers early errors (auth, method, size, media type)
 * before any body is read, so a client that sent "Expect: 100-continue" gets
 * the error instead of sending the body. Body calls stream into the store or
 * a bounded buffer and always consume every chunk. The last call answers.
 * A ?wait request is suspended and resumed by the job hook or the timer
 * thread; the handler then answers as it would have without waiting.
 *
 * Slow clients (issue #10). libmicrohttpd 0.9.75's connection timeout only
 * measures inactivity, so a head sent a byte a second would hold its slot
 * forever. Every connection is tracked from accept (NOTIFY_CONNECTION) in
 * one of four phases: HEAD (the request head is arriving: from accept, or
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
 *   - keeps headroom: when the open connections reach 90% of
 *     --max-connections, it closes the oldest HEAD (with a 408) and IDLE
 *     connections until they are down to 80%. A client that sends its head
 *     at once is BUSY within a millisecond and is never a victim, so
 *     however many addresses drip heads, a fresh client finds a slot (or
 *     waits in the listen backlog, ahead of the victims' reconnections,
 *     for at most one sweep) and is served.
 * A request line longer than --max-uri-bytes gets a JSON 414 the same way
 * (from the URI log callback, in the connection's own thread), and a head
 * larger than --max-header-bytes a JSON 431 from the access handler. What
 * libmicrohttpd still answers itself, with its own HTML body, is listed in
 * the README (Limits) and api/openapi.yaml: a request line or head too long
 * for the connection's 256 KiB buffer (414, 431), a malformed header line
 * or Content-Length (400), a chunk size over 64 bits (413), a bad chunk
 * (400) and HTTP versions other than 1.x (505). */
#include "http.h"
#include "kinds.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <microhttpd.h>
#include <netdb.h>
#include <nettle/memops.h>
#include <nettle/sha2.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "metrics.h"
#include "request.h"
#include "util/budget.h"
#include "util/fsutil.h"
#include "util/log.h"

typedef enum body_kind { BODY_NONE, BODY_UPLOAD, BODY_JSON } body_kind;
/* Declared upload types: model/obj is OBJ; text/plain is text, OBJ or .bpt
 * by content; model/x-bpt is .bpt; the Draco types are Draco; no type or
 * application/octet-stream is told by content. */
typedef enum media { MEDIA_SNIFF, MEDIA_OBJ, MEDIA_DRACO, MEDIA_TEXT, MEDIA_BPT } media;

typedef struct req req;

/* The phases of a connection (see the top of the file). */
typedef enum cphase { P_HEAD, P_BODY, P_BUSY, P_IDLE } cphase;

/* One open connection, from accept to close; all fields under vx_http.clock. */
typedef struct vconn {
    struct vconn *prev, *next;
    int fd;
    cphase phase;
    double t_phase;      /* monotonic: when the phase began */
    uint64_t body_bytes; /* BODY: received so far */
    int win_started;     /* BODY: the rate window is running */
    double win_t0;
    uint64_t win_bytes;
    int killed;      /* answered (or closed) by us behind libmicrohttpd's back */
    int kill_status; /* the status we wrote, 0 for none */
    int rd_closed;   /* shutdown(SHUT_RD) done */
    double t_killed;
} vconn;

typedef struct waiter {
    req *r;
    struct MHD_Connection *conn;
    char jid[33];
    double deadline; /* monotonic */
    struct waiter *next;
} waiter;

struct req {
    vx_route route;
    char method[12];
    char id[VX_REQ_ID_MAX], name[VX_REQ_ID_MAX];
    vconn *vc;
    vx_req_query q;
    char qerr[160]; /* a bad query parameter, answered 400 */
    double t0;
    int status;
    uint64_t bytes_in, bytes_out;
    body_kind body;
    /* uploads */
    vx_upload *up;
    media declared;
    int too_big;
    vx_err body_err; /* storing the body failed (full disk): answered at the end */
    /* JSON bodies */
    char *buf;
    size_t len, cap;
    /* ?wait */
    waiter w;
    int waiting; /* suspended, not yet resumed */
    int resumed;
    int post_job; /* the held request was POST /v1/jobs */
    int answered;
};

struct vx_http {
    vx_http_desc d;
    struct MHD_Daemon *mhd;
    int port;
    unsigned char token_digest[SHA256_DIGEST_SIZE];
    int auth;
    pthread_mutex_t wlock;
    pthread_cond_t wcond;
    waiter *waiters;
    pthread_t timer;
    int timer_started;
    int stopping;
    /* connections (vconn), the sweeper */
    pthread_mutex_t clock;
    vconn *conns;
    size_t nconns;
    pthread_t sweeper;
    int sweeper_started;
    int sweep_stop;
};

/* The data dir, scrubbed from every error message (clients never see
 * server paths); set once by vx_http_start. */
static const char *g_data_dir;

/* ---- responses ----------------------------------------------------- */

static int queue(struct MHD_Connection *c, req *r, unsigned status, struct MHD_Response *resp,
                 uint64_t body_bytes)
{
    if (!resp) return MHD_NO;
    r->status = (int)status;
    r->bytes_out = body_bytes;
    r->answered = 1;
    int rc = MHD_queue_response(c, status, resp);
    MHD_destroy_response(resp);
    return rc;
}

static int send_text(struct MHD_Connection *c, req *r, unsigned status, char *text,
                     const char *ctype, const char *h1, const char *v1)
{
    size_t n = text ? strlen(text) : 0;
    struct MHD_Response *resp = MHD_create_response_from_buffer(
        n, text ? text : (void *)"", text ? MHD_RESPMEM_MUST_FREE : MHD_RESPMEM_PERSISTENT);
    if (!resp) {
        free(text);
        return MHD_NO;
    }
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    if (h1 && v1) MHD_add_response_header(resp, h1, v1);
    return queue(c, r, status, resp, n);
}

/* Sends a JSON document; takes ownership of doc. */
static int send_json(struct MHD_Connection *c, req *r, unsigned status, cJSON *doc, const char *h1,
                     const char *v1)
{
    char *text = doc ? cJSON_PrintUnformatted(doc) : NULL;
    cJSON_Delete(doc);
    if (!text) text = strdup("{\"error\":{\"code\":\"internal\",\"message\":\"out of memory\"}}");
    return send_text(c, r, status, text, "application/json", h1, v1);
}

static int send_error_h(struct MHD_Connection *c, req *r, unsigned status, const char *code,
                        const char *message, const char *h1, const char *v1)
{
    char scrubbed[600];
    snprintf(scrubbed, sizeof scrubbed, "%s", message);
    vx_scrub_path(scrubbed, g_data_dir);
    cJSON *doc = cJSON_CreateObject();
    cJSON *e = cJSON_AddObjectToObject(doc, "error");
    char clean[512];
    cJSON_AddStringToObject(e, "code", code);
    /* Messages may quote what the client sent: never echo bytes that are
     * not UTF-8 (the body would not be valid JSON text). */
    cJSON_AddStringToObject(e, "message", vx_req_utf8_sanitize(scrubbed, clean, sizeof clean));
    if (status >= 500) VX_ERROR("http.error", "status=%u code=%s", status, code);
    return send_json(c, r, status, doc, h1, v1);
}

static int send_error(struct MHD_Connection *c, req *r, unsigned status, const char *code,
                      const char *message)
{
    return send_error_h(c, r, status, code, message, NULL, NULL);
}

/* The one place that maps error kinds to HTTP statuses. */
static unsigned err_status(const vx_err *e)
{
    switch (e->kind) {
    case VX_EINVAL:
        return 400;
    case VX_EUNPROC:
        return 422;
    case VX_ETOOBIG:
        return 413;
    case VX_ENOTFOUND:
        return strcmp(e->code, "result_evicted") == 0 ? 410 : 404;
    case VX_ECONFLICT:
        return 409;
    case VX_EMEDIA:
        return 415;
    case VX_EBUSY:
        return strcmp(e->code, "not_ready") == 0 ? 503 : 429;
    case VX_ECANCELED:
        return 409;
    case VX_ETIMEOUT:
        return 504;
    case VX_ENOSPC:
        return 507;
    default:
        return 500;
    }
}

static int send_err(struct MHD_Connection *c, req *r, const vx_err *e)
{
    unsigned st = err_status(e);
    if (st == 429)
        return send_error_h(c, r, st, e->code, e->message, MHD_HTTP_HEADER_RETRY_AFTER, "2");
    if (st == 503)
        return send_error_h(c, r, st, e->code, e->message, MHD_HTTP_HEADER_RETRY_AFTER, "5");
    if (st == 507) return send_error(c, r, st, "insufficient_storage", e->message);
    return send_error(c, r, st, e->code, e->message);
}

/* ---- helpers ------------------------------------------------------- */

static const char *header(struct MHD_Connection *c, const char *name)
{
    return MHD_lookup_connection_value(c, MHD_HEADER_KIND, name);
}

/* Constant-time: both sides are hashed so neither length nor content leaks. */
static int auth_ok(vx_http *h, struct MHD_Connection *c)
{
    const char *a = header(c, MHD_HTTP_HEADER_AUTHORIZATION);
    if (!a || strncasecmp(a, "Bearer ", 7) != 0) return 0;
    a += 7;
    while (*a == ' ')
        a++;
    struct sha256_ctx ctx;
    unsigned char d[SHA256_DIGEST_SIZE];
    sha256_init(&ctx);
    sha256_update(&ctx, strlen(a), (const uint8_t *)a);
    sha256_digest(&ctx, sizeof d, d);
    return memeql_sec(d, h->token_digest, sizeof d);
}

/* The ?wait of r in seconds, capped to the request timeout. */
static double wait_seconds(vx_http *h, const req *r)
{
    double v = (double)r->q.wait_us / 1e6;
    return v > h->d.cfg->request_timeout_s ? h->d.cfg->request_timeout_s : v;
}

/* ---- waiting ------------------------------------------------------- */

static void resume_locked(vx_http *h, waiter *w)
{
    waiter **pp = &h->waiters;
    while (*pp && *pp != w)
        pp = &(*pp)->next;
    if (*pp) *pp = w->next;
    w->r->waiting = 0;
    w->r->resumed = 1;
    MHD_resume_connection(w->conn);
}

void vx_http_job_changed(vx_http *h, const char *jid, int terminal)
{
    if (!h || !terminal) return;
    pthread_mutex_lock(&h->wlock);
    for (waiter *w = h->waiters, *next; w; w = next) {
        next = w->next;
        if (!strcmp(w->jid, jid)) resume_locked(h, w);
    }
    pthread_mutex_unlock(&h->wlock);
}

static void *timer_main(void *arg)
{
    vx_http *h = arg;
    pthread_mutex_lock(&h->wlock);
    while (!h->stopping) {
        double now = vx_mono(), next = now + 0.25;
        for (waiter *w = h->waiters, *nx; w; w = nx) {
            nx = w->next;
            if (w->deadline <= now)
                resume_locked(h, w);
            else if (w->deadline < next)
                next = w->deadline;
        }
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        double dt = next - now;
        ts.tv_sec += (time_t)dt;
        ts.tv_nsec += (long)((dt - floor(dt)) * 1e9);
        if (ts.tv_nsec >= 1000000000L) {
            ts.tv_sec++;
            ts.tv_nsec -= 1000000000L;
        }
        pthread_cond_timedwait(&h->wcond, &h->wlock, &ts);
    }
    pthread_mutex_unlock(&h->wlock);
    return NULL;
}

/* Holds the request until jid finishes or wait_s passes. Returns 1 when
 * suspended, 0 when the job has already finished (answer now). */
static int hold(vx_http *h, struct MHD_Connection *c, req *r, const char *jid, double wait_s)
{
    pthread_mutex_lock(&h->wlock);
    int terminal = 0;
    vx_err err;
    cJSON *doc = vx_jobs_get(h->d.jobs, jid, &terminal, &err);
    cJSON_Delete(doc);
    if (!doc || terminal || h->stopping) {
        pthread_mutex_unlock(&h->wlock);
        return 0;
    }
    r->w.r = r;
    r->w.conn = c;
    snprintf(r->w.jid, sizeof r->w.jid, "%s", jid);
    r->w.deadline = vx_mono() + wait_s;
    MHD_suspend_connection(c);
    r->waiting = 1;
    r->w.next = h->waiters;
    h->waiters = &r->w;
    pthread_cond_signal(&h->wcond);
    pthread_mutex_unlock(&h->wlock);
    return 1;
}

/* ---- disk space ---------------------------------------------------- */

/* Free bytes of the data dir's file system (UINT64_MAX when unknown). */
static uint64_t disk_free(vx_http *h)
{
    uint64_t b;
    return vx_disk_free(vx_store_dir(h->d.store), &b) == 0 ? b : UINT64_MAX;
}

/* 1 when the data dir has room for writes: free space at or above the
 * floor (with a floor of 0, any free byte). */
static int disk_ok(vx_http *h, uint64_t *free_bytes)
{
    uint64_t b = disk_free(h);
    if (free_bytes) *free_bytes = b;
    return h->d.cfg->min_free_disk ? b >= h->d.cfg->min_free_disk : b > 0;
}

/* ---- slow clients (see the top of the file) ------------------------- */

#define BODY_GRACE_S 2.0  /* a body is not rated before this */
#define BODY_WINDOW_S 2.0 /* then each window must carry min_body_rate * window */
#define KILL_LINGER_S 0.5 /* between our answer and closing the read side */
#define SWEEP_US 100000
#define EVICT_MIN_AGE_S 0.25 /* a head or idle time this young is nobody's attack */

static vconn *conn_of(struct MHD_Connection *c)
{
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
    return ci ? ci->socket_context : NULL;
}

/* Answers a connection behind libmicrohttpd's back: writes a canned JSON
 * error (status 0: none), shuts the socket for writing, and for reading
 * too when rd (else the sweeper does it after KILL_LINGER_S; libmicrohttpd
 * then reads EOF and closes it). Only while libmicrohttpd is reading the
 * socket, with h->clock held. Returns the bytes written. */
static size_t kill_conn(vconn *vc, int status, const char *code, const char *message, int rd)
{
    char body[256], msg[512];
    int n = 0;
    if (status) {
        int bn = snprintf(body, sizeof body, "{\"error\":{\"code\":\"%s\",\"message\":\"%s\"}}",
                          code, message);
        n = snprintf(
            msg, sizeof msg,
            "HTTP/1.1 %d %s\r\nContent-Type: application/json\r\nCache-Control: no-store\r\n"
            "Connection: close\r\nContent-Length: %d\r\n\r\n%s",
            status, status == 408 ? "Request Timeout" : "URI Too Long", bn, body);
        if (send(vc->fd, msg, (size_t)n, MSG_NOSIGNAL | MSG_DONTWAIT) < 0) n = 0;
    }
    shutdown(vc->fd, rd ? SHUT_RDWR : SHUT_WR);
    vc->killed = 1;
    vc->kill_status = status;
    vc->rd_closed = rd;
    vc->t_killed = vx_mono();
    return (size_t)n;
}

/* Logs and counts an answer given by kill_conn before the head was read
 * (no request, so on_completed never sees it). */
static void note_head_kill(int status, double dt, size_t bytes, const char *why)
{
    vx_metrics_request(vx_req_route_name(VX_R_UNKNOWN), "other", status, dt, 0, bytes);
    VX_INFO("http.request",
            "method=- route=unmatched status=%d ms=%.2f bytes_in=0 bytes_out=%zu reason=%s", status,
            dt * 1e3, bytes, why);
}

static void on_connection(void *cls, struct MHD_Connection *c, void **socket_context,
                          enum MHD_ConnectionNotificationCode code)
{
    vx_http *h = cls;
    if (code == MHD_CONNECTION_NOTIFY_STARTED) {
        const union MHD_ConnectionInfo *ci =
            MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
        vconn *vc = ci ? calloc(1, sizeof *vc) : NULL;
        if (!vc) return; /* untracked: only libmicrohttpd's timeouts apply */
        vc->fd = ci->connect_fd;
        vc->phase = P_HEAD;
        vc->t_phase = vx_mono();
        pthread_mutex_lock(&h->clock);
        vc->next = h->conns;
        if (h->conns) h->conns->prev = vc;
        h->conns = vc;
        h->nconns++;
        pthread_mutex_unlock(&h->clock);
        *socket_context = vc;
        return;
    }
    vconn *vc = *socket_context;
    if (!vc) return;
    pthread_mutex_lock(&h->clock);
    if (vc->prev)
        vc->prev->next = vc->next;
    else
        h->conns = vc->next;
    if (vc->next) vc->next->prev = vc->prev;
    h->nconns--;
    pthread_mutex_unlock(&h->clock);
    free(vc);
    *socket_context = NULL;
}

/* URI log callback: runs when the request line is in, before the headers. */
static void *on_uri(void *cls, const char *uri, struct MHD_Connection *c)
{
    vx_http *h = cls;
    vconn *vc;
    if (strlen(uri) <= h->d.cfg->max_uri_bytes || !(vc = conn_of(c))) return NULL;
    pthread_mutex_lock(&h->clock);
    size_t n = vc->killed ? 0
                          : kill_conn(vc, 414, "uri_too_long",
                                      "the request target is longer than max-uri-bytes", 0);
    double dt = vx_mono() - vc->t_phase;
    pthread_mutex_unlock(&h->clock);
    if (n) note_head_kill(414, dt, n, "uri_too_long");
    return NULL;
}

/* 1 when bytes wait in the kernel that libmicrohttpd has not read yet: its
 * thread is busy (a long handler), so a slow head or body is not the
 * client's doing and is not held against it. */
static int unread(const vconn *vc)
{
    int n = 0;
    return ioctl(vc->fd, FIONREAD, &n) == 0 && n > 0;
}

static int by_phase_time(const void *a, const void *b)
{
    double x = (*(vconn *const *)a)->t_phase, y = (*(vconn *const *)b)->t_phase;
    return x < y ? -1 : x > y;
}

/* One pass of the sweeper, with h->clock held. */
static void sweep(vx_http *h, vconn **cand)
{
    const vx_config *cfg = h->d.cfg;
    double now = vx_mono();
    size_t live = 0, ncand = 0;
    for (vconn *vc = h->conns; vc; vc = vc->next) {
        if (vc->killed) {
            if (!vc->rd_closed && now - vc->t_killed >= KILL_LINGER_S) {
                shutdown(vc->fd, SHUT_RD);
                vc->rd_closed = 1;
            }
            continue;
        }
        if (vc->phase == P_IDLE) {
            /* Has a byte of the next request come in since the answer? The
             * kernel knows when data last arrived; libmicrohttpd has
             * already read it into its buffer. */
            struct tcp_info ti;
            socklen_t tl = sizeof ti;
            if (getsockopt(vc->fd, IPPROTO_TCP, TCP_INFO, &ti, &tl) == 0) {
                double last = now - ti.tcpi_last_data_recv / 1000.0;
                if (last > vc->t_phase + 0.02) {
                    vc->phase = P_HEAD;
                    vc->t_phase = last;
                }
            }
        }
        if (vc->phase == P_HEAD && cfg->header_timeout_s > 0 &&
            now - vc->t_phase > cfg->header_timeout_s && !unread(vc)) {
            char m[96];
            snprintf(m, sizeof m, "the request head did not arrive within %g s",
                     cfg->header_timeout_s);
            size_t n = kill_conn(vc, 408, "request_timeout", m, 0);
            note_head_kill(408, now - vc->t_phase, n, "header_timeout");
            continue;
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
                vc->win_t0 = now;
                vc->win_bytes = vc->body_bytes;
            }
        }
        live++;
        if ((vc->phase == P_HEAD || vc->phase == P_IDLE) && cand) cand[ncand++] = vc;
    }
    /* Headroom: from 90% of the connections down to 80%, oldest first. */
    size_t max = (size_t)cfg->max_connections;
    size_t high = max >= 10 ? max - max / 10 : max, low = max >= 10 ? max - max / 5 : max - 1;
    if (live < high || !cand) return;
    qsort(cand, ncand, sizeof *cand, by_phase_time);
    for (size_t i = 0; i < ncand && live > low; i++) {
        vconn *vc = cand[i];
        if (now - vc->t_phase < EVICT_MIN_AGE_S || unread(vc)) continue;
        live--;
        if (vc->phase == P_HEAD) {
            size_t n = kill_conn(vc, 408, "request_timeout",
                                 "the server is busy and the request head was not complete", 1);
            note_head_kill(408, now - vc->t_phase, n, "evicted");
        } else {
            kill_conn(vc, 0, NULL, NULL, 1);
        }
    }
    for (vconn *vc = h->conns; vc; vc = vc->next) /* free the victims' slots now */
        if (vc->killed && !vc->rd_closed) {
            shutdown(vc->fd, SHUT_RD);
            vc->rd_closed = 1;
        }
}

static void *sweeper_main(void *arg)
{
    vx_http *h = arg;
    size_t cap = 0;
    vconn **cand = NULL;
    while (!__atomic_load_n(&h->sweep_stop, __ATOMIC_ACQUIRE)) {
        usleep(SWEEP_US);
        pthread_mutex_lock(&h->clock);
        if (h->nconns > cap) {
            size_t ncap = h->nconns * 2;
            vconn **nc = realloc(cand, ncap * sizeof *nc);
            if (nc) {
                cand = nc;
                cap = ncap;
            }
        }
        sweep(h, h->nconns <= cap ? cand : NULL);
        pthread_mutex_unlock(&h->clock);
    }
    free(cand);
    return NULL;
}

/* ---- handlers ------------------------------------------------------ */

static int h_readyz(vx_http *h, struct MHD_Connection *c, req *r)
{
    int gl = vx_jobs_ready(h->d.jobs);
    int q = vx_jobs_queue_depth(h->d.jobs) < vx_jobs_queue_capacity(h->d.jobs);
    int dd = vx_store_writable(h->d.store);
    int space = disk_ok(h, NULL);
    int ok = gl && q && dd && space && !h->stopping;
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddStringToObject(doc, "status", ok ? "ready" : "not_ready");
    cJSON *chk = cJSON_AddObjectToObject(doc, "checks");
    cJSON_AddBoolToObject(chk, "gl", gl);
    cJSON_AddBoolToObject(chk, "queue", q);
    cJSON_AddBoolToObject(chk, "data_dir", dd);
    cJSON_AddBoolToObject(chk, "disk_space", space);
    return send_json(c, r, ok ? 200 : 503, doc, NULL, NULL);
}

static int h_metrics(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_metrics_gauges g = {
        .queue_depth = vx_jobs_queue_depth(h->d.jobs),
        .queue_capacity = vx_jobs_queue_capacity(h->d.jobs),
        .running = vx_jobs_running(h->d.jobs),
        .meshes = vx_store_mesh_count(h->d.store),
        .results_bytes = vx_store_results_bytes(h->d.store),
        .disk_free_bytes = disk_free(h),
        .min_free_disk = h->d.cfg->min_free_disk,
        .ready = vx_jobs_ready(h->d.jobs),
        .gl = vx_jobs_gl_info(h->d.jobs),
        .start_time = h->d.start_time,
    };
    return send_text(c, r, 200, vx_metrics_render(&g), "text/plain; version=0.0.4; charset=utf-8",
                     NULL, NULL);
}

static int h_info(vx_http *h, struct MHD_Connection *c, req *r)
{
    const vx_config *cfg = h->d.cfg;
    vx_gl_info gi = vx_jobs_gl_info(h->d.jobs);
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddStringToObject(doc, "name", "voxeld");
    cJSON_AddStringToObject(doc, "version", VX_VERSION);
    cJSON_AddNumberToObject(doc, "uptime_s", floor((vx_now() - h->d.start_time) * 1000) / 1000);
    cJSON *gl = cJSON_AddObjectToObject(doc, "gl");
    cJSON_AddStringToObject(gl, "vendor", gi.vendor);
    cJSON_AddStringToObject(gl, "renderer", gi.renderer);
    cJSON_AddStringToObject(gl, "version", gi.version);
    cJSON_AddStringToObject(gl, "glsl", gi.glsl);
    cJSON_AddStringToObject(gl, "device_kind", gi.device_kind[0] ? gi.device_kind : "surfaceless");
    cJSON_AddNumberToObject(gl, "device_index", gi.device_index);
    cJSON_AddBoolToObject(gl, "robust", gi.robust);
    cJSON *l = cJSON_AddObjectToObject(doc, "limits");
    cJSON_AddNumberToObject(l, "max_upload_bytes", (double)cfg->max_upload_bytes);
    cJSON_AddNumberToObject(l, "max_triangles", (double)cfg->max_triangles);
    cJSON_AddNumberToObject(l, "max_queued_jobs", (double)cfg->max_queued_jobs);
    cJSON_AddNumberToObject(l, "job_timeout_s", cfg->job_timeout_s);
    cJSON_AddNumberToObject(l, "max_wait_s", cfg->request_timeout_s);
    cJSON_AddNumberToObject(l, "request_timeout_s", cfg->request_timeout_s);
    cJSON_AddNumberToObject(l, "connection_timeout_s", cfg->connection_timeout_s);
    cJSON_AddNumberToObject(l, "header_timeout_s", cfg->header_timeout_s);
    cJSON_AddNumberToObject(l, "min_body_rate", (double)cfg->min_body_rate);
    cJSON_AddNumberToObject(l, "max_uri_bytes", (double)cfg->max_uri_bytes);
    cJSON_AddNumberToObject(l, "max_header_bytes", (double)cfg->max_header_bytes);
    cJSON_AddNumberToObject(l, "max_connections_per_ip", (double)cfg->max_connections_per_ip);
    cJSON_AddNumberToObject(l, "max_image_pixels", (double)cfg->max_image_pixels);
    cJSON_AddNumberToObject(l, "max_job_memory_bytes", (double)cfg->max_job_memory);
    cJSON_AddNumberToObject(l, "max_json_bytes", (double)cfg->max_json_bytes);
    cJSON_AddNumberToObject(l, "min_free_disk_bytes", (double)cfg->min_free_disk);
    cJSON_AddNumberToObject(l, "max_parse_memory_bytes", (double)cfg->max_parse_memory);
    cJSON_AddNumberToObject(l, "results_max_bytes", (double)cfg->results_max_bytes);
    cJSON_AddNumberToObject(l, "results_max_age_s", cfg->results_max_age_s);
    cJSON_AddNumberToObject(l, "job_history", (double)cfg->job_history);
    cJSON_AddNumberToObject(l, "job_history_bytes", (double)cfg->job_history_bytes);
    cJSON *kinds = cJSON_AddArrayToObject(doc, "kinds");
    for (size_t i = 0; i < vx_kind_count(); i++) {
        cJSON *k = cJSON_CreateObject();
        cJSON_AddStringToObject(k, "name", vx_kind_at(i)->name);
        cJSON_AddStringToObject(k, "summary", vx_kind_at(i)->summary);
        cJSON_AddItemToArray(kinds, k);
    }
    cJSON_AddBoolToObject(doc, "auth", h->auth);
    return send_json(c, r, 200, doc, NULL, NULL);
}

static int h_mesh_list(vx_http *h, struct MHD_Connection *c, req *r)
{
    int limit = r->q.limit;
    const char *after = r->q.has_after ? r->q.after : NULL;
    char next[65];
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddItemToObject(doc, "items", vx_store_mesh_list(h->d.store, after, limit, next));
    if (next[0])
        cJSON_AddStringToObject(doc, "next", next);
    else
        cJSON_AddNullToObject(doc, "next");
    return send_json(c, r, 200, doc, NULL, NULL);
}

static int h_mesh(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    if (!vx_store_valid_mesh_id(r->id))
        return send_error(c, r, 404, "mesh_not_found",
                          "no mesh with that id (ids are 64 hex digits)");
    if (!strcmp(r->method, "DELETE")) {
        if (vx_store_mesh_delete(h->d.store, r->id, &err)) return send_err(c, r, &err);
        VX_INFO("mesh.deleted", "mesh=%s", r->id);
        return send_text(c, r, 204, NULL, "application/json", NULL, NULL);
    }
    cJSON *meta = vx_store_mesh_meta(h->d.store, r->id, &err);
    if (!meta) return send_err(c, r, &err);
    return send_json(c, r, 200, meta, NULL, NULL);
}

static cJSON *mesh_meta(const char *id, const char *format, uint64_t bytes, const vx_mesh *m)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "id", id);
    cJSON_AddStringToObject(o, "format", format);
    cJSON_AddNumberToObject(o, "bytes", (double)bytes);
    cJSON_AddNumberToObject(o, "vertices", (double)m->nverts);
    cJSON_AddNumberToObject(o, "triangles", (double)m->ntris);
    cJSON *f = cJSON_AddObjectToObject(o, "faces");
    cJSON_AddNumberToObject(f, "total", (double)m->nfaces);
    cJSON_AddNumberToObject(f, "triangles", (double)m->faces_by_size[0]);
    cJSON_AddNumberToObject(f, "quads", (double)m->faces_by_size[1]);
    cJSON_AddNumberToObject(f, "ngons", (double)m->faces_by_size[2]);
    cJSON *bb = cJSON_AddObjectToObject(o, "bbox");
    cJSON_AddItemToObject(bb, "min", cJSON_CreateDoubleArray(m->bbox_min, 3));
    cJSON_AddItemToObject(bb, "max", cJSON_CreateDoubleArray(m->bbox_max, 3));
    cJSON_AddNumberToObject(o, "boundary_edges", (double)m->boundary_edges);
    cJSON_AddNumberToObject(o, "nonmanifold_edges", (double)m->nonmanifold_edges);
    cJSON_AddNumberToObject(o, "degenerate_triangles", (double)m->degenerate_tris);
    cJSON_AddNumberToObject(o, "texcoords", (double)m->ntexcoords);
    cJSON_AddNumberToObject(o, "normals", (double)m->nnormals);
    cJSON_AddNumberToObject(o, "patches", (double)m->npatches);
    char t[32];
    vx_rfc3339(vx_now(), t);
    cJSON_AddStringToObject(o, "created", t);
    return o;
}

/* The worst-case memory of the upload parses running now (--max-parse-memory). */
static vx_budget parse_budget = VX_BUDGET_INIT;

/* The body has been streamed to a temp file: hash known, now validate. */
static int h_upload_done(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    vx_err_clear(&err);
    if (r->too_big) {
        char msg[128];
        snprintf(msg, sizeof msg, "the body is larger than the %llu-byte upload limit",
                 (unsigned long long)h->d.cfg->max_upload_bytes);
        return send_error(c, r, 413, "too_large", msg);
    }
    if (r->body_err.kind != VX_EOK) return send_err(c, r, &r->body_err);
    if (vx_upload_bytes(r->up) == 0)
        return send_error(c, r, 422, "obj_no_faces", "the body is empty: no faces");
    char id[65];
    if (vx_upload_finish(r->up, id, &err)) return send_err(c, r, &err);
    size_t nhead;
    const unsigned char *head = vx_upload_head(r->up, &nhead);
    vx_mesh_format fmt = vx_mesh_sniff(head, nhead);
    if ((r->declared == MEDIA_OBJ || r->declared == MEDIA_TEXT) && fmt == VX_MESH_DRACO)
        return send_error(c, r, 415, "unsupported_media_type",
                          "Content-Type says text (OBJ or .bpt) but the body is a Draco file");
    if (r->declared == MEDIA_DRACO && fmt != VX_MESH_DRACO)
        return send_error(c, r, 415, "unsupported_media_type",
                          "Content-Type says Draco but the body does not start with DRACO");
    if (r->declared == MEDIA_BPT && fmt != VX_MESH_BPT)
        return send_error(c, r, 415, "unsupported_media_type",
                          "Content-Type says .bpt but the first line is not a patch count");
    if (r->declared == MEDIA_SNIFF && fmt == 0)
        return send_error(c, r, 415, "unsupported_media_type",
                          "the body is neither text (OBJ, .bpt) nor a Draco file");
    cJSON *meta = vx_store_mesh_meta(h->d.store, id, NULL);
    if (meta) {
        VX_INFO("mesh.uploaded", "mesh=%s new=0", id);
        return send_json(c, r, 200, meta, NULL, NULL);
    }
    if (r->declared == MEDIA_OBJ || (r->declared == MEDIA_TEXT && fmt != VX_MESH_BPT))
        fmt = VX_MESH_OBJ;
    vx_mesh_limits lim = {.max_triangles = h->d.cfg->max_triangles};
    const char *fname = fmt == VX_MESH_DRACO ? "draco" : fmt == VX_MESH_BPT ? "bpt" : "obj";
    /* Reserve the parse's worst-case memory first; the upload was not
     * acknowledged, so a busy answer loses nothing. */
    uint64_t cost = vx_mesh_parse_cost(vx_upload_path(r->up), fmt, vx_upload_bytes(r->up), &lim);
    uint64_t budget = h->d.cfg->max_parse_memory;
    vx_budget_result br = vx_budget_reserve(&parse_budget, cost, budget);
    if (br != VX_BUDGET_OK) {
        char msg[256];
        VX_INFO("mesh.parse_budget", "format=%s bytes=%llu cost=%llu used=%llu limit=%llu", fname,
                (unsigned long long)vx_upload_bytes(r->up), (unsigned long long)cost,
                (unsigned long long)vx_budget_used(&parse_budget), (unsigned long long)budget);
        if (br == VX_BUDGET_TOO_BIG) {
            snprintf(msg, sizeof msg,
                     "parsing this %s upload may take up to %llu bytes of memory, more than the "
                     "max-parse-memory limit of %llu bytes",
                     fname, (unsigned long long)cost, (unsigned long long)budget);
            return send_error(c, r, 413, "parse_too_big", msg);
        }
        snprintf(msg, sizeof msg,
                 "other uploads being parsed hold the memory this %s upload may need (%llu of "
                 "max-parse-memory's %llu bytes); retry later",
                 fname, (unsigned long long)cost, (unsigned long long)budget);
        return send_error_h(c, r, 503, "busy_parsing", msg, MHD_HTTP_HEADER_RETRY_AFTER, "2");
    }
    double t = vx_mono();
    vx_mesh *m = vx_mesh_read_as(vx_upload_path(r->up), fmt, &lim, &err);
    if (!m) {
        vx_budget_release(&parse_budget, cost);
        char q[600];
        VX_INFO("mesh.rejected", "code=%s message=%s", err.code,
                vx_log_quote(q, sizeof q, err.message));
        return send_err(c, r, &err);
    }
    double parse_ms = (vx_mono() - t) * 1e3;
    if (m->degenerate_tris == m->ntris) {
        vx_mesh_free(m);
        vx_budget_release(&parse_budget, cost);
        return send_error(c, r, 422, "degenerate_mesh", "every triangle of the mesh has zero area");
    }
    meta = mesh_meta(id, fname, vx_upload_bytes(r->up), m);
    VX_INFO("mesh.uploaded",
            "mesh=%s new=1 format=%s bytes=%llu vertices=%zu triangles=%zu parse_ms=%.1f", id,
            fname, (unsigned long long)vx_upload_bytes(r->up), m->nverts, m->ntris, parse_ms);
    vx_mesh_free(m);
    vx_budget_release(&parse_budget, cost);
    int existed = 0;
    vx_upload *up = r->up;
    r->up = NULL; /* commit frees it */
    if (vx_store_mesh_commit(h->d.store, up, id, fmt == VX_MESH_DRACO ? "drc" : fname, meta,
                             &existed, &err)) {
        cJSON_Delete(meta);
        return send_err(c, r, &err);
    }
    char loc[128];
    snprintf(loc, sizeof loc, "/v1/meshes/%s", id);
    if (existed) { /* a concurrent upload of the same bytes won */
        cJSON_Delete(meta);
        meta = vx_store_mesh_meta(h->d.store, id, NULL);
        return send_json(c, r, 200, meta, NULL, NULL);
    }
    return send_json(c, r, 201, meta, MHD_HTTP_HEADER_LOCATION, loc);
}

static int answer_job(vx_http *h, struct MHD_Connection *c, req *r, const char *jid,
                      unsigned status)
{
    vx_err err;
    cJSON *doc = vx_jobs_get(h->d.jobs, jid, NULL, &err);
    if (!doc) return send_err(c, r, &err);
    char loc[128];
    snprintf(loc, sizeof loc, "/v1/jobs/%s", jid);
    return send_json(c, r, status, doc, status == 202 ? MHD_HTTP_HEADER_LOCATION : NULL, loc);
}

static int h_job_post_done(vx_http *h, struct MHD_Connection *c, req *r)
{
    if (r->too_big)
        return send_error(c, r, 413, "too_large", "the JSON body is larger than max-json-bytes");
    double wait_s = wait_seconds(h, r);
    char why[128];
    if (vx_req_json_text_ok(r->buf ? r->buf : "", r->len, why, sizeof why))
        return send_error(c, r, 400, "invalid_json", why);
    cJSON *doc = cJSON_ParseWithLength(r->buf ? r->buf : "", r->len);
    if (!doc) return send_error(c, r, 400, "invalid_json", "the body is not valid JSON");
    const char *msg = NULL;
    const cJSON *mesh = cJSON_GetObjectItemCaseSensitive(doc, "mesh");
    const cJSON *kind = cJSON_GetObjectItemCaseSensitive(doc, "kind");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(doc, "params");
    if (!cJSON_IsObject(doc))
        msg = "the body must be a JSON object";
    else if (!cJSON_IsString(mesh))
        msg = "\"mesh\" (a mesh id string) is required";
    else if (!cJSON_IsString(kind))
        msg = "\"kind\" (a job kind string) is required";
    else if (params && !cJSON_IsObject(params))
        msg = "\"params\" must be an object";
    else {
        const cJSON *it;
        cJSON_ArrayForEach(it, doc) if (strcmp(it->string, "mesh") && strcmp(it->string, "kind") &&
                                        strcmp(it->string, "params")) msg =
            "unknown field in the job request";
    }
    if (msg) {
        cJSON_Delete(doc);
        return send_error(c, r, 400, "invalid_request", msg);
    }
    vx_err err;
    vx_err_clear(&err);
    cJSON *job = NULL;
    if (!vx_store_valid_mesh_id(mesh->valuestring))
        vx_err_set(&err, VX_EINVAL, "invalid_request",
                   "\"mesh\" must be a mesh id (64 hex digits)");
    else
        job = vx_jobs_submit(h->d.jobs, mesh->valuestring, kind->valuestring, params, &err);
    cJSON_Delete(doc);
    if (!job) return send_err(c, r, &err);
    char jid[33];
    snprintf(jid, sizeof jid, "%s",
             cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "id")));
    if (wait_s > 0) {
        r->post_job = 1;
        snprintf(r->id, sizeof r->id, "%s", jid);
        if (hold(h, c, r, jid, wait_s)) {
            cJSON_Delete(job);
            return MHD_YES;
        }
        cJSON_Delete(job);
        return answer_job(h, c, r, jid, 202);
    }
    char loc[128];
    snprintf(loc, sizeof loc, "/v1/jobs/%s", jid);
    return send_json(c, r, 202, job, MHD_HTTP_HEADER_LOCATION, loc);
}

static int h_job_list(vx_http *h, struct MHD_Connection *c, req *r)
{
    int limit = r->q.limit;
    const char *after = r->q.has_after ? r->q.after : NULL,
               *state = r->q.has_state ? r->q.state : NULL;
    char next[40];
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddItemToObject(doc, "items", vx_jobs_list(h->d.jobs, after, limit, state, next));
    if (next[0])
        cJSON_AddStringToObject(doc, "next", next);
    else
        cJSON_AddNullToObject(doc, "next");
    return send_json(c, r, 200, doc, NULL, NULL);
}

static int h_job(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    if (!strcmp(r->method, "DELETE")) {
        int running;
        cJSON *doc = vx_jobs_cancel(h->d.jobs, r->id, &running, &err);
        if (!doc) return send_err(c, r, &err);
        return send_json(c, r, running ? 202 : 200, doc, NULL, NULL);
    }
    double wait_s = wait_seconds(h, r);
    if (wait_s > 0 && hold(h, c, r, r->id, wait_s)) return MHD_YES;
    return answer_job(h, c, r, r->id, 200);
}

static int h_result(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    char path[2400], ctype[64], fname[128];
    if (vx_jobs_output(h->d.jobs, r->id, r->route == VX_R_RESULT_NAME ? r->name : NULL, path,
                       sizeof path, ctype, fname, &err))
        return send_err(c, r, &err);
    char etag[160], disp[200];
    snprintf(etag, sizeof etag, "\"%s\"", fname);
    snprintf(disp, sizeof disp, "attachment; filename=\"%s\"", fname);
    const char *inm = header(c, MHD_HTTP_HEADER_IF_NONE_MATCH);
    if (inm && (strstr(inm, etag) || !strcmp(inm, "*"))) {
        struct MHD_Response *resp =
            MHD_create_response_from_buffer(0, (void *)"", MHD_RESPMEM_PERSISTENT);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
        return queue(c, r, 304, resp, 0);
    }
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0) {
        if (fd >= 0) close(fd);
        return send_error(c, r, 410, "result_evicted", "the result file is gone");
    }
    /* from_fd lets MHD use sendfile(2); it closes fd with the response. */
    struct MHD_Response *resp = MHD_create_response_from_fd64((uint64_t)st.st_size, fd);
    if (!resp) {
        close(fd);
        return MHD_NO;
    }
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
    MHD_add_response_header(resp, "Content-Disposition", disp);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL,
                            "private, max-age=86400, immutable");
    return queue(c, r, 200, resp, (uint64_t)st.st_size);
}

/* ---- dispatch ------------------------------------------------------ */

static enum MHD_Result count_host(void *cls, enum MHD_ValueKind kind, const char *key,
                                  const char *value)
{
    if (key && !strcasecmp(key, MHD_HTTP_HEADER_HOST)) (*(int *)cls)++;
    return MHD_YES;
}

static enum MHD_Result take_arg(void *cls, enum MHD_ValueKind kind, const char *key, size_t klen,
                                const char *value, size_t vlen)
{
    req *r = cls;
    if (!key) return MHD_YES;
    return vx_req_query_add(&r->q, r->route, r->method, key, klen, value, vlen, r->qerr,
                            sizeof r->qerr)
               ? MHD_NO
               : MHD_YES;
}

/* Framing the access handler can still answer in JSON: Host, the transfer
 * coding, both lengths at once. Returns a queued answer or -1. */
static int check_framing(struct MHD_Connection *c, req *r, const char *version)
{
    int hosts = 0;
    MHD_get_connection_values(c, MHD_HEADER_KIND, count_host, &hosts);
    if (strcmp(version, MHD_HTTP_VERSION_1_0) != 0 && hosts != 1)
        return send_error(c, r, 400, "invalid_request",
                          hosts ? "more than one Host header"
                                : "an HTTP/1.1 request needs a Host header");
    const char *te = header(c, MHD_HTTP_HEADER_TRANSFER_ENCODING);
    int coding = vx_req_transfer_encoding(te);
    if (coding < 0)
        return send_error(c, r, 501, "not_implemented",
                          "the only transfer coding taken is chunked (no gzip, no lists)");
    if (coding > 0 && header(c, MHD_HTTP_HEADER_CONTENT_LENGTH))
        return send_error(c, r, 400, "invalid_request",
                          "Content-Length and Transfer-Encoding together");
    return -1;
}

static int first_call(vx_http *h, struct MHD_Connection *c, req *r, const char *version)
{
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_REQUEST_HEADER_SIZE);
    if (ci && ci->header_size > h->d.cfg->max_header_bytes)
        return send_error(c, r, 431, "header_too_large",
                          "the request head is larger than max-header-bytes");
    int rc = check_framing(c, r, version);
    if (rc >= 0) return rc;
    if (r->route == VX_R_UNKNOWN) return send_error(c, r, 404, "not_found", "no such route");
    if (!strncmp(vx_req_route_name(r->route), "/v1/", 4) && h->auth && !auth_ok(h, c))
        return send_error_h(c, r, 401, "unauthorized", "a valid bearer token is required",
                            MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"voxeld\"");
    if (!vx_req_method_allowed(r->route, r->method)) {
        char msg[96];
        snprintf(msg, sizeof msg, "method %s is not allowed here", r->method);
        return send_error_h(c, r, 405, "method_not_allowed", msg, MHD_HTTP_HEADER_ALLOW,
                            vx_req_route_allow(r->route));
    }
    vx_req_query_init(&r->q);
    MHD_get_connection_values_n(c, MHD_GET_ARGUMENT_KIND, take_arg, r);
    if (strcmp(r->method, "POST") != 0) return -1; /* no body: answer in dispatch */
    if (h->stopping || !vx_jobs_ready(h->d.jobs))
        return send_error_h(c, r, 503, "not_ready", "the daemon is not ready",
                            MHD_HTTP_HEADER_RETRY_AFTER, "5");
    if (r->qerr[0]) return send_error(c, r, 400, "invalid_request", r->qerr);

    uint64_t nfree;
    if (!disk_ok(h, &nfree)) {
        char msg[200];
        snprintf(
            msg, sizeof msg,
            "the data dir is full: %llu bytes free, under the %llu-byte floor (--min-free-disk); "
            "reads still work",
            (unsigned long long)(nfree == UINT64_MAX ? 0 : nfree),
            (unsigned long long)h->d.cfg->min_free_disk);
        return send_error(c, r, 507, "insufficient_storage", msg);
    }
    char mt[128];
    vx_req_media_type(header(c, MHD_HTTP_HEADER_CONTENT_TYPE), mt, sizeof mt);
    if (r->route == VX_R_MESHES) {
        if (!strcmp(mt, "model/obj"))
            r->declared = MEDIA_OBJ;
        else if (!strcmp(mt, "text/plain"))
            r->declared = MEDIA_TEXT;
        else if (!strcmp(mt, "model/x-bpt"))
            r->declared = MEDIA_BPT;
        else if (!strcmp(mt, "model/x-draco") || !strcmp(mt, "application/x-draco"))
            r->declared = MEDIA_DRACO;
        else if (!mt[0] || !strcmp(mt, "application/octet-stream"))
            r->declared = MEDIA_SNIFF;
        else {
            char msg[200];
            snprintf(msg, sizeof msg,
                     "cannot take '%.100s': send model/obj, model/x-bpt, model/x-draco or "
                     "application/octet-stream",
                     mt);
            return send_error(c, r, 415, "unsupported_media_type", msg);
        }
        r->body = BODY_UPLOAD;
    } else {
        if (strcmp(mt, "application/json") != 0)
            return send_error(c, r, 415, "unsupported_media_type",
                              "the body must be application/json");
        r->body = BODY_JSON;
    }
    const char *cl = header(c, MHD_HTTP_HEADER_CONTENT_LENGTH);
    const char *te = header(c, MHD_HTTP_HEADER_TRANSFER_ENCODING);
    uint64_t limit =
        r->route == VX_R_MESHES ? h->d.cfg->max_upload_bytes : h->d.cfg->max_json_bytes;
    if (r->route == VX_R_MESHES && !cl && vx_req_transfer_encoding(te) != 1)
        return send_error(c, r, 411, "length_required",
                          "Content-Length or chunked encoding is required");
    if (cl) {
        uint64_t n;
        if (vx_req_parse_length(cl, &n))
            return send_error(c, r, 400, "invalid_request", "bad Content-Length");
        if (n > limit) {
            char msg[128];
            snprintf(msg, sizeof msg, "the body (%llu bytes) is larger than the %llu-byte limit",
                     (unsigned long long)n, (unsigned long long)limit);
            return send_error(c, r, 413, "too_large", msg);
        }
    }
    if (r->body == BODY_UPLOAD) {
        vx_err err;
        r->up = vx_upload_begin(h->d.store, &err);
        if (!r->up) return send_err(c, r, &err);
    }
    return -1;
}

static int take_body(vx_http *h, req *r, const char *data, size_t n)
{
    r->bytes_in += n;
    if (r->body == BODY_UPLOAD) {
        if (r->too_big || r->body_err.kind != VX_EOK) return 0;
        if (r->bytes_in > h->d.cfg->max_upload_bytes) {
            /* Keep reading (and dropping) the rest, answer 413 at the end. */
            r->too_big = 1;
            vx_upload_abort(r->up);
            r->up = NULL;
            return 0;
        }
        if (vx_upload_write(r->up, data, n, &r->body_err)) {
            /* Keep reading (and dropping) the rest: the client gets the
             * answer (507 on a full disk) at the end, not a dropped connection. */
            VX_ERROR("http.upload_failed", "code=%s", r->body_err.code);
            vx_upload_abort(r->up);
            r->up = NULL;
        }
        return 0;
    }
    if (r->too_big) return 0;
    if (r->len + n > h->d.cfg->max_json_bytes) {
        r->too_big = 1;
        return 0;
    }
    if (r->len + n + 1 > r->cap) {
        size_t cap = (r->len + n + 1) * 2;
        char *nb = realloc(r->buf, cap);
        if (!nb) return -1;
        r->buf = nb;
        r->cap = cap;
    }
    memcpy(r->buf + r->len, data, n);
    r->len += n;
    return 0;
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url,
                                  const char *method, const char *version, const char *data,
                                  size_t *data_size, void **con_cls)
{
    vx_http *h = cls;
    req *r = *con_cls;
    if (!r) {
        /* The head is in: the connection leaves HEAD (unless the sweeper
         * has already answered it, and then nothing may be queued). */
        vconn *vc = conn_of(c);
        if (vc) {
            pthread_mutex_lock(&h->clock);
            int dead = vc->killed;
            vc->phase = P_BUSY;
            vc->t_phase = vx_mono();
            pthread_mutex_unlock(&h->clock);
            if (dead) return MHD_NO;
        }
        r = calloc(1, sizeof *r);
        if (!r) return MHD_NO;
        *con_cls = r;
        r->vc = vc;
        r->t0 = vx_mono();
        snprintf(r->method, sizeof r->method, "%s", method);
        vx_req_target t;
        r->route = vx_req_route(url, strlen(url), &t);
        memcpy(r->id, t.id, sizeof r->id);
        memcpy(r->name, t.name, sizeof r->name);
        int rc = first_call(h, c, r, version);
        if (rc >= 0) return rc;
        if (vc && !strcmp(r->method, "POST")) { /* a body follows: rate it */
            pthread_mutex_lock(&h->clock);
            vc->phase = P_BODY;
            vc->t_phase = vx_mono();
            vc->body_bytes = 0;
            vc->win_started = 0;
            pthread_mutex_unlock(&h->clock);
        }
        /* Answer on the next call even without a body: a response queued
         * in the first call makes libmicrohttpd 0.9.75 close the
         * connection (it cannot know yet that no body follows). */
        return MHD_YES;
    }
    if (r->vc) {
        pthread_mutex_lock(&h->clock);
        int dead = r->vc->killed;
        if (*data_size)
            r->vc->body_bytes += *data_size;
        else if (r->vc->phase == P_BODY) {
            r->vc->phase = P_BUSY;
            r->vc->t_phase = vx_mono();
        }
        pthread_mutex_unlock(&h->clock);
        if (dead) { /* answered by the sweeper: drain, never queue */
            if (!*data_size) return MHD_NO;
            *data_size = 0;
            return MHD_YES;
        }
    }
    if (r->answered) {
        *data_size = 0; /* an early answer was queued: drop what still arrives */
        return MHD_YES;
    } else if (*data_size) {
        if (take_body(h, r, data, *data_size)) {
            *data_size = 0;
            return send_error(c, r, 500, "upload_failed", "could not store the body");
        }
        *data_size = 0;
        return MHD_YES;
    }
    if (r->resumed) {
        r->resumed = 0;
        return answer_job(h, c, r, r->id, r->post_job ? 202 : 200);
    }
    if (r->qerr[0]) return send_error(c, r, 400, "invalid_request", r->qerr);
    int is_get = !strcmp(r->method, "GET") || !strcmp(r->method, "HEAD");
    switch (r->route) {
    case VX_R_LIVEZ:
        return send_text(c, r, 200, strdup("{\"status\":\"ok\"}"), "application/json", NULL, NULL);
    case VX_R_READYZ:
        return h_readyz(h, c, r);
    case VX_R_METRICS:
        return h_metrics(h, c, r);
    case VX_R_INFO:
        return h_info(h, c, r);
    case VX_R_MESHES:
        return is_get ? h_mesh_list(h, c, r) : h_upload_done(h, c, r);
    case VX_R_MESH:
        return h_mesh(h, c, r);
    case VX_R_JOBS:
        return is_get ? h_job_list(h, c, r) : h_job_post_done(h, c, r);
    case VX_R_JOB:
        return h_job(h, c, r);
    case VX_R_RESULT:
    case VX_R_RESULT_NAME:
        return h_result(h, c, r);
    default:
        return send_error(c, r, 404, "not_found", "no such route");
    }
}

static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls,
                         enum MHD_RequestTerminationCode toe)
{
    vx_http *h = cls;
    req *r = *con_cls;
    if (!r) return;
    if (r->waiting) { /* the connection died while held */
        pthread_mutex_lock(&h->wlock);
        waiter **pp = &h->waiters;
        while (*pp && *pp != &r->w)
            pp = &(*pp)->next;
        if (*pp) *pp = r->w.next;
        pthread_mutex_unlock(&h->wlock);
    }
    double dt = vx_mono() - r->t0;
    const char *route = vx_req_route_name(r->route);
    int status = r->status ? r->status : 499; /* closed before an answer */
    if (r->vc) {
        pthread_mutex_lock(&h->clock);
        if (r->vc->killed && r->vc->kill_status)
            status = r->vc->kill_status;
        else if (!r->vc->killed) { /* keep-alive: the next head starts with its first byte */
            r->vc->phase = P_IDLE;
            r->vc->t_phase = vx_mono();
        }
        pthread_mutex_unlock(&h->clock);
    }
    static const char *known[] = {"GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS", NULL};
    const char *mlabel = "other";
    for (int i = 0; known[i]; i++)
        if (!strcmp(known[i], r->method)) mlabel = known[i];
    vx_metrics_request(route, mlabel, status, dt, r->bytes_in, r->bytes_out);
    vx_log_level lvl =
        (r->route == VX_R_LIVEZ || r->route == VX_R_READYZ || r->route == VX_R_METRICS) &&
                status < 400
            ? VX_LOG_DEBUG
            : VX_LOG_INFO;
    vx_log(lvl, "http.request",
           "method=%s route=%s status=%d ms=%.2f bytes_in=%llu bytes_out=%llu%s", r->method, route,
           status, dt * 1e3, (unsigned long long)r->bytes_in, (unsigned long long)r->bytes_out,
           toe == MHD_REQUEST_TERMINATED_COMPLETED_OK ? "" : " aborted=1");
    vx_upload_abort(r->up);
    free(r->buf);
    free(r);
    *con_cls = NULL;
}

static void mhd_log(void *cls, const char *fmt, va_list ap)
{
    char msg[512], q[600];
    vsnprintf(msg, sizeof msg, fmt, ap);
    VX_WARN("http.mhd", "message=%s", vx_log_quote(q, sizeof q, msg));
}

/* ---- lifecycle ----------------------------------------------------- */

static int parse_listen(const char *s, struct sockaddr_storage *ss, socklen_t *len, int *v6,
                        vx_err *err)
{
    char host[256], port[16];
    const char *colon;
    if (s[0] == '[') {
        const char *rb = strchr(s, ']');
        if (!rb || rb[1] != ':') goto bad;
        snprintf(host, sizeof host, "%.*s", (int)(rb - s - 1), s + 1);
        colon = rb + 1;
    } else {
        colon = strrchr(s, ':');
        if (!colon) goto bad;
        snprintf(host, sizeof host, "%.*s", (int)(colon - s), s);
    }
    snprintf(port, sizeof port, "%s", colon + 1);
    struct addrinfo hints = {.ai_family = AF_UNSPEC,
                             .ai_socktype = SOCK_STREAM,
                             .ai_flags = AI_PASSIVE},
                    *ai;
    if (getaddrinfo(host[0] ? host : NULL, port, &hints, &ai) != 0) goto bad;
    memcpy(ss, ai->ai_addr, ai->ai_addrlen);
    *len = ai->ai_addrlen;
    *v6 = ai->ai_family == AF_INET6;
    freeaddrinfo(ai);
    return 0;
bad:
    return vx_err_set(err, VX_EINVAL, "bad_listen",
                      "cannot parse listen address '%s' (want ADDR:PORT)", s);
}

vx_http *vx_http_start(const vx_http_desc *desc, vx_err *err)
{
    vx_http *h = calloc(1, sizeof *h);
    if (!h) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    h->d = *desc;
    g_data_dir = vx_store_dir(desc->store);
    const vx_config *cfg = desc->cfg;
    if (cfg->token[0]) {
        struct sha256_ctx ctx;
        sha256_init(&ctx);
        sha256_update(&ctx, strlen(cfg->token), (const uint8_t *)cfg->token);
        sha256_digest(&ctx, sizeof h->token_digest, h->token_digest);
        h->auth = 1;
    }
    pthread_mutex_init(&h->wlock, NULL);
    pthread_mutex_init(&h->clock, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&h->wcond, &ca);
    pthread_condattr_destroy(&ca);

    struct sockaddr_storage ss;
    socklen_t sslen;
    int v6 = 0;
    if (parse_listen(cfg->listen, &ss, &sslen, &v6, err)) {
        free(h);
        return NULL;
    }
    unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_EPOLL | MHD_ALLOW_SUSPEND_RESUME |
                     MHD_USE_ERROR_LOG | (v6 ? MHD_USE_IPv6 : 0);
    /* Without --reuse-port libmicrohttpd sets only SO_REUSEADDR: a port
     * another process listens on cannot be bound (EADDRINUSE). */
    errno = 0;
    h->mhd = MHD_start_daemon(
        flags, 0, NULL, NULL, on_request, h, MHD_OPTION_EXTERNAL_LOGGER, mhd_log, NULL,
        MHD_OPTION_SOCK_ADDR, (struct sockaddr *)&ss, MHD_OPTION_THREAD_POOL_SIZE,
        (unsigned)cfg->http_threads, MHD_OPTION_CONNECTION_TIMEOUT,
        (unsigned)ceil(cfg->connection_timeout_s), MHD_OPTION_CONNECTION_LIMIT,
        (unsigned)cfg->max_connections, MHD_OPTION_PER_IP_CONNECTION_LIMIT,
        (unsigned)cfg->max_connections_per_ip, MHD_OPTION_CONNECTION_MEMORY_LIMIT,
        (size_t)(256 * 1024), MHD_OPTION_NOTIFY_COMPLETED, on_completed, h,
        MHD_OPTION_NOTIFY_CONNECTION, on_connection, h, MHD_OPTION_URI_LOG_CALLBACK, on_uri, h,
        MHD_OPTION_LISTENING_ADDRESS_REUSE, cfg->reuse_port ? 1u : 0u, MHD_OPTION_END);
    if (!h->mhd) {
        int e = errno;
        vx_err_set(err, VX_EIO, "listen_failed", "cannot listen on %s: %s", cfg->listen,
                   e == EADDRINUSE ? "address in use (another process listens on this port)"
                   : e             ? strerror(e)
                                   : "libmicrohttpd could not start (see http.mhd)");
        pthread_mutex_destroy(&h->clock);
        pthread_mutex_destroy(&h->wlock);
        pthread_cond_destroy(&h->wcond);
        free(h);
        return NULL;
    }
    const union MHD_DaemonInfo *di = MHD_get_daemon_info(h->mhd, MHD_DAEMON_INFO_BIND_PORT);
    h->port = di ? di->port : 0;
    if (pthread_create(&h->timer, NULL, timer_main, h) == 0) h->timer_started = 1;
    if (pthread_create(&h->sweeper, NULL, sweeper_main, h) == 0) h->sweeper_started = 1;
    VX_INFO("http.listen", "listen=%s port=%d threads=%d auth=%d", cfg->listen, h->port,
            cfg->http_threads, h->auth);
    return h;
}

int vx_http_port(vx_http *h)
{
    return h->port;
}

void vx_http_quiesce(vx_http *h)
{
    if (!h) return;
    MHD_socket fd = MHD_quiesce_daemon(h->mhd);
    if (fd != MHD_INVALID_SOCKET) close(fd);
    pthread_mutex_lock(&h->wlock);
    h->stopping = 1;
    while (h->waiters)
        resume_locked(h, h->waiters);
    pthread_cond_broadcast(&h->wcond);
    pthread_mutex_unlock(&h->wlock);
}

void vx_http_stop(vx_http *h, double grace_s)
{
    if (!h) return;
    vx_http_quiesce(h);
    double until = vx_mono() + grace_s;
    while (vx_mono() < until) {
        const union MHD_DaemonInfo *di =
            MHD_get_daemon_info(h->mhd, MHD_DAEMON_INFO_CURRENT_CONNECTIONS);
        if (!di || di->num_connections == 0) break;
        usleep(20000);
    }
    if (h->timer_started) pthread_join(h->timer, NULL);
    __atomic_store_n(&h->sweep_stop, 1, __ATOMIC_RELEASE);
    if (h->sweeper_started) pthread_join(h->sweeper, NULL);
    MHD_stop_daemon(h->mhd);
    pthread_mutex_destroy(&h->clock);
    pthread_mutex_destroy(&h->wlock);
    pthread_cond_destroy(&h->wcond);
    free(h);
}
