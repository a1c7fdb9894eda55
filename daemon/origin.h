/* Which browser requests are taken: the Host names a daemon without a
 * token answers to (DNS rebinding: a page of evil.example whose name came
 * to resolve to 127.0.0.1 is same-origin with the API it reaches, and
 * reads it all; a listener on every interface answers on 127.0.0.1 too),
 * and writes from pages of other origins (CSRF: a text/plain POST needs
 * no preflight). Clients that are not browsers send no Origin (the write
 * check passes them); one that reaches a daemon without a token by a DNS
 * name needs that name in --allowed-hosts, as a browser does. */
#ifndef VX_ORIGIN_H
#define VX_ORIGIN_H

#include <microhttpd.h>

/* allowed: --allowed-hosts, a comma list of names ("*" = any, ".x.example"
 * or "*.x.example" = x.example and every name under it; "" = none beyond
 * the defaults);
 * check: Host names are checked without a list too (no token). The list
 * must outlive the server. Called once, before serving. */
void vx_origin_init(const char *allowed, int check);
/* 1 when the Host header host (NULL: none, HTTP/1.0) may be answered: any
 * when neither check nor a list is set, else an IPv4 or IPv6 address, a
 * name without a dot or '%' (a hosts-file or search-domain name: public
 * DNS, which a rebinding page needs, has none), localhost, a name under
 * .localhost, or one of the list. */
int vx_origin_host_ok(const char *host);
/* 1 when c's request, of method, is a write (any method but GET, HEAD,
 * OPTIONS) from a page of another origin that --cors-origin does not
 * allow: its Sec-Fetch-Site is same-site or cross-site, or without one
 * (plain HTTP to a name) its Origin's host and port are not the Host the
 * request came to nor the X-Forwarded-Host a proxy that rewrote it says
 * ("null" and schemes other than http and https included; the scheme
 * itself is not compared: a TLS proxy before this plain-HTTP server). */
int vx_origin_cross_site_write(struct MHD_Connection *c, const char *method);

#endif
