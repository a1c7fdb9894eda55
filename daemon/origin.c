/* Host names and cross-site writes (origin.h). */
#include "origin.h"

#include <arpa/inet.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

#include "http_int.h"

static const char *g_allowed = "";
static int g_check;

void vx_origin_init(const char *allowed, int check)
{
    g_allowed = allowed ? allowed : "";
    g_check = check;
}

/* name (n bytes) is entry (k bytes) of the list, or under a ".name" one,
 * written "*.name" too (an entry's trailing dot is as the name's: none) */
static int listed(const char *name, size_t n, const char *entry, size_t k)
{
    if (k == 1 && entry[0] == '*') return 1;
    if (k > 1 && entry[k - 1] == '.') k--;
    if (k > 2 && entry[0] == '*' && entry[1] == '.') entry++, k--;
    if (k > 1 && entry[0] == '.') {
        if (n == k - 1 && !strncasecmp(name, entry + 1, n)) return 1;
        return n > k && !strncasecmp(name + n - k, entry, k);
    }
    return n == k && !strncasecmp(name, entry, n);
}

int vx_origin_host_ok(const char *host)
{
    if (!host || (!g_check && !g_allowed[0])) return 1;
    /* an IPv6 address (the parser checked it), not an IPvFuture "[v1.x]" */
    if (host[0] == '[') return host[1] != 'v' && host[1] != 'V';
    const char *colon = strchr(host, ':');
    size_t n = colon ? (size_t)(colon - host) : strlen(host);
    while (n && (host[n - 1] == ' ' || host[n - 1] == '\t')) /* what libmicrohttpd leaves */
        n--;
    if (n && host[n - 1] == '.') n--; /* "localhost." is localhost */
    char name[256];
    if (n >= sizeof name) return 0;
    memcpy(name, host, n);
    name[n] = 0;
    struct in_addr a;
    if (inet_pton(AF_INET, name, &a) == 1 || !strpbrk(name, ".%")) return 1;
    static const char lh[] = ".localhost"; /* localhost and every name under it (RFC 6761) */
    if (listed(name, n, lh, sizeof lh - 1)) return 1;
    const char *list = g_allowed, *e;
    size_t k;
    while ((e = vx_resp_list_next(&list, &k)))
        if (k && listed(name, n, e, k)) return 1;
    return 0;
}

/* The port of an authority ("h", "h:8080", "[::1]:80"; blanks after it
 * dropped, as libmicrohttpd leaves them), or dflt. */
static long port_of(const char *auth, size_t n, long dflt, size_t *host_len)
{
    while (n && (auth[n - 1] == ' ' || auth[n - 1] == '\t'))
        n--;
    const char *end = auth + n, *close = auth[0] == '[' ? memchr(auth, ']', n) : NULL;
    const char *colon = NULL;
    for (const char *p = close ? close : auth; p < end; p++)
        if (*p == ':') colon = p;
    *host_len = colon ? (size_t)(colon - auth) : n;
    if (!colon) return dflt;
    long port = 0;
    for (const char *p = colon + 1; p < end; p++) {
        if (*p < '0' || *p > '9' || port > 65535) return -1;
        port = port * 10 + (*p - '0');
    }
    return colon + 1 < end ? port : dflt;
}

/* Origin's scheme and authority are the ones the request came to (its
 * Host; the scheme's default port where either leaves it out). */
static int same_origin(const char *origin, const char *host)
{
    long dflt = !strncasecmp(origin, "http://", 7)    ? 80
                : !strncasecmp(origin, "https://", 8) ? 443
                                                      : 0;
    if (!dflt || !host) return 0; /* "null", another scheme */
    const char *auth = origin + (dflt == 80 ? 7 : 8);
    if (strpbrk(auth, "/?#")) return 0;
    size_t on, hn;
    long op = port_of(auth, strlen(auth), dflt, &on), hp = port_of(host, strlen(host), dflt, &hn);
    return op > 0 && op == hp && on == hn && !strncasecmp(auth, host, on);
}

int vx_origin_cross_site_write(struct MHD_Connection *c, const char *method)
{
    if (!strcmp(method, "GET") || !strcmp(method, "HEAD") || !strcmp(method, "OPTIONS")) return 0;
    const char *origin = vx_resp_header(c, "Origin");
    if (!origin || vx_resp_cors_origin(c)) return 0;
    /* the browser's own word (Fetch Metadata), which a page cannot set */
    const char *site = vx_resp_header(c, "Sec-Fetch-Site");
    if (site) return strcasecmp(site, "same-origin") != 0 && strcasecmp(site, "none") != 0;
    /* a page cannot add X-Forwarded-Host to a request without a preflight,
     * which the server refuses to other origins: a proxy's word */
    const char *fwd = vx_resp_header(c, "X-Forwarded-Host");
    char first[256] = ""; /* proxies after proxies append theirs: the first is the client's */
    if (fwd) {
        size_t k = strcspn(fwd, ", \t");
        snprintf(first, sizeof first, "%.*s", (int)(k < sizeof first ? k : 0), fwd);
    }
    return !same_origin(origin, vx_resp_header(c, MHD_HTTP_HEADER_HOST)) &&
           !(first[0] && same_origin(origin, first));
}
