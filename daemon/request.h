/* The pure parts of reading a request: route matching, methods, media types,
 * strict query parameters (limit, after, state, wait) and UTF-8 checks.
 * No libmicrohttpd here, so that tests/fuzz/fuzz_query.c can drive it with
 * arbitrary bytes; http.c hands over what libmicrohttpd parsed. */
#ifndef VX_REQUEST_H
#define VX_REQUEST_H

#include <stddef.h>
#include <stdint.h>

#include "util/name.h"

typedef enum vx_route {
    VX_R_UNKNOWN,
    VX_R_LIVEZ,
    VX_R_READYZ,
    VX_R_METRICS,
    VX_R_INFO,
    VX_R_MESHES,
    VX_R_MESH,
    VX_R_MESH_FILE,
    VX_R_JOBS,
    VX_R_JOB,
    VX_R_RESULT,
    VX_R_RESULT_NAME,
    VX_R_WEB_INDEX, /* the viewer (routes_web.c) */
    VX_R_WEB_DOCS,
    VX_R_WEB_SPEC,
    VX_R_WEB_ASSET,
    VX_R_EVENTS,
    VX_R_COUNT
} vx_route;

/* Path ids and names are shorter than this (longer ones match no route). */
#define VX_REQ_ID_MAX 80

typedef struct vx_req_target {
    vx_route route;
    char id[VX_REQ_ID_MAX];   /* {id} / {jid}, or empty */
    char name[VX_REQ_ID_MAX]; /* {name} of a result or a viewer file, or empty */
} vx_req_target;

/* Longest ?wait accepted before capping, in microseconds (10^12 s). */
#define VX_REQ_WAIT_MAX_US 1000000000000000000ull

/* Longest mesh name, in bytes (?name=, a Content-Disposition filename). */

/* The declared query parameters of one request, after strict parsing.
 * progress (GET /v1/jobs/{id} only) is a fraction from 0 to 1. */
typedef struct vx_req_query {
    int has_limit, has_after, has_state, has_wait, has_progress, has_order, has_kind, has_mesh;
    int has_name;
    int limit;                  /* 1..1000; 100 when absent */
    char after[VX_REQ_ID_MAX];  /* a mesh or job id in form */
    char state[16];             /* a job state */
    uint64_t wait_us;           /* not yet capped to the request timeout */
    uint32_t progress_ppm;      /* ?progress: wake a ?wait at this progress, in 1e-6 (0..1e6) */
    int desc;                   /* order=desc: newest first */
    char kind[32];              /* a job kind's name in form (the route checks it is known) */
    char mesh[VX_REQ_ID_MAX];   /* a mesh id */
    char name[VX_NAME_MAX + 1]; /* POST /v1/meshes: the mesh's name */
} vx_req_query;

/* Matches path (the URL without its query string, exactly as sent: no
 * normalisation) to a route; fills t. Returns t->route. */
vx_route vx_req_route(const char *path, size_t len, vx_req_target *t);
/* The path template of a route, e.g. "/v1/jobs/{id}" ("unmatched" for none). */
const char *vx_req_route_name(vx_route rt);
/* The Allow header of a route, e.g. "GET, HEAD, DELETE, OPTIONS" ("" for
 * none). */
const char *vx_req_route_allow(vx_route rt);
/* 1 when m is a method of RFC 9110 or PATCH (405 where a route lacks it),
 * else 0 (501). */
int vx_req_method_known(const char *m);
/* 1 when the route takes the method (HEAD wherever GET), else 0. */
int vx_req_method_allowed(vx_route rt, const char *method);
/* Writes the media type of a Content-Type value, parameters and white space
 * dropped and lower-cased, into out (n > 0); ct may be NULL (gives ""). */
void vx_req_media_type(const char *ct, char *out, size_t n);

/* Reads a Transfer-Encoding value (NULL = none): 0 for none, 1 for exactly
 * "chunked" (any case, no white space around it: libmicrohttpd's test),
 * -1 for anything else (gzip, lists, "chunked " ...), -2 for an empty value
 * (white space only). */
int vx_req_transfer_encoding(const char *te);
/* Parses a Content-Length value: digits only (no sign or space), at most
 * 19 of them. 0 or -1. */
int vx_req_parse_length(const char *s, uint64_t *out);

/* Resets q to "no parameters". */
void vx_req_query_init(vx_req_query *q);
/* Takes one query argument as libmicrohttpd decoded it (value NULL for a
 * key without '='). Parameters the route and method do not declare are
 * ignored (the contract); a declared one that is empty, repeated, holds a
 * NUL or has a bad value gives -1 and a message naming it in msg.
 * Returns 0 otherwise. */
int vx_req_query_add(vx_req_query *q, vx_route rt, const char *method, const char *key, size_t klen,
                     const char *value, size_t vlen, char *msg, size_t msgn);
/* Writes q back as a query string ("limit=5&wait=1.500000") that
 * vx_req_query_add parses to the same q. Returns its length, or -1 when it
 * does not fit in n. */
int vx_req_query_format(const vx_req_query *q, char *out, size_t n);

/* A content coding of a response body. */
typedef enum vx_req_coding { VX_CODING_IDENTITY, VX_CODING_ZSTD, VX_CODING_GZIP } vx_req_coding;
/* The coding to send for an Accept-Encoding value (NULL = none sent):
 * zstd or gzip when the client gives it a q above 0 (by name or by "*"),
 * the higher q winning and zstd on a tie; identity otherwise. */
vx_req_coding vx_req_accept_coding(const char *ae);
/* Reads a Range value against a representation of size bytes: 1 and the
 * inclusive [*first, *last] for one satisfiable byte range; 0 when the
 * value is to be ignored (NULL, not a bytes range, several ranges,
 * malformed: the whole body is sent); -1 when it is unsatisfiable (416). */
int vx_req_range(const char *v, uint64_t size, uint64_t *first, uint64_t *last);
/* 1 when etag (a quoted strong tag) appears in an If-None-Match or
 * If-Range style list (W/ prefixes compared weakly when weak_ok), or the
 * list is "*" (only when star_ok). */
int vx_req_etag_match(const char *list, const char *etag, int weak_ok, int star_ok);
/* 1 when a client's X-Request-Id can be echoed: 1 to 64 characters of
 * [A-Za-z0-9._:-]. */
int vx_req_id_ok(const char *s);
/* A new request id into out: 16 lower-case hex digits (getrandom, else a
 * counter and the clock). Any thread. */
void vx_req_new_id(char out[17]);
/* The file name a Content-Disposition value (NULL: none) gives, its
 * directories dropped, into out (n > VX_NAME_MAX): filename*= (RFC
 * 8187, UTF-8 or ISO-8859-1) when it decodes, else filename=. 1 when there
 * is a valid name (vx_name_ok), 0 when there is no filename parameter,
 * -1 when there is one that is not a valid name. */
int vx_req_disposition_name(const char *cd, char *out, size_t n);

/* Parses a page size: a plain decimal integer in [1, 1000]. 0 or -1. */
int vx_req_parse_limit(const char *s, size_t len, int *out);
/* Parses seconds written as plain decimal ("2", "0.5"; no sign, exponent
 * or hex) into microseconds (further digits truncated, values above
 * VX_REQ_WAIT_MAX_US saturate). 0 or -1. */
int vx_req_parse_seconds(const char *s, size_t len, uint64_t *us);

/* 1 when s[0..len) is well-formed UTF-8 (no overlongs, surrogates or code
 * points above U+10FFFF), else 0. */
int vx_req_utf8_valid(const char *s, size_t len);
/* Copies s into out (n > 0) with every byte that is not part of valid UTF-8,
 * and every control character, replaced by '?'; never cuts a character.
 * Returns out. */
char *vx_req_utf8_sanitize(const char *s, char *out, size_t n);
/* Checks a JSON body before parsing: 0 when it is valid UTF-8 without a
 * \u0000 escape (which would cut a string short), else -1 with why in msg. */
int vx_req_json_text_ok(const char *body, size_t len, char *msg, size_t msgn);
/* Parses a JSON request body strictly (RFC 8259): vx_req_json_text_ok's
 * checks, then no raw control character in a string, numbers in JSON's
 * grammar (no leading zeros, "1.", "+1" or ".5"), nothing but whitespace
 * after the value, and no object with a key twice. The document, or NULL
 * with why in msg. */
struct cJSON *vx_req_json_parse(const char *body, size_t len, char *msg, size_t msgn);

#endif
