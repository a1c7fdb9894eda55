/* The browser side (README "Viewer"): the viewer page at /, the API
 * reference at /docs, the contract at /openapi.yaml and the page's scripts
 * and styles at /ui/{name}, all built into the binary (web.h). These
 * routes are public even with --token (http.c asks a token of /v1/ paths
 * only): they hold nothing but the program's own files, and the page sends
 * the token the user enters with its API calls. */
#include <string.h>

#include "http_int.h"
#include "web.h"

/* 1 when an If-None-Match value lists etag (or is "*"). */
static int etag_matches(const char *inm, const char *etag)
{
    if (!inm) return 0;
    if (!strcmp(inm, "*")) return 1;
    size_t n = strlen(etag);
    for (const char *p = inm; (p = strstr(p, etag)); p += n) {
        const char *q = p + n;
        /* a whole entry of the list (a weak W/ prefix compares alike) */
        int left = p == inm || p[-1] == ' ' || p[-1] == ',' || p[-1] == '/';
        int right = !*q || *q == ',' || *q == ' ';
        if (left && right) return 1;
    }
    return 0;
}

int vx_route_web(vx_http *h, struct MHD_Connection *c, req *r)
{
    const char *name = r->route == VX_R_WEB_INDEX  ? "index.html"
                       : r->route == VX_R_WEB_DOCS ? "docs.html"
                       : r->route == VX_R_WEB_SPEC ? "openapi.yaml"
                                                   : r->name;
    const vx_web_file *f = vx_web_find(name);
    if (!f) return vx_resp_fail(c, r, VX_ENOTFOUND, "not_found", "no such viewer file");
    int fresh = etag_matches(vx_resp_header(c, MHD_HTTP_HEADER_IF_NONE_MATCH), f->etag);
    struct MHD_Response *resp = MHD_create_response_from_buffer(
        fresh ? 0 : f->len, fresh ? (void *)"" : (void *)f->data, MHD_RESPMEM_PERSISTENT);
    if (!resp) return MHD_NO;
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, f->etag);
    /* Names are not versioned: keep a copy but ask each time (304 then). */
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-cache");
    if (fresh) return vx_resp_queue(c, r, 304, resp, 0);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, f->ctype);
    MHD_add_response_header(resp, "X-Content-Type-Options", "nosniff");
    if (!strncmp(f->ctype, "text/html", 9)) /* inline: only the import map */
        MHD_add_response_header(resp, "Content-Security-Policy",
                                "default-src 'self'; script-src 'self' 'unsafe-inline'; "
                                "img-src 'self' blob: data:; object-src 'none'; base-uri 'none'; "
                                "frame-ancestors 'none'");
    return vx_resp_queue(c, r, 200, resp, f->len);
}
