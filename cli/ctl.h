/* voxelctl: the command-line client of voxeld (docs/man/voxelctl.1).
 *
 * ctl_http.c talks HTTP through libcurl (requests, uploads, downloads and
 * the job event stream), ctl_local.c starts a private voxeld for --local,
 * ctl_cmds.c has the commands and voxelctl.c reads the command line. */
#ifndef VX_CTL_H
#define VX_CTL_H

#include <cjson/cJSON.h>
#include <stddef.h>
#include <stdio.h>

typedef struct ctl {
    char server[512];    /* base URL without a trailing slash */
    char token[512];     /* empty: no Authorization header */
    int json;            /* --json: machine-readable output on stdout */
    int quiet;           /* --quiet: no progress */
    int progress_tty;    /* stderr is a terminal: a progress bar */
    int quiet_transport; /* ctl_http: no message when no answer comes */
    int no_retry;        /* ctl_http: a 429 or 503 is returned, not tried again */
    char idem_key[40];   /* ctl_http: sent as Idempotency-Key when not empty */
} ctl;

/* A growing response body. */
typedef struct ctl_buf {
    char *p;
    size_t n, cap;
} ctl_buf;

/* ---- ctl_http.c ---- */
/* Sets up libcurl once; 0 or -1 (message printed). */
int ctl_http_init(void);
/* One request to c->server + path. The body is data (may be NULL) or the
 * file at upload (NULL: none), sent as ctype. The answer goes to resp
 * (NUL-terminated, caller frees resp->p) or, for a 2xx, to the file out
 * when out is not NULL. disp, if not NULL, gets the filename of the
 * Content-Disposition header ("" when none). A 429 or 503 with
 * Retry-After (queue full, busy, restarting: nothing was done) is sent
 * again after the seconds it says, for up to CTL_RETRY_FOR seconds in all
 * (said once on stderr unless quiet), unless c->no_retry. Returns the HTTP
 * status, or -1 when no answer came (message printed, unless
 * c->quiet_transport; the reason in ctl_http_error, and for a body that
 * could not be written to out, errno in ctl_http_write_errno, with no
 * message). With c->idem_key, a request whose answer was lost after it
 * was sent (the connection reset or closed, no byte for a minute) is sent
 * again with the same key, every 2 s for up to CTL_RETRY_FOR seconds,
 * and so is one the server's port refuses after that (restarting). */
#define CTL_RETRY_FOR 120
extern char ctl_http_error[256];
extern int ctl_http_write_errno;
long ctl_http(const ctl *c, const char *method, const char *path, const char *ctype,
              const char *data, const char *upload, ctl_buf *resp, FILE *out, char *disp,
              size_t dispn);
/* s (NULL: "") with its control characters (C0, DEL, C1 in UTF-8) as
 * '?' (the server's text on a terminal: an escape sequence could clear it
 * or retitle it), at most n - 1 bytes of it, in out. */
const char *ctl_printable(const char *s, char *out, size_t n);
/* Prints the server's error of a >= 400 answer (its JSON message and code)
 * to stderr, after what ("upload", "submit", ...). Returns 1. */
int ctl_http_fail(const char *what, long status, const ctl_buf *resp);
/* Follows GET /v1/jobs/{jid}/events, calling on_job with each event's Job
 * (borrowed) until the stream ends. Returns the last Job (owned) or NULL
 * when the stream could not be read (status in *status: 0 = transport). */
cJSON *ctl_http_events(const ctl *c, const char *jid, void (*on_job)(void *, const cJSON *),
                       void *ud, long *status);

/* ---- ctl_local.c ---- */
/* Starts a private voxeld (next to this program, $VOXELD_BIN or on PATH)
 * on 127.0.0.1 with a temporary data dir and points c at it. 0 or -1. */
int ctl_local_start(ctl *c);
/* Stops it and removes its data dir (also on SIGINT, SIGTERM, SIGHUP or
 * SIGQUIT, which then end the process). */
void ctl_local_stop(void);
/* 1 once a signal is stopping the private voxeld: the server going away is
 * then no news to report. */
int ctl_local_interrupted(void);

/* ---- ctl_cmds.c ---- */
/* A job command: KIND on the mesh file (or mesh id) src with params (owned),
 * the primary result written to out (NULL: the server's file name), or
 * the job only submitted with no_wait. Returns the exit status. */
int ctl_cmd_job(ctl *c, const char *kind, const char *src, cJSON *params, const char *out,
                int no_wait);
/* `jobs`, `meshes`, `get`, `cancel`, `upload`. Return the exit status. */
int ctl_cmd_jobs(ctl *c, const char *state, int newest, int limit, const char *after);
int ctl_cmd_meshes(ctl *c, int limit, const char *after);
/* Shows job jid, or with out or name follows it to its end first, as a job
 * command does, and downloads output name (NULL: the primary output, every
 * frame of a turntable). */
int ctl_cmd_get(ctl *c, const char *jid, const char *name, const char *out);
int ctl_cmd_cancel(ctl *c, const char *jid);
/* Deletes a job: cancels it when unfinished, else removes it and its results. */
int ctl_cmd_delete(ctl *c, const char *jid);
int ctl_cmd_upload(ctl *c, const char *file);
/* Whether -o out cannot be written (said on stderr), checked before a job
 * is submitted rather than after it ran: a part file is made where the
 * result would go (through symlinks) and removed. "-" is stdout. */
int ctl_out_unwritable(const char *out);
/* The same for a result written without -o: under the server's file name
 * in the current directory. */
int ctl_cwd_unwritable(void);
/* Removes the part file being written and the spooled upload, if any
 * (async-signal-safe: for a signal that ends the process). */
void ctl_cmds_remove_temp(void);

#endif
