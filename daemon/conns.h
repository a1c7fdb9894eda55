/* Connection tracking against slow clients (conns.c, at the top, has the
 * whole story): every connection from accept to close in one of four
 * phases (head arriving, body arriving, busy, idle keep-alive) and a
 * sweeper thread that answers heads and bodies that arrive too slowly with
 * a JSON 408, and evicts the oldest idle or head-sending connections when
 * the connection limit comes near. */
#ifndef VX_CONNS_H
#define VX_CONNS_H

#include <microhttpd.h>
#include <stddef.h>

#include "config.h"

typedef struct vx_conns vx_conns;
typedef struct vx_conn vx_conn;

/* What a browser script on an allowed origin may read of an answer (the
 * handlers' and the canned ones written here). */
#define VX_CORS_EXPOSE                                                                             \
    "Location, ETag, Retry-After, X-Request-Id, Content-Range, Content-Encoding, "                 \
    "Content-Disposition, Accept-Ranges, WWW-Authenticate, Allow"

/* Starts the sweeper for the limits of cfg (kept). Owned; NULL without memory. */
vx_conns *vx_conns_start(const vx_config *cfg);
/* Stops the sweeper (before libmicrohttpd stops: it writes to sockets). */
void vx_conns_stop(vx_conns *s);
/* The server is stopping: answers every connection whose request head or
 * body is still arriving with a JSON 503 shutting_down (Retry-After: 1).
 * Returns how many were answered (their clients need a moment to read it
 * before libmicrohttpd closes the sockets). */
int vx_conns_shutdown(vx_conns *s);
/* The open connections that are not idle between requests (a head or body
 * arriving, an answer being made or sent): what a stop waits for. */
size_t vx_conns_pending(vx_conns *s);
/* Of those, the ones being answered (the answer made or sent, a result
 * downloading): what a stop lets finish after the requests' grace. */
size_t vx_conns_answering(vx_conns *s);
/* Stops the sweeper if running and frees s (after libmicrohttpd has
 * stopped: its close notifications use s). */
void vx_conns_free(vx_conns *s);
/* MHD_OPTION_NOTIFY_CONNECTION callback (cls: the vx_conns): tracks a
 * connection from accept, forgets it at close. */
void vx_conns_notify(void *cls, struct MHD_Connection *c, void **socket_context,
                     enum MHD_ConnectionNotificationCode code);
/* MHD_OPTION_URI_LOG_CALLBACK (cls: the vx_conns): a request target over
 * max_uri_bytes gets a JSON 414. Returns NULL (no request context). */
void *vx_conns_on_uri(void *cls, const char *uri, struct MHD_Connection *c);
/* 1 when the current request's path (before '?') had %00 or %2F, which
 * libmicrohttpd decoded into a NUL or a separator: such a path names no
 * resource (404). */
int vx_conns_path_escape(const vx_conn *vc);
/* 1 when the client of a held answer (a ?wait hold, an event stream
 * between events: suspended connections, which libmicrohttpd does not
 * watch) has closed or reset its connection: nothing unread and EOF, or a
 * socket error. Any thread. */
int vx_conns_peer_gone(struct MHD_Connection *c);
/* 1 when vc was opened while its client already had --max-connections-per-ip
 * open: its request is answered 503 too_many_connections and the
 * connection closed (libmicrohttpd's own limit closed it unanswered). */
int vx_conns_over_ip(const vx_conn *vc);
/* 1 when the current request's target had a raw space or control
 * character (libmicrohttpd takes "GET /a b HTTP/1.1" as path "/a b"). */
int vx_conns_target_bad(const vx_conn *vc);
/* 1 when a NUL cut the request line's method or target short: libmicrohttpd
 * (0.9.75) cuts the line in its buffer at its two spaces, so the target
 * starts one byte after the method's end and the version one after the
 * target's ("GET /livez\0junk HTTP/1.1" was /livez); 0 otherwise or when
 * the buffer is not read (vx_mhd_in_place). */
int vx_conns_line_cut(const vx_conn *vc, const char *method, const char *version);
/* 1 when the running libmicrohttpd parses a head in place in its buffer as
 * 0.9.75 does (http.c reads that buffer around the fields it gives, and
 * vx_conns_line_cut compares where the request line's parts lie in it, to
 * find what it hid: folded lines, NULs, empty field names); 0 for another
 * version, whose buffer may be laid out otherwise (not read then). */
int vx_mhd_in_place(void);
/* The tracked connection of c, or NULL when untracked. */
vx_conn *vx_conns_of(struct MHD_Connection *c);

/* The functions below take vc NULL (untracked) as a no-op. */
/* The head is in: vc is busy. 1 when the sweeper has already answered it
 * (then nothing may be queued on it). */
int vx_conns_head_in(vx_conns *s, vx_conn *vc);
/* A body follows: its arrival rate is watched from now; a 408 (or 503)
 * for it carries the request's id rid and, when CORS allows the request's
 * origin, that origin (NULL: none). */
void vx_conns_body_begins(vx_conns *s, vx_conn *vc, const char *rid, const char *origin);
/* n bytes of the body came (n 0: the body is complete, vc is busy). 1 when
 * the sweeper has answered vc (drain, never queue). */
int vx_conns_body(vx_conns *s, vx_conn *vc, size_t n);
/* An answer was queued before the request's body was read: libmicrohttpd
 * will close the connection after it, and the socket is then kept open
 * and its body read and dropped (up to 5 s, until the client closes or
 * nothing comes for 1 s) so
 * that the close does not reset the connection before the client has read
 * the answer. */
void vx_conns_linger(vx_conns *s, vx_conn *vc);
/* The body arriving on vc is refused: a JSON error answer (status 413,
 * 507 or 500, code, message: escaped here) is written to the socket now,
 * as the sweeper's 408s are, and the rest of the body is dropped until the
 * read side is closed half a second later (vx_conns_body then says 1). */
void vx_conns_refuse(vx_conns *s, vx_conn *vc, int status, const char *code, const char *message);
/* The answer sends the file open as fd as it is, up to byte need: should
 * the file be cut shorter meanwhile (truncated behind the daemon), the
 * sweeper closes the connection (libmicrohttpd would wait for the missing
 * bytes until --connection-timeout). Until vx_conns_done (a copy of fd is
 * kept till then). */
void vx_conns_watch_file(vx_conns *s, vx_conn *vc, int fd, uint64_t need);
/* The request is over: vc idles until the next head. Returns the status the
 * sweeper answered vc with, 0 when it did not. */
int vx_conns_done(vx_conns *s, vx_conn *vc);
/* libmicrohttpd's idle timeout is off on vc's connection (on 1) or back
 * (0): while off the sweeper closes the connection once it is idle between
 * requests for --connection-timeout, counted from when the kernel holds no
 * byte of the last answer and no byte of a next request has come. */
void vx_conns_own_idle(vx_conn *vc, int on);
int vx_conns_owns_idle(const vx_conn *vc);

#endif
