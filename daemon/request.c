/* Request parsing without libmicrohttpd (request.h). Everything here is
 * strict on purpose: numbers are plain decimal, a declared query parameter
 * must appear at most once with a value, and text that reaches a JSON
 * answer is valid UTF-8. */
#include "request.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/random.h>
#include <time.h>

#include <cJSON.h>

#include "jobs/jobs.h"
#include "store/store.h"

static const struct {
    const char *name; /* metrics label: the path template */
    const char *allow;
} routes[VX_R_COUNT] = {
    [VX_R_UNKNOWN] = {"unmatched", ""},
    [VX_R_LIVEZ] = {"/livez", "GET, HEAD, OPTIONS"},
    [VX_R_READYZ] = {"/readyz", "GET, HEAD, OPTIONS"},
    [VX_R_METRICS] = {"/metrics", "GET, HEAD, OPTIONS"},
    [VX_R_INFO] = {"/v1/info", "GET, HEAD, OPTIONS"},
    [VX_R_MESHES] = {"/v1/meshes", "GET, HEAD, POST, OPTIONS"},
    [VX_R_MESH] = {"/v1/meshes/{id}", "GET, HEAD, DELETE, OPTIONS"},
    [VX_R_MESH_FILE] = {"/v1/meshes/{id}/file", "GET, HEAD, OPTIONS"},
    [VX_R_JOBS] = {"/v1/jobs", "GET, HEAD, POST, OPTIONS"},
    [VX_R_JOB] = {"/v1/jobs/{id}", "GET, HEAD, DELETE, OPTIONS"},
    [VX_R_RESULT] = {"/v1/jobs/{id}/result", "GET, HEAD, OPTIONS"},
    [VX_R_RESULT_NAME] = {"/v1/jobs/{id}/result/{name}", "GET, HEAD, OPTIONS"},
    [VX_R_WEB_INDEX] = {"/", "GET, HEAD, OPTIONS"},
    [VX_R_WEB_DOCS] = {"/docs", "GET, HEAD, OPTIONS"},
    [VX_R_WEB_SPEC] = {"/openapi.yaml", "GET, HEAD, OPTIONS"},
    [VX_R_WEB_ASSET] = {"/ui/{name}", "GET, HEAD, OPTIONS"},
    [VX_R_EVENTS] = {"/v1/jobs/{id}/events", "GET, HEAD, OPTIONS"},
};

static int is(const char *p, size_t len, const char *lit)
{
    size_t n = strlen(lit);
    return len == n && !memcmp(p, lit, n);
}

static int starts(const char *p, size_t len, const char *lit)
{
    size_t n = strlen(lit);
    return len >= n && !memcmp(p, lit, n);
}

/* A path segment: non-empty, no '/', no NUL, shorter than VX_REQ_ID_MAX. */
static int segment(const char *p, size_t n, char *out)
{
    if (!n || n >= VX_REQ_ID_MAX || memchr(p, '/', n) || memchr(p, 0, n)) return 0;
    memcpy(out, p, n);
    out[n] = 0;
    return 1;
}

vx_route vx_req_route(const char *path, size_t len, vx_req_target *t)
{
    t->id[0] = t->name[0] = 0;
    t->route = VX_R_UNKNOWN;
    if (is(path, len, "/livez"))
        t->route = VX_R_LIVEZ;
    else if (is(path, len, "/readyz"))
        t->route = VX_R_READYZ;
    else if (is(path, len, "/metrics"))
        t->route = VX_R_METRICS;
    else if (is(path, len, "/v1/info"))
        t->route = VX_R_INFO;
    else if (is(path, len, "/v1/meshes"))
        t->route = VX_R_MESHES;
    else if (is(path, len, "/v1/jobs"))
        t->route = VX_R_JOBS;
    else if (is(path, len, "/"))
        t->route = VX_R_WEB_INDEX;
    else if (is(path, len, "/docs"))
        t->route = VX_R_WEB_DOCS;
    else if (is(path, len, "/openapi.yaml"))
        t->route = VX_R_WEB_SPEC;
    else if (starts(path, len, "/ui/")) {
        if (segment(path + 4, len - 4, t->name)) t->route = VX_R_WEB_ASSET;
    } else if (starts(path, len, "/v1/meshes/")) {
        const char *rest = path + 11, *end = path + len;
        const char *slash = memchr(rest, '/', (size_t)(end - rest));
        if (!slash && segment(rest, len - 11, t->id))
            t->route = VX_R_MESH;
        else if (slash && is(slash, (size_t)(end - slash), "/file") &&
                 segment(rest, (size_t)(slash - rest), t->id))
            t->route = VX_R_MESH_FILE;
    } else if (starts(path, len, "/v1/jobs/")) {
        const char *rest = path + 9, *end = path + len;
        const char *slash = memchr(rest, '/', (size_t)(end - rest));
        size_t n = (size_t)((slash ? slash : end) - rest);
        if (!segment(rest, n, t->id)) return t->route;
        if (!slash)
            t->route = VX_R_JOB;
        else if (is(slash, (size_t)(end - slash), "/result"))
            t->route = VX_R_RESULT;
        else if (is(slash, (size_t)(end - slash), "/events"))
            t->route = VX_R_EVENTS;
        else if (starts(slash, (size_t)(end - slash), "/result/") &&
                 segment(slash + 8, (size_t)(end - slash - 8), t->name))
            t->route = VX_R_RESULT_NAME;
    }
    if (t->route == VX_R_UNKNOWN) t->id[0] = t->name[0] = 0;
    return t->route;
}

const char *vx_req_route_name(vx_route rt)
{
    return (unsigned)rt < VX_R_COUNT ? routes[rt].name : routes[VX_R_UNKNOWN].name;
}

const char *vx_req_route_allow(vx_route rt)
{
    return (unsigned)rt < VX_R_COUNT ? routes[rt].allow : "";
}

int vx_req_method_known(const char *m)
{
    static const char *known[] = {"GET",     "HEAD",    "POST",  "PUT",   "DELETE",
                                  "CONNECT", "OPTIONS", "TRACE", "PATCH", NULL};
    for (int i = 0; known[i]; i++)
        if (!strcmp(m, known[i])) return 1;
    return 0;
}

int vx_req_method_allowed(vx_route rt, const char *m)
{
    const char *allow = vx_req_route_allow(rt);
    size_t n = strlen(m);
    if (!n) return 0;
    for (const char *p = allow; (p = strstr(p, m)); p += n)
        if ((p == allow || p[-1] == ' ') && (p[n] == 0 || p[n] == ',')) return 1;
    return 0;
}

void vx_req_media_type(const char *ct, char *out, size_t n)
{
    size_t o = 0;
    if (ct)
        for (; *ct && *ct != ';' && o + 1 < n; ct++)
            if (*ct != ' ' && *ct != '\t')
                out[o++] = (char)(*ct >= 'A' && *ct <= 'Z' ? *ct + 32 : *ct);
    out[o] = 0;
}

int vx_req_transfer_encoding(const char *te)
{
    if (!te) return 0;
    if (!te[strspn(te, " \t")]) return -2; /* an empty value: no coding at all, malformed */
    /* exactly as libmicrohttpd reads it: "chunked " (trailing white space,
     * which it keeps) it does not take as chunked, and read the body to
     * the connection's end while this took it for chunks */
    return !strcasecmp(te, "chunked") ? 1 : -1;
}

int vx_req_parse_length(const char *s, uint64_t *out)
{
    size_t n = strlen(s);
    if (!n || n > 19) return -1;
    uint64_t v = 0;
    for (size_t i = 0; i < n; i++) {
        if (s[i] < '0' || s[i] > '9') return -1;
        v = v * 10 + (uint64_t)(s[i] - '0');
    }
    *out = v;
    return 0;
}

/* ---- query parameters ------------------------------------------------ */

int vx_req_parse_limit(const char *s, size_t len, int *out)
{
    if (!len || len > 4) return -1; /* "1000" is the longest */
    int v = 0;
    for (size_t i = 0; i < len; i++) {
        if (s[i] < '0' || s[i] > '9') return -1;
        v = v * 10 + (s[i] - '0');
    }
    if (v < 1 || v > 1000) return -1;
    *out = v;
    return 0;
}

int vx_req_parse_seconds(const char *s, size_t len, uint64_t *us)
{
    const uint64_t max_s = VX_REQ_WAIT_MAX_US / 1000000;
    uint64_t whole = 0, frac = 0;
    size_t i = 0, nint = 0;
    for (; i < len && s[i] >= '0' && s[i] <= '9'; i++, nint++)
        if (whole <= max_s) whole = whole * 10 + (uint64_t)(s[i] - '0');
    if (!nint) return -1;
    if (i < len) {
        if (s[i] != '.') return -1;
        i++;
        size_t nfrac = 0;
        for (; i < len && s[i] >= '0' && s[i] <= '9'; i++, nfrac++)
            if (nfrac < 6) frac = frac * 10 + (uint64_t)(s[i] - '0');
        if (!nfrac || i < len) return -1;
        for (; nfrac < 6; nfrac++)
            frac *= 10;
    }
    *us = whole >= max_s ? VX_REQ_WAIT_MAX_US : whole * 1000000 + frac;
    return 0;
}

void vx_req_query_init(vx_req_query *q)
{
    memset(q, 0, sizeof *q);
    q->limit = 100;
}

enum qparam {
    Q_NONE,
    Q_LIMIT,
    Q_AFTER,
    Q_STATE,
    Q_WAIT,
    Q_PROGRESS,
    Q_ORDER,
    Q_KIND,
    Q_MESH,
    Q_NAME
};

/* Which parameters a route and method declare (api/openapi.yaml). */
static enum qparam declared(vx_route rt, const char *method, const char *key, size_t klen)
{
    int get = !strcmp(method, "GET") || !strcmp(method, "HEAD");
    int post = !strcmp(method, "POST");
    if ((rt == VX_R_MESHES || rt == VX_R_JOBS) && get) {
        if (is(key, klen, "limit")) return Q_LIMIT;
        if (is(key, klen, "after")) return Q_AFTER;
        if (rt == VX_R_JOBS && is(key, klen, "state")) return Q_STATE;
        if (rt == VX_R_JOBS && is(key, klen, "order")) return Q_ORDER;
        if (rt == VX_R_JOBS && is(key, klen, "kind")) return Q_KIND;
        if (rt == VX_R_JOBS && is(key, klen, "mesh")) return Q_MESH;
    }
    if (((rt == VX_R_JOBS && post) || (rt == VX_R_JOB && get)) && is(key, klen, "wait"))
        return Q_WAIT;
    if (rt == VX_R_JOB && get && is(key, klen, "progress")) return Q_PROGRESS;
    if (rt == VX_R_MESHES && post && is(key, klen, "name")) return Q_NAME;
    return Q_NONE;
}

/* A kind's name in form: lower-case letters, digits and '-'. */
static int kind_name(const char *s, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!((s[i] >= 'a' && s[i] <= 'z') || (s[i] >= '0' && s[i] <= '9') || s[i] == '-'))
            return 0;
    return n > 0;
}

static int job_state(const char *s)
{
    static const char *states[] = {"queued", "running", "succeeded", "failed", "canceled"};
    for (size_t i = 0; i < sizeof states / sizeof states[0]; i++)
        if (!strcmp(s, states[i])) return 1;
    return 0;
}

int vx_req_query_add(vx_req_query *q, vx_route rt, const char *method, const char *key, size_t klen,
                     const char *value, size_t vlen, char *msg, size_t msgn)
{
    enum qparam p = declared(rt, method, key, klen);
    if (p == Q_NONE) return 0;
    static const char *names[] = {"",         "limit", "after", "state", "wait",
                                  "progress", "order", "kind",  "mesh",  "name"};
    const char *name = names[p];
    int *seen = p == Q_LIMIT   ? &q->has_limit
                : p == Q_AFTER ? &q->has_after
                : p == Q_STATE ? &q->has_state
                : p == Q_WAIT  ? &q->has_wait
                : p == Q_ORDER ? &q->has_order
                : p == Q_KIND  ? &q->has_kind
                : p == Q_MESH  ? &q->has_mesh
                : p == Q_NAME  ? &q->has_name
                               : &q->has_progress;
    if (*seen) {
        snprintf(msg, msgn, "query parameter %s is given more than once", name);
        return -1;
    }
    *seen = 1;
    if (!value || !vlen) {
        snprintf(msg, msgn, "query parameter %s needs a value", name);
        return -1;
    }
    if (memchr(value, 0, vlen)) {
        snprintf(msg, msgn, "query parameter %s holds a NUL byte", name);
        return -1;
    }
    switch (p) {
    case Q_LIMIT:
        if (vx_req_parse_limit(value, vlen, &q->limit)) {
            snprintf(msg, msgn, "query parameter limit must be a decimal integer from 1 to 1000");
            return -1;
        }
        return 0;
    case Q_AFTER:
        if (vlen >= sizeof q->after) goto bad_after;
        memcpy(q->after, value, vlen);
        q->after[vlen] = 0;
        if (rt == VX_R_MESHES ? !vx_store_valid_mesh_id(q->after) : !vx_jobs_valid_id(q->after))
            goto bad_after;
        return 0;
    case Q_STATE:
        if (vlen >= sizeof q->state) goto bad_state;
        memcpy(q->state, value, vlen);
        q->state[vlen] = 0;
        if (!job_state(q->state)) goto bad_state;
        return 0;
    case Q_ORDER:
        if (!is(value, vlen, "asc") && !is(value, vlen, "desc")) {
            snprintf(msg, msgn, "query parameter order must be asc or desc");
            return -1;
        }
        q->desc = is(value, vlen, "desc");
        return 0;
    case Q_KIND:
        if (vlen >= sizeof q->kind || !kind_name(value, vlen)) {
            snprintf(msg, msgn, "query parameter kind must be a job kind's name");
            return -1;
        }
        memcpy(q->kind, value, vlen);
        q->kind[vlen] = 0;
        return 0;
    case Q_MESH:
        if (vlen >= sizeof q->mesh) goto bad_mesh;
        memcpy(q->mesh, value, vlen);
        q->mesh[vlen] = 0;
        if (!vx_store_valid_mesh_id(q->mesh)) goto bad_mesh;
        return 0;
    case Q_NAME:
        if (!vx_name_ok(value, vlen)) {
            snprintf(msg, msgn,
                     "query parameter name must be 1 to %d bytes of UTF-8 without control or "
                     "invisible format characters, '/', '\\' or '\"', and not . or ..",
                     VX_NAME_MAX);
            return -1;
        }
        memcpy(q->name, value, vlen);
        q->name[vlen] = 0;
        return 0;
    case Q_WAIT:
        if (vx_req_parse_seconds(value, vlen, &q->wait_us)) {
            snprintf(msg, msgn,
                     "query parameter wait must be a non-negative decimal number of seconds");
            return -1;
        }
        return 0;
    case Q_PROGRESS: {
        uint64_t ppm;
        if (vx_req_parse_seconds(value, vlen, &ppm) || ppm > 1000000) {
            snprintf(msg, msgn, "query parameter progress must be a decimal number from 0 to 1");
            return -1;
        }
        q->progress_ppm = (uint32_t)ppm;
        return 0;
    }
    default:
        return 0;
    }
bad_after:
    q->after[0] = 0;
    snprintf(msg, msgn, "query parameter after must be a %s id",
             rt == VX_R_MESHES ? "mesh" : "job");
    return -1;
bad_mesh:
    q->mesh[0] = 0;
    snprintf(msg, msgn, "query parameter mesh must be a mesh id (64 hex digits)");
    return -1;
bad_state:
    q->state[0] = 0;
    snprintf(msg, msgn,
             "query parameter state must be queued, running, succeeded, failed or canceled");
    return -1;
}

int vx_req_query_format(const vx_req_query *q, char *out, size_t n)
{
    size_t o = 0;
    int k;
    out[0] = 0;
#define PUT(...)                                                                                   \
    do {                                                                                           \
        k = snprintf(out + o, n - o, "%s", o ? "&" : "");                                          \
        if (k < 0 || (size_t)k >= n - o) return -1;                                                \
        o += (size_t)k;                                                                            \
        k = snprintf(out + o, n - o, __VA_ARGS__);                                                 \
        if (k < 0 || (size_t)k >= n - o) return -1;                                                \
        o += (size_t)k;                                                                            \
    } while (0)
    if (q->has_limit) PUT("limit=%d", q->limit);
    if (q->has_after) PUT("after=%s", q->after);
    if (q->has_state) PUT("state=%s", q->state);
    if (q->has_order) PUT("order=%s", q->desc ? "desc" : "asc");
    if (q->has_kind) PUT("kind=%s", q->kind);
    if (q->has_mesh) PUT("mesh=%s", q->mesh);
    if (q->has_wait)
        PUT("wait=%llu.%06llu", (unsigned long long)(q->wait_us / 1000000),
            (unsigned long long)(q->wait_us % 1000000));
    if (q->has_progress)
        PUT("progress=%u.%06u", (unsigned)(q->progress_ppm / 1000000),
            (unsigned)(q->progress_ppm % 1000000));
    if (q->has_name) {
        /* Percent-encoded but for unreserved characters. */
        char enc[3 * VX_NAME_MAX + 1];
        size_t e = 0;
        for (const unsigned char *c = (const unsigned char *)q->name; *c; c++) {
            if ((*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') || (*c >= '0' && *c <= '9') ||
                *c == '-' || *c == '.' || *c == '_' || *c == '~')
                enc[e++] = (char)*c;
            else
                e += (size_t)snprintf(enc + e, sizeof enc - e, "%%%02X", *c);
        }
        enc[e] = 0;
        PUT("name=%s", enc);
    }
#undef PUT
    return (int)o;
}

/* ---- mesh names --------------------------------------------------------- */

/* Where the value of Content-Disposition parameter name (without '=')
 * starts: at the value's start or after a ';' outside a quoted string;
 * NULL when it is not there. */
static const char *disposition_param(const char *cd, const char *name)
{
    size_t n = strlen(name);
    int quoted = 0;
    for (const char *p = cd; p && *p; p++) {
        if (quoted) {
            if (*p == '\\' && p[1])
                p++;
            else if (*p == '"')
                quoted = 0;
            continue;
        }
        if (*p == '"') quoted = 1;
        if (p != cd && *p != ';') continue;
        const char *q = p == cd ? p : p + 1;
        while (*q == ' ' || *q == '\t')
            q++;
        if (strncasecmp(q, name, n) != 0) continue;
        for (q += n; *q == ' ' || *q == '\t'; q++)
            ;
        if (*q != '=') continue;
        for (q++; *q == ' ' || *q == '\t'; q++)
            ;
        return q;
    }
    return NULL;
}

static int hex_digit(int c)
{
    return c >= '0' && c <= '9'   ? c - '0'
           : c >= 'a' && c <= 'f' ? c - 'a' + 10
           : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                  : -1;
}

/* An RFC 8187 ext-value (charset'language'percent-encoded, the charset
 * UTF-8 or ISO-8859-1) decoded into UTF-8 in out: 0, or -1 when it is not
 * one (another charset, a bad or NUL escape, too long). */
static int ext_value(const char *v, char *out, size_t n)
{
    const char *q1 = strchr(v, '\'');
    if (!q1) return -1;
    size_t cs = (size_t)(q1 - v);
    int latin1 = cs == 10 && !strncasecmp(v, "ISO-8859-1", 10);
    if (!latin1 && !(cs == 5 && !strncasecmp(v, "UTF-8", 5))) return -1;
    const char *q2 = strchr(q1 + 1, '\'');
    if (!q2) return -1;
    size_t k = 0;
    for (const char *p = q2 + 1; *p && *p != ';' && *p != ' ' && *p != '\t'; p++) {
        int c = (unsigned char)*p;
        if (c == '%') {
            int hi = hex_digit(p[1]), lo = hi < 0 ? -1 : hex_digit(p[2]);
            if (lo < 0 || (hi | lo) == 0) return -1;
            c = hi << 4 | lo;
            p += 2;
        }
        if (k + 3 >= n) return -1;
        if (latin1 && c >= 0x80) {
            out[k++] = (char)(0xC0 | c >> 6);
            out[k++] = (char)(0x80 | (c & 0x3f));
        } else {
            out[k++] = (char)c;
        }
    }
    out[k] = 0;
    return 0;
}

int vx_req_disposition_name(const char *cd, char *out, size_t n)
{
    out[0] = 0;
    char buf[4 * VX_NAME_MAX];
    size_t k = 0;
    /* filename*= (RFC 6266: preferred), else filename= */
    const char *p = disposition_param(cd, "filename*");
    if (p && !ext_value(p, buf, sizeof buf)) {
        k = strlen(buf);
    } else if ((p = disposition_param(cd, "filename"))) {
        if (*p == '"') {
            for (p++; *p && *p != '"'; p++) {
                if (*p == '\\' && p[1]) p++;
                if (k + 1 >= sizeof buf) return -1;
                buf[k++] = *p;
            }
            if (*p != '"') return -1;
        } else {
            for (; *p && *p != ';' && *p != ' ' && *p != '\t'; p++) {
                if (k + 1 >= sizeof buf) return -1;
                buf[k++] = *p;
            }
        }
    } else {
        return disposition_param(cd, "filename*") ? -1 : 0;
    }
    buf[k] = 0;
    /* The client's directories are no part of the name. */
    const char *base = buf;
    for (const char *q = buf; *q; q++)
        if (*q == '/' || *q == '\\') base = q + 1;
    size_t len = strlen(base);
    if (!vx_name_ok(base, len) || len >= n) return -1;
    memcpy(out, base, len + 1);
    return 1;
}

/* ---- UTF-8 ------------------------------------------------------------ */

int vx_req_utf8_valid(const char *s, size_t len)
{
    const unsigned char *p = (const unsigned char *)s;
    for (size_t i = 0; i < len;) {
        size_t k = vx_err_utf8_len(p + i, len - i);
        if (!k) return 0;
        i += k;
    }
    return 1;
}

char *vx_req_utf8_sanitize(const char *s, char *out, size_t n)
{
    const unsigned char *p = (const unsigned char *)s;
    size_t len = strlen(s), o = 0;
    for (size_t i = 0; i < len;) {
        size_t k = vx_err_utf8_len(p + i, len - i);
        if (k <= 1) {
            if (o + 1 >= n) break;
            out[o++] = k == 1 && p[i] >= 0x20 && p[i] != 0x7f ? (char)p[i] : '?';
            i++;
            continue;
        }
        if (o + k >= n) break;
        memcpy(out + o, p + i, k);
        o += k;
        i += k;
    }
    out[o] = 0;
    return out;
}

int vx_req_json_text_ok(const char *body, size_t len, char *msg, size_t msgn)
{
    if (!vx_req_utf8_valid(body, len)) {
        snprintf(msg, msgn, "the body is not valid UTF-8");
        return -1;
    }
    /* Outside strings a backslash is invalid JSON anyway (the parser says
     * so); inside, each escape is two characters, so "\\u0000" is text. */
    for (size_t i = 0; i + 1 < len; i++) {
        if (body[i] != '\\') continue;
        if (body[i + 1] == 'u' && i + 5 < len && !memcmp(body + i + 2, "0000", 4)) {
            snprintf(msg, msgn, "the body holds a \\u0000 escape (NUL is not allowed in strings)");
            return -1;
        }
        i++;
    }
    if (memchr(body, 0, len)) {
        snprintf(msg, msgn, "the body holds a NUL byte");
        return -1;
    }
    return 0;
}

/* Length of the JSON number at p (p < end, *p '-' or a digit), or 0 when
 * the run of number characters there is not one. */
static size_t json_number(const char *p, const char *end)
{
    const char *s = p, *e = p;
    while (e < end && ((*e >= '0' && *e <= '9') || *e == '-' || *e == '+' || *e == '.' ||
                       *e == 'e' || *e == 'E'))
        e++;
    if (s < e && *s == '-') s++;
    if (s == e || *s < '0' || *s > '9') return 0;
    if (*s++ == '0') {
        if (s < e && *s >= '0' && *s <= '9') return 0; /* a leading zero */
    } else {
        while (s < e && *s >= '0' && *s <= '9')
            s++;
    }
    if (s < e && *s == '.') {
        const char *f = ++s;
        while (s < e && *s >= '0' && *s <= '9')
            s++;
        if (s == f) return 0;
    }
    if (s < e && (*s == 'e' || *s == 'E')) {
        s++;
        if (s < e && (*s == '+' || *s == '-')) s++;
        const char *f = s;
        while (s < e && *s >= '0' && *s <= '9')
            s++;
        if (s == f) return 0;
    }
    return s == e ? (size_t)(e - p) : 0;
}

/* Whether the number token p[0..n) (JSON's form) has a nonzero digit
 * before its exponent but reads as 0 in a double (1e-400): cJSON would
 * take it as 0, and a field that must be over 0 would see 0. */
static int json_number_underflows(const char *p, size_t n)
{
    /* Below the smallest double (4.9e-324) only with a negative exponent,
     * or 323 zeros after the point: every other number (a frames body
     * holds 10^5 of them) is not read twice. */
    const char *e = memchr(p, 'e', n);
    if (!e) e = memchr(p, 'E', n);
    if (n <= 320 && !(e && e + 1 < p + n && e[1] == '-')) return 0;
    int nonzero = 0;
    for (size_t i = 0; i < n && p[i] != 'e' && p[i] != 'E'; i++)
        nonzero |= p[i] >= '1' && p[i] <= '9';
    if (!nonzero) return 0;
    char small[128], *t = n < sizeof small ? small : malloc(n + 1);
    if (!t) return 0; /* no memory to tell: cJSON reads it as before */
    memcpy(t, p, n);
    t[n] = 0;
    const int under = strtod(t, NULL) == 0.0;
    if (t != small) free(t);
    return under;
}

static int cmp_key(const void *a, const void *b)
{
    return strcmp(*(const char *const *)a, *(const char *const *)b);
}

/* The first key an object of v's tree holds twice, or NULL. */
static const char *json_dup_key(const cJSON *v)
{
    if (!cJSON_IsObject(v) && !cJSON_IsArray(v)) return NULL;
    size_t n = 0;
    for (const cJSON *c = v->child; c; c = c->next) {
        const char *d = json_dup_key(c);
        if (d) return d;
        n++;
    }
    if (!cJSON_IsObject(v) || n < 2) return NULL;
    const char **k = malloc(n * sizeof *k);
    if (!k) return "?"; /* no memory to check: refuse rather than guess */
    n = 0;
    for (const cJSON *c = v->child; c; c = c->next)
        k[n++] = c->string;
    qsort(k, n, sizeof *k, cmp_key);
    const char *dup = NULL;
    for (size_t i = 1; i < n && !dup; i++)
        if (!strcmp(k[i - 1], k[i])) dup = k[i];
    free(k);
    return dup;
}

cJSON *vx_req_json_parse(const char *body, size_t len, char *msg, size_t msgn)
{
    if (vx_req_json_text_ok(body, len, msg, msgn)) return NULL;
    const char *end = body + len;
    int depth = 0;
    for (const char *p = body; p < end;) {
        if (*p == '[' || *p == '{') {
            if (++depth > CJSON_NESTING_LIMIT) {
                snprintf(msg, msgn, "arrays and objects nest deeper than %d levels (at byte %zu)",
                         CJSON_NESTING_LIMIT, (size_t)(p - body));
                return NULL;
            }
            p++;
        } else if (*p == ']' || *p == '}') {
            depth--;
            p++;
        } else if (*p == '"') { /* a string: escapes are two characters, no raw controls */
            for (p++; p < end && *p != '"'; p++) {
                if ((unsigned char)*p < 0x20) {
                    snprintf(msg, msgn, "a string holds a raw control character (escape it)");
                    return NULL;
                }
                if (*p == '\\') p++;
            }
            p++;
        } else if (*p == '-' || (*p >= '0' && *p <= '9')) {
            size_t n = json_number(p, end);
            if (!n) {
                snprintf(msg, msgn, "a number is not in JSON's form (at byte %zu)",
                         (size_t)(p - body));
                return NULL;
            }
            if (json_number_underflows(p, n)) {
                snprintf(msg, msgn,
                         "a number is nearer 0 than any double and would read as 0 (at byte %zu)",
                         (size_t)(p - body));
                return NULL;
            }
            p += n;
        } else {
            p++;
        }
    }
    const char *stop = NULL;
    cJSON *doc = cJSON_ParseWithLengthOpts(body, len, &stop, 0);
    if (!doc) { /* cJSON leaves stop where it failed */
        if (stop && stop >= body && stop <= end)
            snprintf(msg, msgn, "the body is not valid JSON (at byte %zu)", (size_t)(stop - body));
        else
            snprintf(msg, msgn, "the body is not valid JSON");
        return NULL;
    }
    while (stop && stop < end && (*stop == ' ' || *stop == '\t' || *stop == '\n' || *stop == '\r'))
        stop++;
    if (stop && stop < end) {
        snprintf(msg, msgn, "the body has more after its JSON value (at byte %zu)",
                 (size_t)(stop - body));
        cJSON_Delete(doc);
        return NULL;
    }
    const char *dup = json_dup_key(doc);
    if (dup) {
        char key[64];
        snprintf(msg, msgn, "an object has the key \"%s\" twice",
                 vx_req_utf8_sanitize(dup, key, sizeof key));
        cJSON_Delete(doc);
        return NULL;
    }
    return doc;
}

/* ---- content negotiation, ranges, validators ------------------------ */

/* The q of one Accept-Encoding element's parameters (p after the coding,
 * at ';' or the element's end): 1 when absent, -1 when malformed. */
static double coding_q(const char *p, const char *end)
{
    while (p < end && (*p == ' ' || *p == '\t' || *p == ';'))
        p++;
    if (p == end) return 1;
    if (end - p < 2 || (p[0] != 'q' && p[0] != 'Q') || p[1] != '=') return -1;
    p += 2;
    double q = 0, scale = 1;
    if (p == end || (*p != '0' && *p != '1')) return -1;
    q = *p++ - '0';
    if (p < end && *p == '.')
        for (p++; p < end && *p >= '0' && *p <= '9'; p++) {
            if (scale < 0.0015) return -1; /* qvalue: at most three decimals (RFC 9110 12.4.2) */
            scale /= 10;
            q += (*p - '0') * scale;
        }
    while (p < end && (*p == ' ' || *p == '\t'))
        p++;
    return p == end && q <= 1 ? q : -1;
}

vx_req_coding vx_req_accept_coding(const char *ae)
{
    if (!ae) return VX_CODING_IDENTITY;
    double qz = -1, qg = -1, qstar = -1, qi = -1;
    for (const char *p = ae; *p;) {
        const char *end = strchr(p, ',');
        if (!end) end = p + strlen(p);
        while (p < end && (*p == ' ' || *p == '\t'))
            p++;
        const char *t = p;
        while (t < end && *t != ';' && *t != ' ' && *t != '\t')
            t++;
        size_t n = (size_t)(t - p);
        double q = coding_q(t, end);
        if (q >= 0) {
            if (n == 4 && !strncasecmp(p, "zstd", 4)) qz = q;
            if ((n == 4 && !strncasecmp(p, "gzip", 4)) || (n == 6 && !strncasecmp(p, "x-gzip", 6)))
                qg = q;
            if (n == 1 && *p == '*') qstar = q;
            if (n == 8 && !strncasecmp(p, "identity", 8)) qi = q;
        }
        p = *end ? end + 1 : end;
    }
    if (qz < 0) qz = qstar;
    if (qg < 0) qg = qstar;
    /* the client's preference (RFC 9110 12.5.3): identity given a higher
     * q than every coding we have is sent as it is */
    if (qi > (qz > qg ? qz : qg)) return VX_CODING_IDENTITY;
    if (qz > 0 && qz >= qg) return VX_CODING_ZSTD;
    if (qg > 0) return VX_CODING_GZIP;
    return VX_CODING_IDENTITY;
}

/* Parses digits at *p, advancing it; leading zeros are digits like any
 * other, and a number of more than 19 digits after them is UINT64_MAX
 * (past any end: a first-pos that large is 416, as any other past the
 * end). 0 or -1. */
static int range_num(const char **p, uint64_t *v)
{
    const char *s = *p;
    uint64_t x = 0;
    int n = 0, sig = 0;
    for (; *s >= '0' && *s <= '9'; s++, n++) {
        if (!sig && *s == '0') continue;
        x = sig >= 19 ? UINT64_MAX : x * 10 + (uint64_t)(*s - '0');
        sig++;
    }
    if (!n) return -1;
    *p = s;
    *v = x;
    return 0;
}

/* One range-spec, [p, e) with no blanks around it: as vx_req_range. */
static int range_spec(const char *p, const char *e, uint64_t size, uint64_t *first, uint64_t *last)
{
    uint64_t a = 0, b = UINT64_MAX;
    if (*p == '-') { /* a suffix: the last b bytes */
        p++;
        if (range_num(&p, &b) || p != e) return 0;
        if (b == 0 || size == 0) return -1;
        *first = b >= size ? 0 : size - b;
        *last = size - 1;
        return 1;
    }
    if (range_num(&p, &a) || p == e || *p++ != '-') return 0;
    if (p < e && range_num(&p, &b)) return 0;
    if (p != e || b < a) return 0;
    if (a >= size) return -1;
    *first = a;
    *last = b >= size ? size - 1 : b;
    return 1;
}

int vx_req_range(const char *v, uint64_t size, uint64_t *first, uint64_t *last)
{
    if (!v) return 0;
    while (*v == ' ' || *v == '\t')
        v++;
    if (strncasecmp(v, "bytes=", 6)) return 0;
    /* A list whose empty elements are ignored (RFC 9110 5.6.1.2): one range
     * left is served, several are the whole body. */
    const char *one = NULL, *one_end = NULL;
    for (const char *p = v + 6; *p;) {
        while (*p == ' ' || *p == '\t' || *p == ',')
            p++;
        const char *s = p;
        while (*p && *p != ',')
            p++;
        const char *e = p;
        while (e > s && (e[-1] == ' ' || e[-1] == '\t'))
            e--;
        if (e == s) continue;
        if (one) return 0;
        one = s;
        one_end = e;
    }
    return one ? range_spec(one, one_end, size, first, last) : 0;
}

int vx_req_etag_match(const char *list, const char *etag, int weak_ok, int star_ok)
{
    if (!list) return 0;
    size_t n = strlen(etag);
    for (const char *p = list; *p;) {
        while (*p == ' ' || *p == '\t' || *p == ',')
            p++;
        if (!*p) break;
        if (*p == '*') {
            if (star_ok) return 1;
            p++;
            continue;
        }
        int weak = p[0] == 'W' && p[1] == '/';
        if (weak) p += 2;
        if (*p != '"') { /* not a tag (an If-Range date): no match */
            while (*p && *p != ',')
                p++;
            continue;
        }
        const char *q = strchr(p + 1, '"');
        if (!q) return 0;
        if ((!weak || weak_ok) && (size_t)(q + 1 - p) == n && !memcmp(p, etag, n)) return 1;
        p = q + 1;
    }
    return 0;
}

void vx_req_new_id(char out[17])
{
    unsigned char rnd[8] = {0};
    if (getrandom(rnd, sizeof rnd, GRND_NONBLOCK) != (ssize_t)sizeof rnd) {
        static unsigned long long seq;
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        unsigned long long v =
            __atomic_add_fetch(&seq, 1, __ATOMIC_RELAXED) ^
            ((unsigned long long)ts.tv_sec * 1000000000ull + (unsigned long long)ts.tv_nsec);
        memcpy(rnd, &v, sizeof rnd);
    }
    for (int i = 0; i < 8; i++)
        snprintf(out + 2 * i, 3, "%02x", rnd[i]);
}

int vx_req_id_ok(const char *s)
{
    size_t n = s ? strlen(s) : 0;
    if (!n || n > 64) return 0;
    for (size_t i = 0; i < n; i++) {
        char c = s[i];
        if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
              c == '.' || c == '_' || c == ':' || c == '-'))
            return 0;
    }
    return 1;
}
