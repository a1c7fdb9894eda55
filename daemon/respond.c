/* Responses: JSON and text bodies, and the one mapping from error kinds to
 * HTTP answers (status, header, code), so that every error body is made
 * the same way: {"error":{"code","message"}}, its message scrubbed of the
 * data dir and sanitized to UTF-8. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "http_int.h"
#include "sockq.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/json.h"

static const char *g_data_dir, *g_cors;

void vx_resp_init(const char *data_dir, const char *cors_origins)
{
    g_data_dir = data_dir;
    g_cors = cors_origins ? cors_origins : "";
}

const char *vx_resp_cors_origin(struct MHD_Connection *c)
{
    /* one origin: two Origin lines, or a list in one (RFC 6454 7.1), are
     * no origin that can be echoed back in Access-Control-Allow-Origin */
    const char *origin = vx_resp_header(c, "Origin");
    if (!origin || !origin[0] || !g_cors || !g_cors[0] || strpbrk(origin, " \t,")) return NULL;
    char all[2048];
    if (!vx_resp_header_list(c, "Origin", all, sizeof all) || strchr(all, ',')) return NULL;
    size_t n = strlen(origin), k;
    const char *list = g_cors, *e;
    while ((e = vx_resp_list_next(&list, &k)))
        if ((k == 1 && *e == '*') || (k == n && !strncasecmp(e, origin, n))) return origin;
    return NULL;
}

const char *vx_resp_list_next(const char **p, size_t *k)
{
    const char *s = *p;
    while (*s == ' ' || *s == '\t' || *s == ',')
        s++;
    if (!*s) return NULL;
    const char *end = strchr(s, ',');
    if (!end) end = s + strlen(s);
    *p = end;
    for (*k = (size_t)(end - s); *k && (s[*k - 1] == ' ' || s[*k - 1] == '\t');)
        --*k;
    return s;
}

const char *vx_resp_header(struct MHD_Connection *c, const char *name)
{
    return MHD_lookup_connection_value(c, MHD_HEADER_KIND, name);
}

const char *vx_resp_header_trim(struct MHD_Connection *c, const char *name, char *buf, size_t n)
{
    const char *v = vx_resp_header(c, name);
    size_t len = v ? strlen(v) : 0;
    if (!len || (v[len - 1] != ' ' && v[len - 1] != '\t')) return v;
    while (len && (v[len - 1] == ' ' || v[len - 1] == '\t'))
        len--;
    if (len >= n) return v;
    memcpy(buf, v, len);
    buf[len] = 0;
    return buf;
}

typedef struct joined {
    const char *name;
    char *buf;
    size_t n, len;
    int lines, full;
} joined;

static enum MHD_Result join_line(void *cls, enum MHD_ValueKind kind, const char *key,
                                 const char *value)
{
    joined *j = cls;
    (void)kind;
    if (!key || !value || strcasecmp(key, j->name)) return MHD_YES;
    int w = snprintf(j->buf + j->len, j->n - j->len, "%s%s", j->lines ? ", " : "", value);
    if (w < 0 || (size_t)w >= j->n - j->len) {
        j->full = 1;
        return MHD_NO;
    }
    j->len += (size_t)w;
    j->lines++;
    return MHD_YES;
}

const char *vx_resp_header_list(struct MHD_Connection *c, const char *name, char *buf, size_t n)
{
    joined j = {name, buf, n, 0, 0, 0};
    if (n) buf[0] = 0;
    MHD_get_connection_values(c, MHD_HEADER_KIND, join_line, &j);
    return j.lines && !j.full ? buf : NULL;
}

int vx_resp_preconditions(struct MHD_Connection *c, const char *etag, const char *also)
{
    char buf[4096];
    if (vx_resp_header(c, MHD_HTTP_HEADER_IF_MATCH)) {
        /* strong comparison; a list too long to read matches nothing */
        const char *im = vx_resp_header_list(c, MHD_HTTP_HEADER_IF_MATCH, buf, sizeof buf);
        if (!vx_req_etag_match(im, etag, 0, 1) && !(also && vx_req_etag_match(im, also, 0, 0)))
            return 412;
    }
    const char *inm = vx_resp_header_list(c, MHD_HTTP_HEADER_IF_NONE_MATCH, buf, sizeof buf);
    return vx_req_etag_match(inm, etag, 1, 1) ? 304 : 0;
}

int vx_resp_precondition_failed(struct MHD_Connection *c, req *r, const char *etag)
{
    return vx_resp_fail(c, r, VX_EPRECOND, "precondition_failed",
                        "If-Match names no current tag of this resource (its ETag is %s)", etag);
}

static ssize_t no_body(void *cls, uint64_t pos, char *buf, size_t max)
{
    (void)cls, (void)pos, (void)buf, (void)max;
    return MHD_CONTENT_READER_END_OF_STREAM;
}

struct MHD_Response *vx_resp_headers_only(void)
{
    struct MHD_Response *resp =
        MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 64, no_body, NULL, NULL);
    if (resp) MHD_set_response_options(resp, MHD_RF_HTTP_1_0_COMPATIBLE_STRICT, MHD_RO_END);
    return resp;
}

int vx_resp_queue(struct MHD_Connection *c, req *r, unsigned status, struct MHD_Response *resp,
                  uint64_t body_bytes)
{
    if (!resp) return MHD_NO;
    if (r->rid[0]) MHD_add_response_header(resp, "X-Request-Id", r->rid);
    if (r->close) MHD_add_response_header(resp, MHD_HTTP_HEADER_CONNECTION, "close");
    const char *origin = vx_resp_cors_origin(c);
    if (origin) {
        /* The origin itself, not "*" */
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_ORIGIN, origin);
        MHD_add_response_header(resp, "Access-Control-Expose-Headers", VX_CORS_EXPOSE);
    }
    /* With origins allowed, every answer varies by Origin, those without
     * CORS headers too: a cache that kept one for a request without Origin
     * would give it to a page of an allowed origin, which then fails. */
    if (g_cors && g_cors[0]) MHD_add_response_header(resp, MHD_HTTP_HEADER_VARY, "Origin");
    r->status = (int)status;
    r->bytes_out = body_bytes;
    r->answered = 1;
    int rc = MHD_queue_response(c, status, resp);
    MHD_destroy_response(resp);
    /* libmicrohttpd's timeout counts from its last write, and the kernel
     * wakes a writer only when a third of the send buffer (megabytes) has
     * drained: a client reading a large answer at 30-100 KB/s was closed
     * as idle mid-answer. While the answer is sent the sweeper judges the
     * client by what it acknowledges (conns.c); on_completed puts the
     * timeout back. */
    const union MHD_ConnectionInfo *ci =
        rc == MHD_YES ? MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD) : NULL;
    if (ci) {
        r->acked0 = vx_sockq_acked(ci->connect_fd);
        r->timeout_off = MHD_set_connection_option(c, MHD_CONNECTION_OPTION_TIMEOUT, 0u) == MHD_YES;
        if (r->timeout_off) vx_conns_own_idle(r->vc, 1);
    }
    return rc;
}

int vx_resp_text(struct MHD_Connection *c, req *r, unsigned status, char *text, const char *ctype,
                 const char *h1, const char *v1)
{
    size_t n = text ? strlen(text) : 0;
    struct MHD_Response *resp = MHD_create_response_from_buffer(
        n, text ? text : (void *)"", text ? MHD_RESPMEM_MUST_FREE : MHD_RESPMEM_PERSISTENT);
    if (!resp) {
        free(text);
        return MHD_NO;
    }
    if (ctype) MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    if (h1 && v1) MHD_add_response_header(resp, h1, v1);
    return vx_resp_queue(c, r, status, resp, n);
}

int vx_resp_json(struct MHD_Connection *c, req *r, unsigned status, cJSON *doc, const char *h1,
                 const char *v1)
{
    char *text = doc ? vx_json_print(doc, 0) : NULL;
    cJSON_Delete(doc);
    if (!text) text = strdup("{\"error\":{\"code\":\"internal\",\"message\":\"out of memory\"}}");
    return vx_resp_text(c, r, status, text, "application/json", h1, v1);
}

int vx_resp_page(struct MHD_Connection *c, req *r, cJSON *items, const char *next)
{
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddItemToObject(doc, "items", items);
    if (next[0])
        cJSON_AddStringToObject(doc, "next", next);
    else
        cJSON_AddNullToObject(doc, "next");
    return vx_resp_json(c, r, 200, doc, NULL, NULL);
}

vx_resp_answer vx_resp_answer_of(const vx_err *e)
{
    static const vx_resp_answer by_kind[VX_EKIND_COUNT] = {
        [VX_EOK] = {500},
        [VX_EINVAL] = {400},
        [VX_EUNPROC] = {422},
        [VX_ETOOBIG] = {413},
        [VX_ENOTFOUND] = {404},
        [VX_ECONFLICT] = {409},
        [VX_EMEDIA] = {415},
        [VX_EBUSY] = {429, MHD_HTTP_HEADER_RETRY_AFTER, "2"},
        [VX_ECANCELED] = {409},
        [VX_ETIMEOUT] = {504},
        [VX_EGPU] = {500},
        [VX_EIO] = {500},
        [VX_EINTERNAL] = {500},
        [VX_ENOSPC] = {507, NULL, NULL, "insufficient_storage"},
        [VX_EGONE] = {410},
        [VX_EUNAVAIL] = {503, MHD_HTTP_HEADER_RETRY_AFTER, "5"},
        [VX_EOVERLOAD] = {503, MHD_HTTP_HEADER_RETRY_AFTER, "2"},
        [VX_EAUTH] = {401, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"voxeld\""},
        [VX_EMETHOD] = {405, MHD_HTTP_HEADER_ALLOW, NULL},
        [VX_ELENGTH] = {411},
        [VX_EHEADER] = {431},
        [VX_ENOTIMPL] = {501},
        [VX_ERANGE] = {416},
        [VX_EPRECOND] = {412},
        [VX_EFORBIDDEN] = {403},
    };
    if ((unsigned)e->kind < VX_EKIND_COUNT) return by_kind[e->kind];
    return by_kind[VX_EOK];
}

int vx_resp_err(struct MHD_Connection *c, req *r, const vx_err *e)
{
    return vx_resp_err_with(c, r, e, NULL, NULL);
}

const char *vx_resp_err_text(const vx_err *e, vx_resp_answer *a, char *msg, size_t n)
{
    *a = vx_resp_answer_of(e);
    char scrubbed[600];
    snprintf(scrubbed, sizeof scrubbed, "%s", e->message);
    vx_scrub_path(scrubbed, g_data_dir);
    /* Messages may quote what the client sent: never echo bytes that are
     * not UTF-8 (the body would not be valid JSON text). */
    vx_req_utf8_sanitize(scrubbed, msg, n);
    return a->code ? a->code : e->code;
}

int vx_resp_err_with(struct MHD_Connection *c, req *r, const vx_err *e, const char *h,
                     const char *v)
{
    vx_resp_answer a;
    char clean[512];
    const char *code = vx_resp_err_text(e, &a, clean, sizeof clean);
    cJSON *doc = cJSON_CreateObject();
    cJSON *o = cJSON_AddObjectToObject(doc, "error");
    cJSON_AddStringToObject(o, "code", code);
    cJSON_AddStringToObject(o, "message", clean);
    if (a.status >= 500 && a.status != 501) /* 501: a method the client made up */
        VX_ERROR("http.error", "request_id=%s status=%u code=%s", r && r->rid[0] ? r->rid : "-",
                 a.status, code);
    if (!a.header) return vx_resp_json(c, r, a.status, doc, h, v);
    return vx_resp_json(c, r, a.status, doc, a.header,
                        a.header && !a.value ? vx_req_route_allow(r->route) : a.value);
}

int vx_resp_fail(struct MHD_Connection *c, req *r, vx_err_kind kind, const char *code,
                 const char *fmt, ...)
{
    vx_err e;
    va_list ap;
    va_start(ap, fmt);
    vx_err_setv(&e, kind, code, fmt, ap);
    va_end(ap);
    return vx_resp_err(c, r, &e);
}

void vx_resp_disposition(char *out, size_t n, const char *name, const char *file,
                         const char *fallback, const char *ext)
{
    char fn[3 * 128], stem[128];
    /* a name stored before the rules of vx_name_ok is not used */
    if (name && !vx_name_ok(name, strlen(name))) name = NULL;
    snprintf(stem, sizeof stem, "%s", name ? name : fallback);
    char *dot = strrchr(stem, '.');
    if (name && dot && dot != stem) *dot = 0;
    if (file && !name)
        snprintf(fn, sizeof fn, "%s", file);
    else if (file)
        snprintf(fn, sizeof fn, "%s-%s", stem, file);
    else if (name)
        snprintf(fn, sizeof fn, "%s", name);
    else
        snprintf(fn, sizeof fn, "%s.%s", fallback, ext);
    /* filename=: the fallback (a result's own file name) when there is a
     * file, else fn as ASCII; filename*=: fn as UTF-8. */
    const char *plain = file ? fallback : fn;
    char ascii[sizeof fn], enc[3 * sizeof fn];
    size_t a = 0, e = 0;
    for (const unsigned char *c = (const unsigned char *)plain; *c && a + 1 < sizeof ascii; c++)
        ascii[a++] = *c >= 0x20 && *c < 0x7f && *c != '"' && *c != '\\' ? (char)*c : '_';
    for (const unsigned char *c = (const unsigned char *)fn; *c; c++) {
        if ((*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') || (*c >= '0' && *c <= '9') ||
            *c == '-' || *c == '.' || *c == '_')
            enc[e++] = (char)*c;
        else
            e += (size_t)snprintf(enc + e, sizeof enc - e, "%%%02X", *c);
    }
    ascii[a] = enc[e] = 0;
    snprintf(out, n, "attachment; filename=\"%s\"; filename*=UTF-8''%s", ascii, enc);
}
