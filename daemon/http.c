/* Routes of api/openapi.yaml on libmicrohttpd 0.9.75 (http.h).
 *
 * Request lifecycle: the first call of the access handler allocates a
 * `req`, routes it and answers early errors (auth, method, size, media type)
 * before any body is read, so a client that sent "Expect: 100-continue" gets
 * the error instead of sending the body. Body calls stream into the store or
 * a bounded buffer and always consume every chunk. The last call answers.
 * A ?wait request is suspended and resumed by the job hook or the timer
 * thread; the handler then answers as it would have without waiting. */
#include "http.h"

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
#include <sys/stat.h>
#include <unistd.h>

#include "metrics.h"
#include "util/budget.h"
#include "util/fsutil.h"
#include "util/log.h"

enum route {
    R_UNKNOWN,
    R_LIVEZ,
    R_READYZ,
    R_METRICS,
    R_INFO,
    R_MESHES,
    R_MESH,
    R_JOBS,
    R_JOB,
    R_RESULT,
    R_RESULT_NAME,
};

static const struct {
    const char *name; /* metrics label: the path template */
    const char *allow;
} routes[] = {
    [R_UNKNOWN] = {"unmatched", ""},
    [R_LIVEZ] = {"/livez", "GET, HEAD"},
    [R_READYZ] = {"/readyz", "GET, HEAD"},
    [R_METRICS] = {"/metrics", "GET, HEAD"},
    [R_INFO] = {"/v1/info", "GET, HEAD"},
    [R_MESHES] = {"/v1/meshes", "GET, HEAD, POST"},
    [R_MESH] = {"/v1/meshes/{id}", "GET, HEAD, DELETE"},
    [R_JOBS] = {"/v1/jobs", "GET, HEAD, POST"},
    [R_JOB] = {"/v1/jobs/{id}", "GET, HEAD, DELETE"},
    [R_RESULT] = {"/v1/jobs/{id}/result", "GET, HEAD"},
    [R_RESULT_NAME] = {"/v1/jobs/{id}/result/{name}", "GET, HEAD"},
};

typedef enum body_kind { BODY_NONE, BODY_UPLOAD, BODY_JSON } body_kind;
/* Declared upload types: model/obj is OBJ; text/plain is text, OBJ or .bpt
 * by content; model/x-bpt is .bpt; the Draco types are Draco; no type or
 * application/octet-stream is told by content. */
typedef enum media { MEDIA_SNIFF, MEDIA_OBJ, MEDIA_DRACO, MEDIA_TEXT, MEDIA_BPT } media;

typedef struct req req;

typedef struct waiter {
    req *r;
    struct MHD_Connection *conn;
    char jid[33];
    double deadline; /* monotonic */
    struct waiter *next;
} waiter;

struct req {
    enum route route;
    char method[12];
    char id[80], name[80];
    double t0;
    int status;
    uint64_t bytes_in, bytes_out;
    body_kind body;
    /* uploads */
    vx_upload *up;
    media declared;
    int too_big;
    /* JSON bodies */
    char *buf;
    size_t len, cap;
    /* ?wait */
    waiter w;
    int waiting;  /* suspended, not yet resumed */
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
};

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
    struct MHD_Response *resp =
        MHD_create_response_from_buffer(n, text ? text : (void *)"", text ? MHD_RESPMEM_MUST_FREE : MHD_RESPMEM_PERSISTENT);
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
    cJSON *doc = cJSON_CreateObject();
    cJSON *e = cJSON_AddObjectToObject(doc, "error");
    cJSON_AddStringToObject(e, "code", code);
    cJSON_AddStringToObject(e, "message", message);
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
    case VX_EINVAL: return 400;
    case VX_EUNPROC: return 422;
    case VX_ETOOBIG: return 413;
    case VX_ENOTFOUND: return strcmp(e->code, "result_evicted") == 0 ? 410 : 404;
    case VX_ECONFLICT: return 409;
    case VX_EMEDIA: return 415;
    case VX_EBUSY: return strcmp(e->code, "not_ready") == 0 ? 503 : 429;
    case VX_ECANCELED: return 409;
    case VX_ETIMEOUT: return 504;
    default: return 500;
    }
}

static int send_err(struct MHD_Connection *c, req *r, const vx_err *e)
{
    unsigned st = err_status(e);
    if (st == 429) return send_error_h(c, r, st, e->code, e->message, MHD_HTTP_HEADER_RETRY_AFTER, "2");
    if (st == 503) return send_error_h(c, r, st, e->code, e->message, MHD_HTTP_HEADER_RETRY_AFTER, "5");
    return send_error(c, r, st, e->code, e->message);
}

/* ---- helpers ------------------------------------------------------- */

static enum route route_of(const char *url, char *id, size_t idn, char *name, size_t namen)
{
    id[0] = name[0] = 0;
    if (!strcmp(url, "/livez")) return R_LIVEZ;
    if (!strcmp(url, "/readyz")) return R_READYZ;
    if (!strcmp(url, "/metrics")) return R_METRICS;
    if (!strcmp(url, "/v1/info")) return R_INFO;
    if (!strcmp(url, "/v1/meshes")) return R_MESHES;
    if (!strcmp(url, "/v1/jobs")) return R_JOBS;
    const char *rest;
    if (!strncmp(url, "/v1/meshes/", 11)) {
        rest = url + 11;
        if (!*rest || strchr(rest, '/') || strlen(rest) >= idn) return R_UNKNOWN;
        snprintf(id, idn, "%s", rest);
        return R_MESH;
    }
    if (!strncmp(url, "/v1/jobs/", 9)) {
        rest = url + 9;
        const char *slash = strchr(rest, '/');
        size_t n = slash ? (size_t)(slash - rest) : strlen(rest);
        if (!n || n >= idn) return R_UNKNOWN;
        memcpy(id, rest, n);
        id[n] = 0;
        if (!slash) return R_JOB;
        if (!strcmp(slash, "/result")) return R_RESULT;
        if (!strncmp(slash, "/result/", 8) && slash[8] && !strchr(slash + 8, '/') &&
            strlen(slash + 8) < namen) {
            snprintf(name, namen, "%s", slash + 8);
            return R_RESULT_NAME;
        }
    }
    return R_UNKNOWN;
}

static int method_allowed(enum route rt, const char *m)
{
    const char *allow = routes[rt].allow;
    size_t n = strlen(m);
    for (const char *p = allow; (p = strstr(p, m)); p += n)
        if ((p == allow || p[-1] == ' ') && (p[n] == 0 || p[n] == ',')) return 1;
    return 0;
}

static const char *header(struct MHD_Connection *c, const char *name)
{
    return MHD_lookup_connection_value(c, MHD_HEADER_KIND, name);
}

static const char *query(struct MHD_Connection *c, const char *name)
{
    return MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, name);
}

/* Media type without parameters, lower-cased. */
static void media_type(const char *ct, char *out, size_t n)
{
    size_t o = 0;
    if (ct)
        for (; *ct && *ct != ';' && o + 1 < n; ct++)
            if (*ct != ' ' && *ct != '\t') out[o++] = (char)(*ct >= 'A' && *ct <= 'Z' ? *ct + 32 : *ct);
    out[o] = 0;
}

/* Constant-time: both sides are hashed so neither length nor content leaks. */
static int auth_ok(vx_http *h, struct MHD_Connection *c)
{
    const char *a = header(c, MHD_HTTP_HEADER_AUTHORIZATION);
    if (!a || strncasecmp(a, "Bearer ", 7) != 0) return 0;
    a += 7;
    while (*a == ' ') a++;
    struct sha256_ctx ctx;
    unsigned char d[SHA256_DIGEST_SIZE];
    sha256_init(&ctx);
    sha256_update(&ctx, strlen(a), (const uint8_t *)a);
    sha256_digest(&ctx, sizeof d, d);
    return memeql_sec(d, h->token_digest, sizeof d);
}

/* Parses ?wait: -1 on a bad value, else seconds clamped to the request timeout. */
static int parse_wait(vx_http *h, struct MHD_Connection *c, double *out)
{
    const char *w = query(c, "wait");
    *out = 0;
    if (!w) return 0;
    char *end;
    errno = 0;
    double v = strtod(w, &end);
    if (errno || end == w || *end || !isfinite(v) || v < 0) return -1;
    if (v > h->d.cfg->request_timeout_s) v = h->d.cfg->request_timeout_s;
    *out = v;
    return 0;
}

static int parse_limit(struct MHD_Connection *c, int *out)
{
    const char *l = query(c, "limit");
    *out = 100;
    if (!l) return 0;
    char *end;
    errno = 0;
    long v = strtol(l, &end, 10);
    if (errno || end == l || *end || v < 1 || v > 1000) return -1;
    *out = (int)v;
    return 0;
}

/* ---- waiting ------------------------------------------------------- */

static void resume_locked(vx_http *h, waiter *w)
{
    waiter **pp = &h->waiters;
    while (*pp && *pp != w) pp = &(*pp)->next;
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
            if (w->deadline <= now) resume_locked(h, w);
            else if (w->deadline < next) next = w->deadline;
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

/* ---- handlers ------------------------------------------------------ */

static int h_readyz(vx_http *h, struct MHD_Connection *c, req *r)
{
    int gl = vx_jobs_ready(h->d.jobs);
    int q = vx_jobs_queue_depth(h->d.jobs) < vx_jobs_queue_capacity(h->d.jobs);
    int dd = vx_store_writable(h->d.store);
    int ok = gl && q && dd && !h->stopping;
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddStringToObject(doc, "status", ok ? "ready" : "not_ready");
    cJSON *chk = cJSON_AddObjectToObject(doc, "checks");
    cJSON_AddBoolToObject(chk, "gl", gl);
    cJSON_AddBoolToObject(chk, "queue", q);
    cJSON_AddBoolToObject(chk, "data_dir", dd);
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
    cJSON_AddNumberToObject(l, "max_connections_per_ip", (double)cfg->max_connections_per_ip);
    cJSON_AddNumberToObject(l, "max_image_pixels", (double)cfg->max_image_pixels);
    cJSON_AddNumberToObject(l, "max_job_memory_bytes", (double)cfg->max_job_memory);
    cJSON_AddNumberToObject(l, "max_json_bytes", (double)cfg->max_json_bytes);
    cJSON_AddNumberToObject(l, "max_parse_memory_bytes", (double)cfg->max_parse_memory);
    cJSON_AddNumberToObject(l, "results_max_bytes", (double)cfg->results_max_bytes);
    cJSON_AddNumberToObject(l, "results_max_age_s", cfg->results_max_age_s);
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
    int limit;
    const char *after = query(c, "after");
    if (parse_limit(c, &limit))
        return send_error(c, r, 400, "invalid_request", "limit must be an integer in [1, 1000]");
    if (after && !vx_store_valid_mesh_id(after))
        return send_error(c, r, 400, "invalid_request", "after must be a mesh id");
    char next[65];
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddItemToObject(doc, "items", vx_store_mesh_list(h->d.store, after, limit, next));
    if (next[0]) cJSON_AddStringToObject(doc, "next", next);
    else cJSON_AddNullToObject(doc, "next");
    return send_json(c, r, 200, doc, NULL, NULL);
}

static int h_mesh(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    if (!vx_store_valid_mesh_id(r->id))
        return send_error(c, r, 404, "mesh_not_found", "no mesh with that id (ids are 64 hex digits)");
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
    if (vx_upload_bytes(r->up) == 0) return send_error(c, r, 422, "obj_no_faces", "the body is empty: no faces");
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
        VX_INFO("mesh.rejected", "code=%s message=%s", err.code, vx_log_quote(q, sizeof q, err.message));
        return send_err(c, r, &err);
    }
    double parse_ms = (vx_mono() - t) * 1e3;
    if (m->degenerate_tris == m->ntris) {
        vx_mesh_free(m);
        vx_budget_release(&parse_budget, cost);
        return send_error(c, r, 422, "degenerate_mesh", "every triangle of the mesh has zero area");
    }
    meta = mesh_meta(id, fname, vx_upload_bytes(r->up), m);
    VX_INFO("mesh.uploaded", "mesh=%s new=1 format=%s bytes=%llu vertices=%zu triangles=%zu parse_ms=%.1f",
            id, fname, (unsigned long long)vx_upload_bytes(r->up), m->nverts, m->ntris, parse_ms);
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

static int answer_job(vx_http *h, struct MHD_Connection *c, req *r, const char *jid, unsigned status)
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
    if (r->too_big) return send_error(c, r, 413, "too_large", "the JSON body is larger than max-json-bytes");
    double wait_s;
    if (parse_wait(h, c, &wait_s))
        return send_error(c, r, 400, "invalid_request", "wait must be a non-negative number of seconds");
    cJSON *doc = cJSON_ParseWithLength(r->buf ? r->buf : "", r->len);
    if (!doc) return send_error(c, r, 400, "invalid_json", "the body is not valid JSON");
    const char *msg = NULL;
    const cJSON *mesh = cJSON_GetObjectItemCaseSensitive(doc, "mesh");
    const cJSON *kind = cJSON_GetObjectItemCaseSensitive(doc, "kind");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(doc, "params");
    if (!cJSON_IsObject(doc)) msg = "the body must be a JSON object";
    else if (!cJSON_IsString(mesh)) msg = "\"mesh\" (a mesh id string) is required";
    else if (!cJSON_IsString(kind)) msg = "\"kind\" (a job kind string) is required";
    else if (params && !cJSON_IsObject(params)) msg = "\"params\" must be an object";
    else {
        const cJSON *it;
        cJSON_ArrayForEach(it, doc) if (strcmp(it->string, "mesh") && strcmp(it->string, "kind") &&
                                        strcmp(it->string, "params")) msg = "unknown field in the job request";
    }
    if (msg) {
        cJSON_Delete(doc);
        return send_error(c, r, 400, "invalid_request", msg);
    }
    vx_err err;
    vx_err_clear(&err);
    cJSON *job = NULL;
    if (!vx_store_valid_mesh_id(mesh->valuestring))
        vx_err_set(&err, VX_EINVAL, "invalid_request", "\"mesh\" must be a mesh id (64 hex digits)");
    else
        job = vx_jobs_submit(h->d.jobs, mesh->valuestring, kind->valuestring, params, &err);
    cJSON_Delete(doc);
    if (!job) return send_err(c, r, &err);
    char jid[33];
    snprintf(jid, sizeof jid, "%s", cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "id")));
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
    int limit;
    const char *after = query(c, "after"), *state = query(c, "state");
    if (parse_limit(c, &limit))
        return send_error(c, r, 400, "invalid_request", "limit must be an integer in [1, 1000]");
    if (after && !vx_jobs_valid_id(after))
        return send_error(c, r, 400, "invalid_request", "after must be a job id");
    static const char *states[] = {"queued", "running", "succeeded", "failed", "canceled"};
    if (state) {
        int ok = 0;
        for (int i = 0; i < 5; i++) ok |= !strcmp(state, states[i]);
        if (!ok) return send_error(c, r, 400, "invalid_request", "unknown state filter");
    }
    char next[40];
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddItemToObject(doc, "items", vx_jobs_list(h->d.jobs, after, limit, state, next));
    if (next[0]) cJSON_AddStringToObject(doc, "next", next);
    else cJSON_AddNullToObject(doc, "next");
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
    double wait_s;
    if (parse_wait(h, c, &wait_s))
        return send_error(c, r, 400, "invalid_request", "wait must be a non-negative number of seconds");
    if (wait_s > 0 && hold(h, c, r, r->id, wait_s)) return MHD_YES;
    return answer_job(h, c, r, r->id, 200);
}

static int h_result(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    char path[2400], ctype[64], fname[128];
    if (vx_jobs_output(h->d.jobs, r->id, r->route == R_RESULT_NAME ? r->name : NULL, path,
                       sizeof path, ctype, fname, &err))
        return send_err(c, r, &err);
    char etag[160], disp[200];
    snprintf(etag, sizeof etag, "\"%s\"", fname);
    snprintf(disp, sizeof disp, "attachment; filename=\"%s\"", fname);
    const char *inm = header(c, MHD_HTTP_HEADER_IF_NONE_MATCH);
    if (inm && (strstr(inm, etag) || !strcmp(inm, "*"))) {
        struct MHD_Response *resp = MHD_create_response_from_buffer(0, (void *)"", MHD_RESPMEM_PERSISTENT);
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
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "private, max-age=86400, immutable");
    return queue(c, r, 200, resp, (uint64_t)st.st_size);
}

/* ---- dispatch ------------------------------------------------------ */

static int first_call(vx_http *h, struct MHD_Connection *c, req *r)
{
    if (r->route == R_UNKNOWN) return send_error(c, r, 404, "not_found", "no such route");
    if (!strncmp(routes[r->route].name, "/v1/", 4) && h->auth && !auth_ok(h, c))
        return send_error_h(c, r, 401, "unauthorized", "a valid bearer token is required",
                            MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"voxeld\"");
    if (!method_allowed(r->route, r->method)) {
        char msg[96];
        snprintf(msg, sizeof msg, "method %s is not allowed here", r->method);
        return send_error_h(c, r, 405, "method_not_allowed", msg, MHD_HTTP_HEADER_ALLOW,
                            routes[r->route].allow);
    }
    if (strcmp(r->method, "POST") != 0) return -1; /* no body: answer in dispatch */
    if (h->stopping || !vx_jobs_ready(h->d.jobs))
        return send_error_h(c, r, 503, "not_ready", "the daemon is not ready", MHD_HTTP_HEADER_RETRY_AFTER, "5");

    char mt[128];
    media_type(header(c, MHD_HTTP_HEADER_CONTENT_TYPE), mt, sizeof mt);
    if (r->route == R_MESHES) {
        if (!strcmp(mt, "model/obj")) r->declared = MEDIA_OBJ;
        else if (!strcmp(mt, "text/plain")) r->declared = MEDIA_TEXT;
        else if (!strcmp(mt, "model/x-bpt")) r->declared = MEDIA_BPT;
        else if (!strcmp(mt, "model/x-draco") || !strcmp(mt, "application/x-draco")) r->declared = MEDIA_DRACO;
        else if (!mt[0] || !strcmp(mt, "application/octet-stream")) r->declared = MEDIA_SNIFF;
        else {
            char msg[200];
            snprintf(msg, sizeof msg, "cannot take '%.100s': send model/obj, model/x-bpt, model/x-draco or "
                                      "application/octet-stream", mt);
            return send_error(c, r, 415, "unsupported_media_type", msg);
        }
        r->body = BODY_UPLOAD;
    } else {
        if (strcmp(mt, "application/json") != 0)
            return send_error(c, r, 415, "unsupported_media_type", "the body must be application/json");
        r->body = BODY_JSON;
    }
    const char *cl = header(c, MHD_HTTP_HEADER_CONTENT_LENGTH);
    const char *te = header(c, MHD_HTTP_HEADER_TRANSFER_ENCODING);
    uint64_t limit = r->route == R_MESHES ? h->d.cfg->max_upload_bytes : h->d.cfg->max_json_bytes;
    if (r->route == R_MESHES && !cl && !(te && strcasestr(te, "chunked")))
        return send_error(c, r, 411, "length_required", "Content-Length or chunked encoding is required");
    if (cl) {
        char *end;
        errno = 0;
        unsigned long long n = strtoull(cl, &end, 10);
        if (errno || *end || end == cl) return send_error(c, r, 400, "invalid_request", "bad Content-Length");
        if (n > limit) {
            char msg[128];
            snprintf(msg, sizeof msg, "the body (%llu bytes) is larger than the %llu-byte limit", n,
                     (unsigned long long)limit);
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
        if (r->too_big) return 0;
        if (r->bytes_in > h->d.cfg->max_upload_bytes) {
            /* Keep reading (and dropping) the rest, answer 413 at the end. */
            r->too_big = 1;
            vx_upload_abort(r->up);
            r->up = NULL;
            return 0;
        }
        vx_err err;
        if (vx_upload_write(r->up, data, n, &err)) {
            VX_ERROR("http.upload_failed", "code=%s", err.code);
            r->too_big = 0;
            return -1;
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
        r = calloc(1, sizeof *r);
        if (!r) return MHD_NO;
        *con_cls = r;
        r->t0 = vx_mono();
        snprintf(r->method, sizeof r->method, "%s", method);
        r->route = route_of(url, r->id, sizeof r->id, r->name, sizeof r->name);
        int rc = first_call(h, c, r);
        if (rc >= 0) return rc;
        /* Answer on the next call even without a body: a response queued
         * in the first call makes libmicrohttpd 0.9.75 close the
         * connection (it cannot know yet that no body follows). */
        return MHD_YES;
    } else if (r->answered) {
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
    int is_get = !strcmp(r->method, "GET") || !strcmp(r->method, "HEAD");
    switch (r->route) {
    case R_LIVEZ: return send_text(c, r, 200, strdup("{\"status\":\"ok\"}"), "application/json", NULL, NULL);
    case R_READYZ: return h_readyz(h, c, r);
    case R_METRICS: return h_metrics(h, c, r);
    case R_INFO: return h_info(h, c, r);
    case R_MESHES: return is_get ? h_mesh_list(h, c, r) : h_upload_done(h, c, r);
    case R_MESH: return h_mesh(h, c, r);
    case R_JOBS: return is_get ? h_job_list(h, c, r) : h_job_post_done(h, c, r);
    case R_JOB: return h_job(h, c, r);
    case R_RESULT:
    case R_RESULT_NAME: return h_result(h, c, r);
    default: return send_error(c, r, 404, "not_found", "no such route");
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
        while (*pp && *pp != &r->w) pp = &(*pp)->next;
        if (*pp) *pp = r->w.next;
        pthread_mutex_unlock(&h->wlock);
    }
    double dt = vx_mono() - r->t0;
    const char *route = routes[r->route].name;
    int status = r->status ? r->status : 499; /* closed before an answer */
    static const char *known[] = {"GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS", NULL};
    const char *mlabel = "other";
    for (int i = 0; known[i]; i++)
        if (!strcmp(known[i], r->method)) mlabel = known[i];
    vx_metrics_request(route, mlabel, status, dt, r->bytes_in, r->bytes_out);
    vx_log_level lvl = (r->route == R_LIVEZ || r->route == R_READYZ || r->route == R_METRICS) && status < 400
                           ? VX_LOG_DEBUG : VX_LOG_INFO;
    vx_log(lvl, "http.request", "method=%s route=%s status=%d ms=%.2f bytes_in=%llu bytes_out=%llu%s",
           r->method, route, status, dt * 1e3, (unsigned long long)r->bytes_in,
           (unsigned long long)r->bytes_out, toe == MHD_REQUEST_TERMINATED_COMPLETED_OK ? "" : " aborted=1");
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

static int parse_listen(const char *s, struct sockaddr_storage *ss, socklen_t *len, int *v6, vx_err *err)
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
    struct addrinfo hints = {.ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM, .ai_flags = AI_PASSIVE}, *ai;
    if (getaddrinfo(host[0] ? host : NULL, port, &hints, &ai) != 0) goto bad;
    memcpy(ss, ai->ai_addr, ai->ai_addrlen);
    *len = ai->ai_addrlen;
    *v6 = ai->ai_family == AF_INET6;
    freeaddrinfo(ai);
    return 0;
bad:
    return vx_err_set(err, VX_EINVAL, "bad_listen", "cannot parse listen address '%s' (want ADDR:PORT)", s);
}

vx_http *vx_http_start(const vx_http_desc *desc, vx_err *err)
{
    vx_http *h = calloc(1, sizeof *h);
    if (!h) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    h->d = *desc;
    const vx_config *cfg = desc->cfg;
    if (cfg->token[0]) {
        struct sha256_ctx ctx;
        sha256_init(&ctx);
        sha256_update(&ctx, strlen(cfg->token), (const uint8_t *)cfg->token);
        sha256_digest(&ctx, sizeof h->token_digest, h->token_digest);
        h->auth = 1;
    }
    pthread_mutex_init(&h->wlock, NULL);
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
    h->mhd = MHD_start_daemon(
        flags, 0, NULL, NULL, on_request, h, MHD_OPTION_EXTERNAL_LOGGER, mhd_log, NULL,
        MHD_OPTION_SOCK_ADDR, (struct sockaddr *)&ss,
        MHD_OPTION_THREAD_POOL_SIZE, (unsigned)cfg->http_threads, MHD_OPTION_CONNECTION_TIMEOUT,
        (unsigned)ceil(cfg->connection_timeout_s), MHD_OPTION_CONNECTION_LIMIT,
        (unsigned)cfg->max_connections, MHD_OPTION_PER_IP_CONNECTION_LIMIT,
        (unsigned)cfg->max_connections_per_ip, MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)(256 * 1024),
        MHD_OPTION_NOTIFY_COMPLETED, on_completed, h,
        MHD_OPTION_LISTENING_ADDRESS_REUSE, 1u, MHD_OPTION_END);
    if (!h->mhd) {
        vx_err_set(err, VX_EIO, "listen_failed", "cannot listen on %s: %s", cfg->listen, strerror(errno));
        pthread_mutex_destroy(&h->wlock);
        pthread_cond_destroy(&h->wcond);
        free(h);
        return NULL;
    }
    const union MHD_DaemonInfo *di = MHD_get_daemon_info(h->mhd, MHD_DAEMON_INFO_BIND_PORT);
    h->port = di ? di->port : 0;
    if (pthread_create(&h->timer, NULL, timer_main, h) == 0) h->timer_started = 1;
    VX_INFO("http.listen", "listen=%s port=%d threads=%d auth=%d", cfg->listen, h->port,
            cfg->http_threads, h->auth);
    return h;
}

int vx_http_port(vx_http *h) { return h->port; }

void vx_http_quiesce(vx_http *h)
{
    if (!h) return;
    MHD_socket fd = MHD_quiesce_daemon(h->mhd);
    if (fd != MHD_INVALID_SOCKET) close(fd);
    pthread_mutex_lock(&h->wlock);
    h->stopping = 1;
    while (h->waiters) resume_locked(h, h->waiters);
    pthread_cond_broadcast(&h->wcond);
    pthread_mutex_unlock(&h->wlock);
}

void vx_http_stop(vx_http *h, double grace_s)
{
    if (!h) return;
    vx_http_quiesce(h);
    double until = vx_mono() + grace_s;
    while (vx_mono() < until) {
        const union MHD_DaemonInfo *di = MHD_get_daemon_info(h->mhd, MHD_DAEMON_INFO_CURRENT_CONNECTIONS);
        if (!di || di->num_connections == 0) break;
        usleep(20000);
    }
    if (h->timer_started) pthread_join(h->timer, NULL);
    MHD_stop_daemon(h->mhd);
    pthread_mutex_destroy(&h->wlock);
    pthread_cond_destroy(&h->wcond);
    free(h);
}
