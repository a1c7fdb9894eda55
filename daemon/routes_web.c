/* The browser side (README "Viewer"): the viewer page at /, the API
 * reference at /docs, the contract at /openapi.yaml and the page's scripts
 * and styles at /ui/{name}, all built into the binary (web.h). These
 * routes are public even with --token (http.c asks a token of /v1/ paths
 * only): they hold nothing but the program's own files, and the page sends
 * the token the user enters with its API calls. */
#include <nettle/base64.h>
#include <nettle/sha2.h>
#include <stdio.h>
#include <string.h>

#include "http_int.h"
#include "web.h"

/* The Content-Security-Policy of an HTML page into out: scripts from the
 * daemon, and each inline script by the SHA-256 of its text (the viewer's
 * import map), so that no other inline script runs. */
static void page_csp(const vx_web_file *f, char *out, size_t n)
{
    size_t at = (size_t)snprintf(out, n, "default-src 'self'; script-src 'self'");
    const char *p = (const char *)f->data, *end = p + f->len;
    while (at < n && (p = memmem(p, (size_t)(end - p), "<script", 7))) {
        const char *gt = memchr(p, '>', (size_t)(end - p));
        const char *text = gt ? gt + 1 : end;
        const char *close = gt ? memmem(text, (size_t)(end - text), "</script>", 9) : NULL;
        if (!close) break;
        if (!memmem(p, (size_t)(gt - p), " src=", 5)) {
            struct sha256_ctx sha;
            uint8_t digest[SHA256_DIGEST_SIZE];
            char b64[BASE64_ENCODE_RAW_LENGTH(SHA256_DIGEST_SIZE) + 1];
            sha256_init(&sha);
            sha256_update(&sha, (size_t)(close - text), (const uint8_t *)text);
            sha256_digest(&sha, sizeof digest, digest);
            base64_encode_raw(b64, sizeof digest, digest);
            b64[sizeof b64 - 1] = 0;
            at += (size_t)snprintf(out + at, n - at, " 'sha256-%s'", b64);
        }
        p = close + 9;
    }
    if (at < n)
        snprintf(out + at, n - at,
                 "; img-src 'self' blob: data:; object-src 'none'; base-uri 'none'; "
                 "frame-ancestors 'none'");
}

int vx_route_web(vx_http *h, struct MHD_Connection *c, req *r)
{
    const char *name = r->route == VX_R_WEB_INDEX  ? "index.html"
                       : r->route == VX_R_WEB_DOCS ? "docs.html"
                       : r->route == VX_R_WEB_SPEC ? "openapi.yaml"
                                                   : r->name;
    const vx_web_file *f = vx_web_find(name);
    if (!f) return vx_resp_fail(c, r, VX_ENOTFOUND, "not_found", "no such viewer file");
    int pre = vx_resp_preconditions(c, f->etag, NULL);
    if (pre == 412) return vx_resp_precondition_failed(c, r, f->etag);
    int fresh = pre == 304;
    struct MHD_Response *resp =
        fresh ? vx_resp_headers_only() /* 304: no Content-Length */
              : MHD_create_response_from_buffer(f->len, (void *)f->data, MHD_RESPMEM_PERSISTENT);
    if (!resp) return MHD_NO;
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, f->etag);
    /* Names are not versioned: keep a copy but ask each time (304 then). */
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-cache");
    if (fresh) return vx_resp_queue(c, r, 304, resp, 0);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, f->ctype);
    MHD_add_response_header(resp, "X-Content-Type-Options", "nosniff");
    if (!strncmp(f->ctype, "text/html", 9)) {
        char csp[1024];
        page_csp(f, csp, sizeof csp);
        MHD_add_response_header(resp, "Content-Security-Policy", csp);
    }
    return vx_resp_queue(c, r, 200, resp, f->len);
}
