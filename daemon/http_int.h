/* What the files of the HTTP layer share (private to daemon/): the request
 * and server state, the responses (respond.c) and the route handlers
 * (routes_*.c). http.c has the libmicrohttpd plumbing and the request
 * lifecycle. Each handler answers one request: it queues a response and
 * returns the MHD result, or holds the request (?wait) and returns MHD_YES. */
#ifndef VX_HTTP_INT_H
#define VX_HTTP_INT_H

#include <microhttpd.h>
#include <stdint.h>

#include "auth.h"
#include "conns.h"
#include "events.h"
#include "http.h"
#include "util/budget.h"
#include "mesh/intake.h"
#include "request.h"
#include "wait.h"

typedef enum body_kind { BODY_NONE, BODY_UPLOAD, BODY_JSON } body_kind;

/* One request, from its head to its completion. */
typedef struct req {
    vx_route route;
    char method[12];
    char id[VX_REQ_ID_MAX], name[VX_REQ_ID_MAX];
    vx_conn *vc;
    vx_req_query q;
    char qerr[160]; /* a bad query parameter, answered 400 */
    double t0;
    int status;
    uint64_t bytes_in, bytes_out;
    body_kind body;
    /* uploads */
    vx_upload *up;
    vx_intake_media declared;
    int too_big;
    vx_err body_err; /* storing the body failed (full disk): answered at the end */
    /* JSON bodies */
    vx_err new_refused; /* POST /v1/jobs: why a new job may not be made (a full
                           disk), while an existing one is still answered */
    char *buf;
    size_t len, cap;
    /* ?wait */
    vx_waiter w;
    int post_job;      /* the held request was POST /v1/jobs */
    int post_existing; /* ... answered with a job that was there already (200) */
    int answered;
    /* the answer turned libmicrohttpd's idle timeout off for its sending
     * (vx_resp_queue): at its completion the timeout is put back, and an
     * aborted answer's bytes_out is what the client acknowledged since
     * (acked0: the connection's count when it was queued; -1 unknown) */
    int timeout_off;
    int64_t acked0;
    int refused;     /* a 413 was written past libmicrohttpd (vx_conns_refuse) */
    int close;       /* the answer closes the connection (Connection: close) */
    char rid[72];    /* X-Request-Id: the client's when sane, else made here */
    char path[256];  /* the concrete path (cut), for the log */
    char client[64]; /* the client's address, for the log */
} req;

struct vx_http {
    vx_http_desc d;
    struct MHD_Daemon *mhd;
    int port;
    vx_auth auth;
    vx_wait *wait;
    vx_conns *conns;
    vx_events *events;
    /* --max-parse-memory: the worst-case memory of the upload parses and
     * JSON bodies being parsed now, reserved before each */
    vx_budget parse_budget;
    int stopping;
};

/* ---- respond.c ---- */
/* How an error is answered: the status, at most one extra header (value
 * NULL: the request route's Allow) and the code the body carries instead of
 * the error's own (NULL: its own). */
typedef struct vx_resp_answer {
    unsigned status;
    const char *header, *value, *code;
} vx_resp_answer;

/* The data dir, scrubbed from every error message (clients never see
 * server paths), and the origins CORS allows (--cors-origin: a comma
 * list, "*" = any, "" = none). Called once, before serving; both strings
 * must outlive the server. */
void vx_resp_init(const char *data_dir, const char *cors_origins);
/* The next entry of a comma list (an option's: blanks around entries
 * dropped) from *p: its start, its length in *k, and *p past it; NULL at
 * the list's end. */
const char *vx_resp_list_next(const char **p, size_t *k);
/* The origin of c's request when CORS allows it (the Origin header's
 * value), else NULL. */
const char *vx_resp_cors_origin(struct MHD_Connection *c);
/* The one mapping from error kinds to HTTP answers. */
vx_resp_answer vx_resp_answer_of(const vx_err *e);
/* Value of request header name, or NULL. */
const char *vx_resp_header(struct MHD_Connection *c, const char *name);
/* The same without the blanks after it (libmicrohttpd keeps them; RFC 9110
 * 5.5 excludes them from the value), copied into buf when it had some and
 * fits in n - 1 bytes (else the value as sent). */
const char *vx_resp_header_trim(struct MHD_Connection *c, const char *name, char *buf, size_t n);
/* The values of every line of list header name, joined with ", " into buf
 * (RFC 9110 5.3: If-None-Match or Accept-Encoding may come on several
 * lines; vx_resp_header gives the first only); NULL when there is none or
 * they do not fit. */
const char *vx_resp_header_list(struct MHD_Connection *c, const char *name, char *buf, size_t n);
/* The preconditions of RFC 9110 13.2.2 on a GET or HEAD of a representation
 * whose strong tag is etag (also: another tag of the same content that
 * If-Match may name, or NULL): 412 when If-Match names neither (nor "*"),
 * else 304 when If-None-Match names etag (weakly) or is "*", else 0. */
int vx_resp_preconditions(struct MHD_Connection *c, const char *etag, const char *also);
/* The JSON 412 precondition_failed of a resource tagged etag. */
int vx_resp_precondition_failed(struct MHD_Connection *c, req *r, const char *etag);
/* A response of headers alone, no Content-Length and no body: a 304, or a
 * HEAD whose GET has no length known up front (a coded result, an event
 * stream). libmicrohttpd 0.9.75 adds Content-Length: 0 to a sized response
 * and the last chunk (a body) to an unsized one, even for HEAD; this one
 * is sent unsized in its HTTP/1.0-compatible mode, which closes the
 * connection after it. NULL without memory. */
struct MHD_Response *vx_resp_headers_only(void);
/* Queues resp (taken, may be NULL: MHD_NO) as r's answer. */
int vx_resp_queue(struct MHD_Connection *c, req *r, unsigned status, struct MHD_Response *resp,
                  uint64_t body_bytes);
/* Answers text (owned, NULL: empty) as ctype (NULL: no Content-Type, for
 * a 204), no-store, with one optional header h1: v1. */
int vx_resp_text(struct MHD_Connection *c, req *r, unsigned status, char *text, const char *ctype,
                 const char *h1, const char *v1);
/* Answers a JSON document (owned). */
int vx_resp_json(struct MHD_Connection *c, req *r, unsigned status, cJSON *doc, const char *h1,
                 const char *v1);
/* Answers 200 {"items": items (owned), "next": next or null}: a list page. */
int vx_resp_page(struct MHD_Connection *c, req *r, cJSON *items, const char *next);
/* Answers e as {"error":{"code","message"}} through vx_resp_answer_of. */
int vx_resp_err(struct MHD_Connection *c, req *r, const vx_err *e);
/* How vx_resp_err answers e: *a, and the code (returned) and message (into
 * msg, n bytes: the data dir scrubbed, valid UTF-8) of its body. */
const char *vx_resp_err_text(const vx_err *e, vx_resp_answer *a, char *msg, size_t n);
/* vx_resp_err with one more header h: v (used where the kind's answer has
 * none, e.g. Content-Range on a 416). */
int vx_resp_err_with(struct MHD_Connection *c, req *r, const vx_err *e, const char *h,
                     const char *v);
/* A Content-Disposition attachment value into out. The name is
 * "<stem>-<file>" where stem is name without its extension, or (file NULL)
 * name itself; without a name (NULL, or not one by vx_name_ok) it is
 * file, or "<fallback>.<ext>". It goes as UTF-8 in filename*=, and
 * filename= (ASCII, other bytes '_') carries fallback when file is given (a
 * result's own name), else the name. */
void vx_resp_disposition(char *out, size_t n, const char *name, const char *file,
                         const char *fallback, const char *ext);
/* Answers an error made here: vx_err_set + vx_resp_err. */
int vx_resp_fail(struct MHD_Connection *c, req *r, vx_err_kind kind, const char *code,
                 const char *fmt, ...) __attribute__((format(printf, 5, 6)));

/* ---- routes_misc.c: probes, metrics, info, disk space ---- */
/* Free bytes of the data dir's file system (UINT64_MAX when unknown). */
uint64_t vx_route_disk_free(vx_http *h);
/* 1 when the data dir has room for writes: free space at or above the
 * floor (with a floor of 0, any free byte); the free bytes in *free_bytes. */
int vx_route_disk_ok(vx_http *h, uint64_t *free_bytes);
/* Why the daemon takes no work (--require-gpu's refused renderer, shutting
 * down, no GL context), for /readyz and the 503 not_ready messages. */
void vx_route_not_ready_reason(vx_http *h, char *out, size_t n);
/* OPTIONS on any route: 204 with Allow, and the CORS preflight answer
 * (Access-Control-Allow-*) for an allowed origin. */
int vx_route_options(vx_http *h, struct MHD_Connection *c, req *r);
/* GET /livez, /readyz, /metrics, /v1/info. */
int vx_route_livez(vx_http *h, struct MHD_Connection *c, req *r);
int vx_route_readyz(vx_http *h, struct MHD_Connection *c, req *r);
int vx_route_metrics(vx_http *h, struct MHD_Connection *c, req *r);
int vx_route_info(vx_http *h, struct MHD_Connection *c, req *r);

/* ---- routes_meshes.c ---- */
/* GET /v1/meshes. */
int vx_route_mesh_list(vx_http *h, struct MHD_Connection *c, req *r);
/* GET, DELETE /v1/meshes/{id}. */
int vx_route_mesh(vx_http *h, struct MHD_Connection *c, req *r);
/* GET /v1/meshes/{id}/file: the uploaded bytes, as the format's media type. */
int vx_route_mesh_file(vx_http *h, struct MHD_Connection *c, req *r);
/* POST /v1/meshes once the body is streamed to the store: validate, parse
 * under the parse-memory budget, store. */
int vx_route_upload(vx_http *h, struct MHD_Connection *c, req *r);

/* ---- routes_jobs.c ---- */
/* POST /v1/jobs once the JSON body is in (may hold it for ?wait). */
int vx_route_job_post(vx_http *h, struct MHD_Connection *c, req *r);
/* GET /v1/jobs. */
int vx_route_job_list(vx_http *h, struct MHD_Connection *c, req *r);
/* GET (may hold it for ?wait), DELETE /v1/jobs/{id}. */
int vx_route_job(vx_http *h, struct MHD_Connection *c, req *r);
/* A held request, resumed: answers the job as it is now. */
int vx_route_job_resumed(vx_http *h, struct MHD_Connection *c, req *r);
/* GET /v1/jobs/{id}/result[/{name}]. */
int vx_route_result(vx_http *h, struct MHD_Connection *c, req *r);

/* ---- routes_web.c: the viewer, /openapi.yaml, /docs (public) ---- */
/* GET /, /docs, /openapi.yaml, /ui/{name}: a file built into the binary,
 * with its Content-Type and an ETag (304 on If-None-Match). */
int vx_route_web(vx_http *h, struct MHD_Connection *c, req *r);
/* ---- events.c ---- */
/* GET /v1/jobs/{id}/events: the job's Server-Sent Events stream. */
int vx_route_events(vx_http *h, struct MHD_Connection *c, req *r);

#endif
