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
 * The files of the layer (http_int.h): respond.c makes every response and
 * maps errors to statuses; routes_misc.c, routes_meshes.c and
 * routes_jobs.c are the handlers; wait.c holds ?wait requests; events.c
 * streams job events (Server-Sent Events); conns.c
 * tracks connections against slow clients (issue #10) and answers those
 * with a JSON 408 or 414; auth.c checks bearer tokens. This file is the
 * libmicrohttpd plumbing: the access handler, framing and head checks,
 * body intake, dispatch, completion and the server's lifecycle. */
#include "http_int.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <netdb.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/random.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "metrics.h"
#include "origin.h"
#include "sockq.h"
#include "util/fsutil.h"
#include "util/log.h"

void vx_http_job_changed(vx_http *h, const char *jid, int terminal)
{
    if (!h) return;
    vx_events_job_changed(h->events, jid);
    if (terminal) vx_wait_job_changed(h->wait, jid);
}

/* ---- dispatch ------------------------------------------------------ */

/* How many times the headers that must come once came, and whether a
 * field name or value was malformed (bad), a line folded onto the last
 * (fold) or a value cut at a NUL (nul). */
typedef struct once_counts {
    int host, length, idem, coding, auth, type, bad, fold, nul, badhost;
    const char *line_end; /* where the last line's text ended (check_in_place) */
} once_counts;

/* What libmicrohttpd 0.9.75 hides when it parses a head in place (its
 * buffer holds "name\0 value\0\0" for "name: value\r\n", the fields
 * pointing into it, one line after the other), which a proxy in front may
 * read otherwise:
 * - a line folded onto the last (obs-fold, RFC 9112 5.2) is glued to the
 *   field's NAME in a copy elsewhere ("Content-Length:\r\n 52" became a
 *   field "Content-Length52" of no value, and the 52 bytes of body a
 *   second request): the value then does not follow its name;
 * - a NUL in a value ends it there ("Content-Length: 0\0" "99"): the next
 *   line then does not start one or two bytes (LF, CR LF) after it. The
 *   first line starts after the version's end (n->line_end at the start);
 *   the last one's end is head_cut's. */
static void check_in_place(once_counts *n, const char *key, size_t klen, const char *value,
                           size_t vlen)
{
    const char *e = n->line_end;
    if (e && key != e + 1 && !(key == e + 2 && e[1] == '\0')) n->nul = 1;
    n->line_end = NULL;
    const uintptr_t k = (uintptr_t)key, v = (uintptr_t)value;
    /* (a key moved by a fold stays within the connection's 256 KiB) */
    if (v < k + klen + 1 || v - (k + klen + 1) > ((size_t)256 << 10) || key[klen] != '\0') {
        n->fold = 1;
        return;
    }
    for (const char *p = key + klen + 1; p < value; p++)
        if (*p != ' ' && *p != '\t') n->fold = 1;
    n->line_end = value + vlen;
}

/* Whether the head ends otherwise than after the last line's end (end:
 * the last value's, or the version's) with its line end and the empty
 * line, 2 to 4 bytes libmicrohttpd 0.9.75 made NULs: it took a line with
 * an empty field name (": x") for the empty line and read what followed
 * as the next request, or the last value held a NUL. A bare ":" ended by
 * a lone LF leaves the same NULs as a line end, and passes. */
static int head_cut(struct MHD_Connection *c, const char *head, const char *end)
{
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_REQUEST_HEADER_SIZE);
    if (!ci || !head || !end || end < head || end >= head + ci->header_size) return 0;
    const size_t gap = (size_t)(head + ci->header_size - end);
    if (gap < 2 || gap > 4) return 1;
    for (size_t i = 0; i < gap; i++)
        if (end[i] != '\0') return 1;
    return 0;
}

/* A field name must be a token, a value hold no NUL, CR or LF (RFC 9110
 * 5.1, 5.5): libmicrohttpd took "Content-Length : 34" as a field of
 * another name (the body then read as a second request). */
static enum MHD_Result check_field(void *cls, enum MHD_ValueKind kind, const char *key, size_t klen,
                                   const char *value, size_t vlen)
{
    once_counts *n = cls;
    (void)kind;
    if (!key) return MHD_YES;
    if (!klen) { /* a line ": x" (the head's first: libmicrohttpd kept it) */
        n->bad = 1;
        return MHD_NO;
    }
    for (size_t i = 0; i < klen; i++) {
        unsigned char ch = (unsigned char)key[i];
        if (!(isalnum(ch) || strchr("!#$%&'*+-.^_`|~", ch)) || !ch) n->bad = 1;
    }
    for (size_t i = 0; value && i < vlen; i++)
        if (value[i] == 0 || value[i] == '\r' || value[i] == '\n') n->bad = 1;
    if (value && vx_mhd_in_place()) check_in_place(n, key, klen, value, vlen);
    return n->bad || n->fold || n->nul ? MHD_NO : MHD_YES;
}

/* uri-host [":" port] (RFC 9112 3.2, RFC 3986 3.2.2): a registered name
 * (unreserved, sub-delims and %XX escapes) or an IP literal in brackets,
 * then at most one ":" and a port of digits up to 65535; empty for a target
 * without an authority. Trailing white space libmicrohttpd 0.9.75 leaves
 * in a value is not the value's. */
static int host_ok(const char *v)
{
    size_t n = strlen(v), i = 0;
    while (n && (v[n - 1] == ' ' || v[n - 1] == '\t')) /* (not the value's: OWS) */
        n--;
    if (n && v[0] == '[') { /* an IPv6 address, or IPvFuture */
        for (i = 1; i < n && v[i] != ']'; i++)
            if (!isalnum((unsigned char)v[i]) && !strchr(":.-_~!$&'()*+,;=", v[i])) return 0;
        if (i == n) return 0;             /* no "]" */
        if (v[1] == 'v' || v[1] == 'V') { /* "v" 1*HEXDIG "." 1*(unreserved / sub-delims / ":") */
            size_t k = 2;
            while (k < i && isxdigit((unsigned char)v[k]))
                k++;
            if (k == 2 || k >= i || v[k] != '.' || k + 1 == i) return 0;
        } else {
            char a[INET6_ADDRSTRLEN];
            struct in6_addr six;
            if (i - 1 >= sizeof a) return 0;
            memcpy(a, v + 1, i - 1);
            a[i - 1] = 0;
            if (inet_pton(AF_INET6, a, &six) != 1) return 0;
        }
        i++;
    } else {
        for (; i < n && v[i] != ':'; i++) {
            if (v[i] == '%') {
                if (i + 2 >= n || !isxdigit((unsigned char)v[i + 1]) ||
                    !isxdigit((unsigned char)v[i + 2]))
                    return 0;
                i += 2;
            } else if (!isalnum((unsigned char)v[i]) && !strchr("-._~!$&'()*+,;=", v[i])) {
                return 0;
            }
        }
    }
    if (i == n) return 1;
    if (v[i] != ':') return 0; /* "[::1]x" */
    unsigned long port = 0;
    for (i++; i < n; i++) {
        if (!isdigit((unsigned char)v[i])) return 0;
        port = port * 10 + (unsigned long)(v[i] - '0');
        if (port > 65535) return 0;
    }
    return 1;
}

static enum MHD_Result count_once(void *cls, enum MHD_ValueKind kind, const char *key,
                                  const char *value)
{
    once_counts *n = cls;
    if (!key) return MHD_YES;
    if (!strcasecmp(key, MHD_HTTP_HEADER_HOST)) {
        n->host++;
        if (value && !host_ok(value)) n->badhost = 1;
    }
    if (!strcasecmp(key, MHD_HTTP_HEADER_CONTENT_LENGTH)) n->length++;
    if (!strcasecmp(key, "Idempotency-Key")) n->idem++;
    if (!strcasecmp(key, MHD_HTTP_HEADER_AUTHORIZATION)) n->auth++;
    if (!strcasecmp(key, MHD_HTTP_HEADER_TRANSFER_ENCODING)) n->coding++;
    if (!strcasecmp(key, MHD_HTTP_HEADER_CONTENT_TYPE)) n->type++;
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

/* A 400 after which the connection closes: the body's framing is in
 * doubt, so nothing after this head may be read as another request
 * (request smuggling behind a proxy that framed it otherwise). */
static int fail_framing(struct MHD_Connection *c, req *r, const char *why)
{
    vx_err e;
    vx_err_set(&e, VX_EINVAL, "invalid_request", "%s", why);
    return vx_resp_err_with(c, r, &e, MHD_HTTP_HEADER_CONNECTION, "close");
}

/* 1 when the head announces a body (a length other than 0, or chunks). */
static int declares_body(struct MHD_Connection *c)
{
    const char *cl = vx_resp_header(c, MHD_HTTP_HEADER_CONTENT_LENGTH);
    uint64_t n;
    return vx_resp_header(c, MHD_HTTP_HEADER_TRANSFER_ENCODING) ||
           (cl && (vx_req_parse_length(cl, &n) || n > 0));
}

/* Framing the access handler can still answer in JSON: Host, the transfer
 * coding, the length, headers that must come once. Returns a queued answer
 * or -1. */
static int check_framing(struct MHD_Connection *c, req *r, const char *head, const char *version)
{
    once_counts n = {0};
    const int in_place = vx_mhd_in_place();
    if (in_place) n.line_end = version + strlen(version);
    MHD_get_connection_values(c, MHD_HEADER_KIND, count_once, &n);
    MHD_get_connection_values_n(c, MHD_HEADER_KIND, check_field, &n);
    if (n.bad)
        return fail_framing(c, r,
                            "a header field name that is not a token (a space before its "
                            "colon?) or a value with a NUL, CR or LF");
    if (n.fold)
        return fail_framing(c, r,
                            "a header line continued on the next (a line starting with a space or "
                            "tab: obs-fold, RFC 9112 5.2): put each field on one line");
    if (n.nul) return fail_framing(c, r, "a header value with a NUL");
    if (in_place && head_cut(c, head, n.line_end))
        return fail_framing(c, r,
                            "a header line with an empty field name (': x', RFC 9110 5.1) or a "
                            "NUL at the last value's end");
    if (vx_conns_line_cut(r->vc, head, version))
        return fail_framing(c, r,
                            "a request line whose method, target and version are not split by "
                            "single spaces, or a NUL in its method or target");
    if (vx_conns_target_bad(r->vc))
        return fail_framing(c, r,
                            "the request target has a space or a control character (escape it: "
                            "%20)");
    /* two Host lines are in doubt in HTTP/1.0 too (the first was taken,
     * where the Host check went by it) */
    if (n.host > 1 || (strcmp(version, MHD_HTTP_VERSION_1_0) != 0 && n.host != 1))
        return vx_resp_fail(c, r, VX_EINVAL, "invalid_request",
                            n.host ? "more than one Host header"
                                   : "an HTTP/1.1 request needs a Host header");
    if (n.badhost)
        return vx_resp_fail(c, r, VX_EINVAL, "invalid_request",
                            "a Host header that is not a host and port");
    if (n.length > 1) return fail_framing(c, r, "more than one Content-Length header");
    const char *te = vx_resp_header(c, MHD_HTTP_HEADER_TRANSFER_ENCODING);
    /* two Transfer-Encoding lines are one list (RFC 9112): libmicrohttpd
     * reads the first only, a proxy may go by the last */
    int coding = n.coding > 1 ? -1 : vx_req_transfer_encoding(te);
    if (coding == -2) return fail_framing(c, r, "an empty Transfer-Encoding header");
    if (coding < 0)
        return vx_resp_fail(c, r, VX_ENOTIMPL, "not_implemented",
                            "the only transfer coding taken is chunked, written so (no gzip, "
                            "no lists, no blank after it)");
    if (coding > 0 && n.length)
        return fail_framing(c, r, "Content-Length and Transfer-Encoding together");
    /* RFC 9112 6.1: an HTTP/1.0 message's framing is faulty with one */
    if (te && !strcmp(version, MHD_HTTP_VERSION_1_0))
        return fail_framing(c, r, "Transfer-Encoding in an HTTP/1.0 request");
    /* the upload reads the first; a proxy may go by the last */
    if (n.type > 1) return fail_framing(c, r, "more than one Content-Type header");
    if (n.idem > 1)
        return vx_resp_fail(c, r, VX_EINVAL, "invalid_request",
                            "more than one Idempotency-Key header");
    /* the token check reads the first; a proxy may go by the last */
    if (n.auth > 1)
        return vx_resp_fail(c, r, VX_EINVAL, "invalid_request",
                            "more than one Authorization header");
    return -1;
}

/* libmicrohttpd's idle timeout back on c (it was off while an answer was
 * sent: vx_resp_queue); in the connection's own thread. */
static void own_timeout(vx_http *h, struct MHD_Connection *c, vx_conn *vc)
{
    MHD_set_connection_option(c, MHD_CONNECTION_OPTION_TIMEOUT,
                              (unsigned)ceil(h->d.cfg->connection_timeout_s));
    vx_conns_own_idle(vc, 0);
}

static int first_call(vx_http *h, struct MHD_Connection *c, req *r, const char *head,
                      const char *version)
{
    if (vx_conns_owns_idle(r->vc)) own_timeout(h, c, r->vc); /* a next request has come */
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_REQUEST_HEADER_SIZE);
    if (ci && ci->header_size > h->d.cfg->max_header_bytes)
        return vx_resp_fail(c, r, VX_EHEADER, "header_too_large",
                            "the request head is larger than max-header-bytes");
    int rc = check_framing(c, r, head, version);
    if (rc >= 0) return rc;
    const char *host = vx_resp_header(c, MHD_HTTP_HEADER_HOST);
    if (!vx_origin_host_ok(host))
        return vx_resp_fail(c, r, VX_EFORBIDDEN, "host_not_allowed",
                            "Host %.100s is not a name of this daemon: it answers IP addresses, "
                            "localhost, *.localhost, names without a dot and --allowed-hosts",
                            host);
    if (!vx_req_method_known(r->method))
        return vx_resp_fail(c, r, VX_ENOTIMPL, "not_implemented",
                            "method %.40s is not implemented (voxeld takes GET, HEAD, POST, DELETE "
                            "and OPTIONS)",
                            r->method);
    if (r->route == VX_R_UNKNOWN)
        return vx_resp_fail(c, r, VX_ENOTFOUND, "not_found", "no such route");
    /* Only POST takes a body: any other's would be read into memory (up to
     * max-json-bytes, before auth) and hold its slot while it trickles. */
    if (strcmp(r->method, "POST") != 0 && declares_body(c))
        return fail_framing(c, r, "only POST takes a request body");
    /* A CORS preflight carries no credentials: answered before auth. */
    if (!strcmp(r->method, "OPTIONS")) return -1;
    if (vx_origin_cross_site_write(c, r->method))
        return vx_resp_fail(c, r, VX_EFORBIDDEN, "cross_origin",
                            "a %s from a page of another origin (%.100s) that --cors-origin does "
                            "not allow",
                            r->method, vx_resp_header(c, "Origin"));
    if (!strncmp(vx_req_route_name(r->route), "/v1/", 4) && h->auth.on &&
        !vx_auth_ok(&h->auth, vx_resp_header(c, MHD_HTTP_HEADER_AUTHORIZATION)))
        return vx_resp_fail(c, r, VX_EAUTH, "unauthorized",
                            "a valid bearer token is required: send 'Authorization: Bearer "
                            "TOKEN' with the token of the daemon's --token-file (voxelctl: "
                            "--token or VOXELD_TOKEN)");
    if (!vx_req_method_allowed(r->route, r->method))
        return vx_resp_fail(c, r, VX_EMETHOD, "method_not_allowed", "method %s is not allowed here",
                            r->method);
    vx_req_query_init(&r->q);
    MHD_get_connection_values_n(c, MHD_GET_ARGUMENT_KIND, take_arg, r);
    if (strcmp(r->method, "POST") != 0) return -1; /* no body: answer in dispatch */
    if (h->stopping || !vx_jobs_ready(h->d.jobs)) {
        char why[600];
        vx_route_not_ready_reason(h, why, sizeof why);
        return vx_resp_fail(c, r, VX_EUNAVAIL, "not_ready", "%s", why);
    }
    if (r->qerr[0]) return vx_resp_fail(c, r, VX_EINVAL, "invalid_request", "%s", r->qerr);

    /* No room, or a data dir gone read-only (a remount: a file made and
     * removed in DATA/tmp, as /readyz does): refused before the body, which
     * would fail late (an upload) or at its first output (a job). A local
     * job submission is answered still when it names a job already there
     * (Idempotency-Key, reuse): it is refused only if it would make one. */
    uint64_t nfree;
    vx_err no_room;
    vx_err_clear(&no_room);
    if (!vx_route_disk_ok(h, &nfree)) {
        if (!h->d.cfg->min_free_disk)
            vx_err_set(&no_room, VX_ENOSPC, "insufficient_storage",
                       "the data dir's disk is full; reads still work");
        else
            vx_err_set(&no_room, VX_ENOSPC, "insufficient_storage",
                       "the data dir has %llu bytes free, under the %llu-byte floor "
                       "(--min-free-disk); reads still work",
                       (unsigned long long)(nfree == UINT64_MAX ? 0 : nfree),
                       (unsigned long long)h->d.cfg->min_free_disk);
    } else if (!vx_store_writable(h->d.store)) {
        vx_err_set(&no_room, VX_EUNAVAIL, "not_ready",
                   "the data directory is not writable; reads still work");
    }
    if (no_room.kind != VX_EOK) {
        if (r->route != VX_R_JOBS || vx_jobs_cluster(h->d.jobs, NULL))
            return vx_resp_err(c, r, &no_room);
        r->new_refused = no_room;
    }
    /* A compressed body would be parsed as it is (a gzip'd OBJ read as a
     * format nobody knows): refused by name (RFC 9110 15.5.16). */
    const char *codings = vx_resp_header(c, MHD_HTTP_HEADER_CONTENT_ENCODING), *ce;
    size_t cn;
    while (codings && (ce = vx_resp_list_next(&codings, &cn)))
        if (cn && !(cn == 8 && !strncasecmp(ce, "identity", 8)))
            return vx_resp_fail(c, r, VX_EMEDIA, "unsupported_media_type",
                                "Content-Encoding %.*s: the body must come uncompressed (Draco "
                                "and glb files compress meshes themselves)",
                                (int)(cn < 40 ? cn : 40), ce);
    char mt[128];
    vx_req_media_type(vx_resp_header(c, MHD_HTTP_HEADER_CONTENT_TYPE), mt, sizeof mt);
    if (r->route == VX_R_MESHES) {
        vx_err err;
        if (vx_intake_media_of(mt, &r->declared, &err)) return vx_resp_err(c, r, &err);
        r->body = BODY_UPLOAD;
    } else {
        if (strcmp(mt, "application/json") != 0)
            return vx_resp_fail(c, r, VX_EMEDIA, "unsupported_media_type",
                                "the body must be application/json");
        r->body = BODY_JSON;
    }
    const char *cl = vx_resp_header(c, MHD_HTTP_HEADER_CONTENT_LENGTH);
    const char *te = vx_resp_header(c, MHD_HTTP_HEADER_TRANSFER_ENCODING);
    uint64_t limit =
        r->route == VX_R_MESHES ? h->d.cfg->max_upload_bytes : h->d.cfg->max_json_bytes;
    if (r->route == VX_R_MESHES && !cl && vx_req_transfer_encoding(te) != 1)
        return vx_resp_fail(c, r, VX_ELENGTH, "length_required",
                            "Content-Length or chunked encoding is required");
    if (cl) {
        uint64_t n;
        if (vx_req_parse_length(cl, &n))
            return vx_resp_fail(c, r, VX_EINVAL, "invalid_request", "bad Content-Length");
        if (n > limit)
            return vx_resp_fail(c, r, VX_ETOOBIG, "too_large",
                                "the body (%llu bytes) is larger than the %llu-byte limit",
                                (unsigned long long)n, (unsigned long long)limit);
    }
    if (r->body == BODY_UPLOAD) {
        vx_err err;
        r->up = vx_upload_begin(h->d.store, &err);
        if (!r->up) return vx_resp_err(c, r, &err);
    }
    return -1;
}

static int take_body(vx_http *h, req *r, const char *data, size_t n)
{
    r->bytes_in += n;
    if (r->body == BODY_UPLOAD) {
        if (r->too_big || r->body_err.kind != VX_EOK) return 0;
        if (r->bytes_in > h->d.cfg->max_upload_bytes) {
            /* on_request answers 413 now; the rest is dropped */
            r->too_big = 1;
            vx_upload_abort(r->up);
            r->up = NULL;
            return 0;
        }
        if (vx_upload_write(r->up, data, n, &r->body_err)) {
            /* on_request answers it now (507 on a full disk) */
            VX_ERROR("http.upload_failed", "code=%s", r->body_err.code);
            vx_upload_abort(r->up);
            r->up = NULL;
        }
        return 0;
    }
    if (r->too_big || r->body != BODY_JSON) return 0; /* no body is kept but a JSON one */
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

/* The request's id (the client's X-Request-Id when sane, else a new one),
 * its path and the client's address, for the answer and the log. */
static void identify(struct MHD_Connection *c, req *r, const char *url)
{
    char rbuf[sizeof r->rid];
    const char *rid = vx_resp_header_trim(c, "X-Request-Id", rbuf, sizeof rbuf);
    if (vx_req_id_ok(rid))
        snprintf(r->rid, sizeof r->rid, "%s", rid);
    else
        vx_req_new_id(r->rid);
    vx_log_quote(r->path, sizeof r->path, url);
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
    snprintf(r->client, sizeof r->client, "-");
    if (ci && ci->client_addr) {
        const struct sockaddr *sa = ci->client_addr;
        socklen_t len =
            sa->sa_family == AF_INET6 ? sizeof(struct sockaddr_in6) : sizeof(struct sockaddr_in);
        getnameinfo(sa, len, r->client, sizeof r->client, NULL, 0, NI_NUMERICHOST);
        /* an IPv4 client of a dual-stack listener ([::]) as IPv4, as on an
         * IPv4 one (it was ::ffff:127.0.0.1) */
        if (!strncasecmp(r->client, "::ffff:", 7) && strchr(r->client + 7, '.'))
            memmove(r->client, r->client + 7, strlen(r->client + 7) + 1);
    }
}

/* The first call: the head is in. Allocates r, routes it and answers what
 * the head alone decides (first_call). */
static enum MHD_Result on_head(vx_http *h, struct MHD_Connection *c, const char *url,
                               const char *method, const char *version, void **con_cls)
{
    /* The connection leaves HEAD (unless the sweeper has already answered
     * it, and then nothing may be queued). */
    vx_conn *vc = vx_conns_of(c);
    if (vx_conns_head_in(h->conns, vc)) return MHD_NO;
    req *r = calloc(1, sizeof *r);
    if (!r) return MHD_NO;
    *con_cls = r;
    r->vc = vc;
    r->t0 = vx_mono();
    snprintf(r->method, sizeof r->method, "%s", method);
    /* absolute-form (RFC 9112 3.2.2: a server must take it): the path */
    int scheme = !strncasecmp(url, "http://", 7) ? 7 : !strncasecmp(url, "https://", 8) ? 8 : 0;
    if (scheme) {
        const char *slash = strchr(url + scheme, '/');
        url = slash ? slash : "/";
    }
    identify(c, r, url);
    vx_req_target t = {0};
    r->route = vx_req_route(url, strlen(url), &t);
    if (vx_conns_path_escape(vc)) { /* names nothing: its resource's own 404 */
        /* a %2F last decodes to a trailing '/', which no route has: the
         * route is the one without it (/v1/jobs/ID%2F is a job's 404) */
        size_t n = strlen(url);
        while (!t.id[0] && n > 1 && url[n - 1] == '/') {
            vx_req_target u = {0};
            vx_route rt = vx_req_route(url, --n, &u);
            if (u.id[0]) r->route = rt, t = u;
        }
        if (t.id[0]) /* what the 404's message names */
            snprintf(t.id, sizeof t.id, "(a path with %%00 or %%2F)");
        else
            r->route = VX_R_UNKNOWN;
    }
    memcpy(r->id, t.id, sizeof r->id);
    memcpy(r->name, t.name, sizeof r->name);
    int rc;
    if (h->stopping) r->close = 1; /* a stop waits for no next request */
    if (vx_conns_over_ip(vc)) {
        r->close = 1;
        rc = vx_resp_fail(c, r, VX_EOVERLOAD, "too_many_connections",
                          "%s has more than %llu connections open (--max-connections-per-ip)",
                          r->client, (unsigned long long)h->d.cfg->max_connections_per_ip);
    } else {
        rc = first_call(h, c, r, method, version);
    }
    if (rc >= 0) {
        if (declares_body(c)) vx_conns_linger(h->conns, vc);
        return rc;
    }
    /* A body follows: rate it (another method's was refused above). */
    if (!strcmp(r->method, "POST")) {
        vx_conns_body_begins(h->conns, vc, r->rid, vx_resp_cors_origin(c));
        /* ... and time it out when idle (the sweeper: conns.c) */
        if (h->d.cfg->connection_timeout_s > 0 &&
            MHD_set_connection_option(c, MHD_CONNECTION_OPTION_TIMEOUT, 0u) == MHD_YES)
            vx_conns_own_idle(vc, 1);
    }
    /* Answer on the next call even without a body: a response queued in
     * the first call makes libmicrohttpd 0.9.75 close the connection (it
     * cannot know yet that no body follows). */
    return MHD_YES;
}

/* The last call: the whole request is in. */
static int dispatch(vx_http *h, struct MHD_Connection *c, req *r)
{
    if (vx_waiter_resumed(&r->w)) return vx_route_job_resumed(h, c, r);
    if (!strcmp(r->method, "OPTIONS")) return vx_route_options(h, c, r);
    if (r->qerr[0]) return vx_resp_fail(c, r, VX_EINVAL, "invalid_request", "%s", r->qerr);
    int is_get = !strcmp(r->method, "GET") || !strcmp(r->method, "HEAD");
    switch (r->route) {
    case VX_R_LIVEZ:
        return vx_route_livez(h, c, r);
    case VX_R_READYZ:
        return vx_route_readyz(h, c, r);
    case VX_R_METRICS:
        return vx_route_metrics(h, c, r);
    case VX_R_INFO:
        return vx_route_info(h, c, r);
    case VX_R_MESHES:
        return is_get ? vx_route_mesh_list(h, c, r) : vx_route_upload(h, c, r);
    case VX_R_MESH:
        return vx_route_mesh(h, c, r);
    case VX_R_MESH_FILE:
        return vx_route_mesh_file(h, c, r);
    case VX_R_JOBS:
        return is_get ? vx_route_job_list(h, c, r) : vx_route_job_post(h, c, r);
    case VX_R_JOB:
        return vx_route_job(h, c, r);
    case VX_R_RESULT:
    case VX_R_RESULT_NAME:
        return vx_route_result(h, c, r);
    case VX_R_WEB_INDEX:
    case VX_R_WEB_DOCS:
    case VX_R_WEB_SPEC:
    case VX_R_WEB_ASSET:
        return vx_route_web(h, c, r);
    case VX_R_EVENTS:
        return vx_route_events(h, c, r);
    default:
        return vx_resp_fail(c, r, VX_ENOTFOUND, "not_found", "no such route");
    }
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url,
                                  const char *method, const char *version, const char *data,
                                  size_t *data_size, void **con_cls)
{
    vx_http *h = cls;
    req *r = *con_cls;
    if (!r) return on_head(h, c, url, method, version, con_cls);
    if (vx_conns_body(h->conns, r->vc, *data_size)) {
        /* answered by the sweeper: drain, never queue */
        if (!*data_size) return MHD_NO;
        *data_size = 0;
        return MHD_YES;
    }
    if (r->answered) {
        *data_size = 0; /* an early answer was queued: drop what still arrives */
        return MHD_YES;
    } else if (*data_size) {
        if (take_body(h, r, data, *data_size)) {
            *data_size = 0;
            vx_conns_linger(h->conns, r->vc);
            /* only the JSON body's buffer can fail here (an upload's
             * errors are answered below): an allocation failure */
            return vx_resp_fail(c, r, VX_EINTERNAL, "out_of_memory", "no memory for the body");
        }
        *data_size = 0;
        if (r->body == BODY_UPLOAD && r->body_err.kind != VX_EOK && !r->refused) {
            /* Storing the body failed (the disk filled up): answer now, as
             * the 413 below, not once the body ends (a chunked one on a
             * full disk was read to its end first, forever if endless). */
            r->refused = 1;
            vx_resp_answer a;
            char m[512];
            const char *code = vx_resp_err_text(&r->body_err, &a, m, sizeof m);
            vx_conns_refuse(h->conns, r->vc, (int)a.status, code, m);
        } else if (r->too_big && !r->refused) {
            /* Answer the 413 now, written past libmicrohttpd as the 408s
             * are (it takes no answer in the middle of a body): a chunked
             * body has no end to wait for, and one sent forever was read
             * forever. What still comes is read and dropped, then closed. */
            r->refused = 1;
            char m[96];
            if (r->body == BODY_UPLOAD)
                snprintf(m, sizeof m, "the body is larger than the %llu-byte upload limit",
                         (unsigned long long)h->d.cfg->max_upload_bytes);
            else
                snprintf(m, sizeof m, "the JSON body is larger than max-json-bytes");
            vx_conns_refuse(h->conns, r->vc, 413, "too_large", m);
        }
        return MHD_YES;
    }
    return dispatch(h, c, r);
}

static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls,
                         enum MHD_RequestTerminationCode toe)
{
    vx_http *h = cls;
    req *r = *con_cls;
    if (!r) return;
    vx_wait_forget(h->wait, &r->w); /* the connection died while held */
    double dt = vx_mono() - r->t0;
    const char *route = vx_req_route_name(r->route);
    /* closed before an answer: by libmicrohttpd's --connection-timeout
     * (nothing came for that long: 408, as a proxy logs it), else by the
     * client (499) */
    const int timed_out = toe == MHD_REQUEST_TERMINATED_TIMEOUT_REACHED;
    int status = r->status ? r->status : timed_out ? 408 : 499;
    int killed_with = vx_conns_done(h->conns, r->vc);
    if (killed_with) status = killed_with;
    const union MHD_ConnectionInfo *ci =
        r->timeout_off ? MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD) : NULL;
    if (ci && toe != MHD_REQUEST_TERMINATED_COMPLETED_OK && r->acked0 >= 0) {
        /* what reached the client, not what was queued (heads included) */
        const int64_t acked = vx_sockq_acked(ci->connect_fd);
        if (acked >= r->acked0 && (uint64_t)(acked - r->acked0) < r->bytes_out)
            r->bytes_out = (uint64_t)(acked - r->acked0);
    }
    /* The connection stays, idle again: libmicrohttpd's clock back at
     * once if the kernel holds nothing of the answer; else the sweeper
     * keeps it until the client has read the answer, and the next
     * request's head puts it back (own_timeout). */
    if (ci && toe == MHD_REQUEST_TERMINATED_COMPLETED_OK && vx_sockq_queued(ci->connect_fd) == 0)
        own_timeout(h, c, r->vc);
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
    char mq[80]; /* the method is the client's bytes (escapes, bells) */
    vx_log(lvl, "http.request",
           "request_id=%s method=%s route=%s path=%s client=%s status=%d ms=%.2f bytes_in=%llu "
           "bytes_out=%llu%s",
           r->rid, vx_log_quote(mq, sizeof mq, r->method), route, r->path, r->client, status,
           dt * 1e3, (unsigned long long)r->bytes_in, (unsigned long long)r->bytes_out,
           toe == MHD_REQUEST_TERMINATED_COMPLETED_OK ? ""
           : timed_out                                ? " timed_out=1"
                                                      : " aborted=1");
    vx_upload_abort(r->up);
    free(r->buf);
    free(r);
    *con_cls = NULL;
}

static void mhd_log(void *cls, const char *fmt, va_list ap)
{
    /* At most MHD_LOG_BURST lines a second, then one line saying how many
     * were left out: out of file descriptors, libmicrohttpd says the same
     * thing at every accept (a million lines in 11 s). */
    enum { MHD_LOG_BURST = 20 };
    static vx_log_rate rate = VX_LOG_RATE_INIT;
    unsigned dropped;
    int show = vx_log_rate_ok(&rate, MHD_LOG_BURST, &dropped);
    if (dropped) VX_WARN("http.mhd_suppressed", "lines=%u seconds=1", dropped);
    if (!show) return;
    char msg[512], q[600];
    vsnprintf(msg, sizeof msg, fmt, ap);
    /* a client that went away (an events stream closed by its browser)
     * is no fault of the daemon's: debug, not a warning a stream */
    const int gone = strstr(msg, "no longer available") || strstr(msg, "onnection reset") ||
                     strstr(msg, "closed by remote");
    vx_log(gone ? VX_LOG_DEBUG : VX_LOG_WARN, "http.mhd", "message=%s",
           vx_log_quote(q, sizeof q, msg));
}

/* ---- lifecycle ----------------------------------------------------- */

/* *v6: 0 IPv4, 1 IPv6, 2 the IPv6 wildcard [::], which takes IPv4 too
 * (dual stack: the one address that serves both). */
static int parse_listen(const char *s, struct sockaddr_storage *ss, socklen_t *len, int *v6,
                        vx_err *err)
{
    char host[256], port[6];
    if (vx_config_split_listen(s, host, port)) goto bad;
    struct addrinfo hints = {.ai_family = AF_UNSPEC,
                             .ai_socktype = SOCK_STREAM,
                             .ai_flags = AI_PASSIVE},
                    *ai;
    int gai = getaddrinfo(host[0] ? host : NULL, port, &hints, &ai);
    if (gai != 0) /* the form was checked at start: a host name that does not resolve */
        return vx_err_set(err, VX_EINVAL, "bad_listen",
                          "cannot resolve the host '%s' of listen address '%s': %s", host, s,
                          gai == EAI_SYSTEM ? strerror(errno) : gai_strerror(gai));
    memcpy(ss, ai->ai_addr, ai->ai_addrlen);
    *len = ai->ai_addrlen;
    *v6 = ai->ai_family == AF_INET6;
    if (*v6 && IN6_IS_ADDR_UNSPECIFIED(&((struct sockaddr_in6 *)ss)->sin6_addr)) *v6 = 2;
    freeaddrinfo(ai);
    return 0;
bad:
    return vx_err_set(err, VX_EINVAL, "bad_listen",
                      "cannot parse listen address '%s' (want ADDR:PORT)", s);
}

static int listen_failed(vx_err *err, const char *listen, int e)
{
    return vx_err_set(err, VX_EIO, "listen_failed", "cannot listen on %s: %s", listen,
                      e == EADDRINUSE ? "address in use (another process listens on this port)"
                      : e             ? strerror(e)
                                      : "libmicrohttpd could not start (see http.mhd)");
}

int vx_http_check_listen(const vx_config *cfg, vx_err *err)
{
    struct sockaddr_storage ss;
    socklen_t sslen;
    int v6 = 0;
    if (parse_listen(cfg->listen, &ss, &sslen, &v6, err)) return -1;
    /* the options libmicrohttpd sets on its socket (SO_REUSEADDR by
     * default, SO_REUSEPORT with --reuse-port, IPV6_V6ONLY but for dual
     * stack), so that this bind fails exactly when its would */
    int fd = socket(ss.ss_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return listen_failed(err, cfg->listen, errno);
    int one = 1, v6only = v6 == 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (cfg->reuse_port) setsockopt(fd, SOL_SOCKET, SO_REUSEPORT, &one, sizeof one);
    if (v6) setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, &v6only, sizeof v6only);
    int rc = bind(fd, (struct sockaddr *)&ss, sslen);
    int e = errno;
    close(fd);
    return rc ? listen_failed(err, cfg->listen, e) : 0;
}

vx_http *vx_http_start(const vx_http_desc *desc, vx_err *err)
{
    vx_http *h = calloc(1, sizeof *h);
    if (!h) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    h->d = *desc;
    pthread_mutex_init(&h->parse_budget.lock, NULL);
    vx_resp_init(vx_store_dir(desc->store), desc->cfg->cors_origin);
    const vx_config *cfg = desc->cfg;
    vx_auth_init(&h->auth, cfg->token);

    struct sockaddr_storage ss;
    socklen_t sslen;
    int v6 = 0;
    if (parse_listen(cfg->listen, &ss, &sslen, &v6, err)) {
        free(h);
        return NULL;
    }
    vx_origin_init(cfg->allowed_hosts, !h->auth.on);
    h->wait = vx_wait_start(desc->jobs, cfg->max_waits);
    h->conns = vx_conns_start(cfg);
    h->events = vx_events_start(desc->jobs, cfg->max_event_streams, cfg->event_keepalive_s);
    if (!h->wait || !h->conns || !h->events) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        vx_events_free(h->events);
        vx_wait_free(h->wait);
        vx_conns_free(h->conns);
        free(h);
        return NULL;
    }
    unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_EPOLL | MHD_ALLOW_SUSPEND_RESUME |
                     MHD_USE_ERROR_LOG |
                     (v6 == 2 ? MHD_USE_DUAL_STACK
                      : v6    ? MHD_USE_IPv6
                              : 0);
    /* --reuse-port: MHD_OPTION_LISTENING_ADDRESS_REUSE 1 (SO_REUSEPORT).
     * Without it the option is left out (MHD_OPTION_END stops the list
     * there): libmicrohttpd's default sets SO_REUSEADDR, so a restart binds
     * while the last run's connections sit in TIME_WAIT, and a port another
     * process listens on still cannot be bound (EADDRINUSE). An explicit 0
     * would turn SO_REUSEADDR off. */
    /* One HTTP thread is the internal polling thread alone, without the
     * pool option (the library warns that it ignores a pool of 1, or 0). */
    struct MHD_OptionItem pool[] = {
        {cfg->http_threads > 1 ? MHD_OPTION_THREAD_POOL_SIZE : MHD_OPTION_END,
         (intptr_t)cfg->http_threads, NULL},
        {MHD_OPTION_END, 0, NULL}};
    errno = 0;
    h->mhd = MHD_start_daemon(
        flags, 0, NULL, NULL, on_request, h, MHD_OPTION_EXTERNAL_LOGGER, mhd_log, NULL,
        MHD_OPTION_SOCK_ADDR, (struct sockaddr *)&ss, MHD_OPTION_ARRAY, pool,
        MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)ceil(cfg->connection_timeout_s),
        MHD_OPTION_CONNECTION_LIMIT, (unsigned)cfg->max_connections,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)(256 * 1024), MHD_OPTION_NOTIFY_COMPLETED,
        on_completed, h, MHD_OPTION_NOTIFY_CONNECTION, vx_conns_notify, h->conns,
        MHD_OPTION_URI_LOG_CALLBACK, vx_conns_on_uri, h->conns,
        cfg->reuse_port ? MHD_OPTION_LISTENING_ADDRESS_REUSE : MHD_OPTION_END, 1u, MHD_OPTION_END);
    if (!h->mhd) {
        listen_failed(err, cfg->listen, errno);
        vx_events_free(h->events);
        vx_wait_free(h->wait);
        vx_conns_free(h->conns);
        free(h);
        return NULL;
    }
    const union MHD_DaemonInfo *di = MHD_get_daemon_info(h->mhd, MHD_DAEMON_INFO_BIND_PORT);
    h->port = di ? di->port : 0;
    VX_INFO("http.listen", "listen=%s port=%d threads=%d auth=%d", VX_Q(cfg->listen), h->port,
            cfg->http_threads, h->auth.on);
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
    h->stopping = 1;
    vx_wait_quiesce(h->wait);
    vx_events_quiesce(h->events);
}

void vx_http_stop(vx_http *h, double grace_s, double answers_s)
{
    if (!h) return;
    vx_http_quiesce(h);
    /* (a keep-alive connection idle between requests is not waited for:
     * each held the stop for the whole grace) */
    double until = vx_mono() + grace_s;
    while (vx_mono() < until) {
        const union MHD_DaemonInfo *di =
            MHD_get_daemon_info(h->mhd, MHD_DAEMON_INFO_CURRENT_CONNECTIONS);
        if (!di || di->num_connections == 0 || vx_conns_pending(h->conns) == 0) break;
        usleep(20000);
    }
    /* A head or body still arriving gets a 503, read before the close. An
     * answer being sent (a result downloading) is let finish, up to
     * answers_s (0: main's stop watchdog bounds it; the sweeper still cuts
     * a reader that stalls or is too slow); meanwhile a head still
     * arriving gets the 503 too, and every answer while stopping closes
     * its connection. */
    double killed_at = vx_conns_shutdown(h->conns) > 0 ? vx_mono() : 0;
    const double answers_until = answers_s > 0 ? vx_mono() + answers_s : 0;
    while (vx_conns_answering(h->conns) > 0 && (!answers_until || vx_mono() < answers_until)) {
        usleep(20000);
        if (vx_conns_shutdown(h->conns) > 0) killed_at = vx_mono();
    }
    const double left = killed_at ? killed_at + 0.5 - vx_mono() : 0;
    if (left > 0) usleep((useconds_t)(left * 1e6));
    vx_conns_stop(h->conns);
    MHD_stop_daemon(h->mhd);
    vx_events_free(h->events);
    vx_wait_free(h->wait);
    vx_conns_free(h->conns);
    free(h);
}
