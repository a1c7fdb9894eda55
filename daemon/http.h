/* The HTTP/JSON API (api/openapi.yaml) on libmicrohttpd: a thread pool with
 * epoll, uploads streamed to the store, ?wait held by suspending the
 * connection. HTTP threads never touch GL. */
#ifndef VX_HTTP_H
#define VX_HTTP_H

#include "config.h"
#include "jobs/jobs.h"
#include "store/store.h"

typedef struct vx_http vx_http;

typedef struct vx_http_desc {
    const vx_config *cfg;
    vx_store *store;
    vx_jobs *jobs;
    double start_time;
    /* Non-NULL: --require-gpu found this software renderer, the job runner
     * was not started, /readyz answers 503 naming it. Not owned. */
    const vx_gl_info *gpu_refused;
    /* Non-NULL: when the GL thread last said it was alive (vx_mono, set
     * by it about once a second); /livez answers 503 gl_stalled past
     * --gl-stall-timeout. NULL (no GL thread): not checked. Not owned. */
    const _Atomic double *gl_alive_at;
} vx_http_desc;

/* Whether cfg->listen can be bound as vx_http_start will bind it (the host
 * resolves, the port is free or --reuse-port shares it), by binding a
 * socket and closing it: 0, or -1 (err: bad_listen, listen_failed). Run
 * before the store, the journal and the GL context, so that a port in use
 * fails at once instead of after a start that may already run jobs. */
int vx_http_check_listen(const vx_config *cfg, vx_err *err);
/* Binds and starts serving. Owned; stop with vx_http_stop. */
vx_http *vx_http_start(const vx_http_desc *desc, vx_err *err);
/* The port actually bound (useful with port 0). */
int vx_http_port(vx_http *h);
/* The jobs hook: wakes requests waiting on jid once it has finished. */
void vx_http_job_changed(vx_http *h, const char *jid, int terminal);
/* Stops accepting connections and answers every held request now. */
void vx_http_quiesce(vx_http *h);
/* Waits up to grace_s for requests arriving (then answers them 503) and
 * up to answers_s (0 = as long as they take) for answers being sent, then
 * stops and frees. */
void vx_http_stop(vx_http *h, double grace_s, double answers_s);

#endif
