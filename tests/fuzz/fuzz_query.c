/* libFuzzer target: route matching and strict query parsing (daemon/request.c)
 * on arbitrary bytes, handed over as libmicrohttpd would: the first byte
 * picks the method, the rest is "path?query"; the path stops at its first
 * NUL (libmicrohttpd's strings do), the query is split at '&' and at the
 * first '=' of each argument (none: the value is NULL), each part %-decoded.
 * Oracle: no crash or sanitizer report; a matched route written back as a
 * path matches the same route, id and name; an accepted query respects the
 * limits and, written back by vx_req_query_format, parses to the same
 * result; a rejected one says why. The UTF-8 sanitizer's output is valid
 * UTF-8, and the other helpers hold their contracts on the same bytes (a
 * name read from them as a Content-Disposition value is a valid name, a
 * byte range read from them lies within the file); the
 * strict JSON parser's accepted bodies print back to bodies it accepts. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "jobs/jobs.h"
#include "request.h"
#include "store/store.h"
#include "util/name.h"

static const char *methods[] = {"GET", "HEAD", "POST", "DELETE", "PUT", "PATCH", "OPTIONS", ""};

static int hexval(int c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* %-decodes s[0..n) into out (n + 1 bytes); returns the decoded length. */
static size_t unescape(const char *s, size_t n, char *out)
{
    size_t o = 0;
    for (size_t i = 0; i < n; i++) {
        int a, b;
        if (s[i] == '%' && i + 2 < n && (a = hexval((unsigned char)s[i + 1])) >= 0 &&
            (b = hexval((unsigned char)s[i + 2])) >= 0) {
            out[o++] = (char)(a * 16 + b);
            i += 2;
        } else {
            out[o++] = s[i];
        }
    }
    out[o] = 0;
    return o;
}

/* Feeds query string s[0..n) into q. Returns 0 when every argument was
 * taken, -1 at the first rejected one (msg says why). */
static int parse_query(vx_req_query *q, vx_route rt, const char *method, const char *s, size_t n,
                       char *msg, size_t msgn)
{
    vx_req_query_init(q);
    char *buf = malloc(2 * n + 2);
    if (!buf) abort();
    size_t i = 0;
    int rc = 0;
    while (i <= n && n) {
        const char *arg = s + i;
        const char *amp = memchr(arg, '&', n - i);
        size_t alen = amp ? (size_t)(amp - arg) : n - i;
        const char *eq = memchr(arg, '=', alen);
        size_t klen = eq ? (size_t)(eq - arg) : alen;
        char *key = buf, *val = buf + klen + 1;
        size_t kl = unescape(arg, klen, key), vl = 0;
        if (eq) vl = unescape(eq + 1, alen - klen - 1, val);
        msg[0] = 0;
        if (vx_req_query_add(q, rt, method, key, kl, eq ? val : NULL, vl, msg, msgn)) {
            if (!msg[0] || !memchr(msg, 0, msgn)) abort(); /* a rejection must say why */
            rc = -1;
            break;
        }
        i += alen + 1;
    }
    free(buf);
    return rc;
}

static void check_route(const char *path, size_t len)
{
    vx_req_target t, u;
    vx_route rt = vx_req_route(path, len, &t);
    if ((unsigned)rt >= VX_R_COUNT) abort();
    if (rt == VX_R_UNKNOWN) {
        if (t.id[0] || t.name[0]) abort();
        return;
    }
    if (strlen(t.id) >= VX_REQ_ID_MAX || strlen(t.name) >= VX_REQ_ID_MAX) abort();
    if (strchr(t.id, '/') || strchr(t.name, '/')) abort();
    /* Written back from the template, the path matches the same way. */
    char back[512];
    const char *tpl = vx_req_route_name(rt);
    size_t o = 0;
    for (const char *p = tpl; *p; p++) {
        const char *sub = NULL;
        if (!strncmp(p, "{id}", 4))
            sub = t.id, p += 3;
        else if (!strncmp(p, "{name}", 6))
            sub = t.name, p += 5;
        if (sub) {
            if (!*sub) abort();
            o += (size_t)snprintf(back + o, sizeof back - o, "%s", sub);
        } else {
            back[o++] = *p;
        }
    }
    back[o] = 0;
    if (o != len || memcmp(back, path, len)) abort(); /* paths are matched exactly */
    if (vx_req_route(back, o, &u) != rt || strcmp(u.id, t.id) || strcmp(u.name, t.name)) abort();
    if (!vx_req_route_allow(rt)[0]) abort();
}

static void check_query(vx_route rt, const char *method, const char *s, size_t n)
{
    vx_req_query q, r;
    char msg[160];
    if (parse_query(&q, rt, method, s, n, msg, sizeof msg)) return;
    if (q.limit < 1 || q.limit > 1000) abort();
    if (!q.has_limit && q.limit != 100) abort();
    if (q.wait_us > VX_REQ_WAIT_MAX_US) abort();
    if (q.progress_ppm > 1000000 || (!q.has_progress && q.progress_ppm)) abort();
    if (q.has_after &&
        !(rt == VX_R_MESHES ? vx_store_valid_mesh_id(q.after) : vx_jobs_valid_id(q.after)))
        abort();
    if (q.has_state && !q.state[0]) abort();
    char back[512];
    int len = vx_req_query_format(&q, back, sizeof back);
    if (len < 0) abort(); /* every accepted set fits */
    if (parse_query(&r, rt, method, back, (size_t)len, msg, sizeof msg)) abort();
    if (memcmp(&q, &r, sizeof q)) abort();
}

/* A job body the strict parser accepts prints back (cJSON, unformatted)
 * to text it accepts again and that prints the same; a refused one says
 * why. */
static void check_json(const char *s, size_t n)
{
    char why[160] = "";
    cJSON *doc = vx_req_json_parse(s, n, why, sizeof why);
    if (!doc) {
        if (!why[0]) abort();
        return;
    }
    char *text = cJSON_PrintUnformatted(doc);
    if (!text) abort();
    cJSON *back = vx_req_json_parse(text, strlen(text), why, sizeof why);
    if (!back) abort();
    char *again = cJSON_PrintUnformatted(back);
    if (!again || strcmp(text, again)) abort();
    cJSON_free(again);
    cJSON_free(text);
    cJSON_Delete(back);
    cJSON_Delete(doc);
}

static void check_text(const char *s, size_t n)
{
    /* A NUL-terminated copy, as message text would be. */
    char *z = malloc(n + 1), out[300];
    if (!z) abort();
    memcpy(z, s, n);
    z[n] = 0;
    vx_req_utf8_sanitize(z, out, sizeof out);
    if (!vx_req_utf8_valid(out, strlen(out))) abort();
    for (const unsigned char *p = (const unsigned char *)out; *p; p++)
        if (*p < 0x20 || *p == 0x7f) abort();
    char mt[64];
    vx_req_media_type(z, mt, sizeof mt);
    for (const char *p = mt; *p; p++)
        if ((*p >= 'A' && *p <= 'Z') || *p == ' ' || *p == ';') abort();
    uint64_t v;
    if (!vx_req_parse_length(z, &v)) {
        char b[32];
        snprintf(b, sizeof b, "%llu", (unsigned long long)v);
        if (strlen(b) > strlen(z)) abort();
    }
    uint64_t us, us2;
    if (!vx_req_parse_seconds(s, n, &us)) {
        char b[48];
        int k = snprintf(b, sizeof b, "%llu.%06llu", (unsigned long long)(us / 1000000),
                         (unsigned long long)(us % 1000000));
        if (us > VX_REQ_WAIT_MAX_US || vx_req_parse_seconds(b, (size_t)k, &us2) || us2 != us)
            abort();
    }
    int lim;
    if (!vx_req_parse_limit(s, n, &lim) && (lim < 1 || lim > 1000)) abort();
    char why[160];
    if (!vx_req_json_text_ok(s, n, why, sizeof why) && !vx_req_utf8_valid(s, n)) abort();
    /* -2 (an empty value) for blanks alone */
    int te = vx_req_transfer_encoding(z);
    if (te < -2 || te > 1 || (te == -2) != (z[strspn(z, " \t")] == 0)) abort();
    /* As a Range value over a file of some sizes: one range within it, or
     * ignored (0), or unsatisfiable (-1, never for a range from 0 on a
     * non-empty file) */
    static const uint64_t sizes[] = {0, 1, 10, 1000, UINT64_MAX};
    for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++) {
        uint64_t first = 0, last = 0;
        int rr = vx_req_range(z, sizes[i], &first, &last);
        if (rr < -1 || rr > 1 || (rr == 1 && (first > last || last >= sizes[i]))) abort();
    }
    /* As a Content-Disposition value: a name it gives is a valid one. */
    char name[VX_NAME_MAX + 8];
    int nr = vx_req_disposition_name(z, name, sizeof name);
    if (nr < -1 || nr > 1 || (nr == 1 && !vx_name_ok(name, strlen(name)))) abort();
    check_json(s, n);
    free(z);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1) return 0;
    const char *method = methods[data[0] % (sizeof methods / sizeof methods[0])];
    const char *s = (const char *)data + 1;
    size_t n = size - 1;
    const char *qm = memchr(s, '?', n);
    size_t plen = qm ? (size_t)(qm - s) : n;
    /* The path as libmicrohttpd hands it over: decoded, up to a NUL. */
    char *path = malloc(plen + 1);
    if (!path) abort();
    size_t dl = unescape(s, plen, path);
    dl = strnlen(path, dl);
    check_route(path, dl);
    vx_req_target t;
    vx_route rt = vx_req_route(path, dl, &t);
    if (vx_req_method_allowed(rt, method) && rt == VX_R_UNKNOWN) abort();
    if (qm) check_query(rt, method, qm + 1, n - plen - 1);
    /* The same query against every route that declares parameters. */
    if (qm) {
        check_query(VX_R_MESHES, "GET", qm + 1, n - plen - 1);
        check_query(VX_R_JOBS, "GET", qm + 1, n - plen - 1);
        check_query(VX_R_JOBS, "POST", qm + 1, n - plen - 1);
        check_query(VX_R_JOB, "HEAD", qm + 1, n - plen - 1);
    }
    check_text(s, n);
    free(path);
    return 0;
}
