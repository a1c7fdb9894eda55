/* Probes (/livez, /readyz), /metrics, /v1/info and the data dir's free
 * space that /readyz and every write check. */
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "http_int.h"
#include "kinds.h"
#include "metrics.h"
#include "util/fsutil.h"

uint64_t vx_route_disk_free(vx_http *h)
{
    uint64_t b;
    return vx_disk_free(vx_store_dir(h->d.store), &b) == 0 ? b : UINT64_MAX;
}

int vx_route_disk_ok(vx_http *h, uint64_t *free_bytes)
{
    uint64_t b = vx_route_disk_free(h);
    if (free_bytes) *free_bytes = b;
    return h->d.cfg->min_free_disk ? b >= h->d.cfg->min_free_disk : b > 0;
}

int vx_route_livez(vx_http *h, struct MHD_Connection *c, req *r)
{
    double limit = h->d.cfg->gl_stall_timeout_s;
    if (limit > 0 && h->d.gl_alive_at) {
        double silent = vx_mono() - atomic_load(h->d.gl_alive_at);
        if (silent > limit) {
            static _Atomic double warned_at; /* one line a stall (and a minute) */
            double last = atomic_load(&warned_at);
            if (vx_mono() - last > 60 &&
                atomic_compare_exchange_strong(&warned_at, &last, vx_mono()))
                VX_ERROR("gl.stalled", "silent_s=%.1f limit_s=%g", silent, limit);
            return vx_resp_fail(c, r, VX_EUNAVAIL, "gl_stalled",
                                "the GL thread has not answered for %.0f s (over gl-stall-timeout "
                                "%g s): a driver call that does not return; restart the daemon",
                                silent, limit);
        }
    }
    return vx_resp_text(c, r, 200, strdup("{\"status\":\"ok\"}"), "application/json", NULL, NULL);
}

/* The GL info /v1/info and /metrics show: the refused software renderer's
 * under --require-gpu (the runner never started), else the runner's. */
static vx_gl_info shown_gl_info(vx_http *h)
{
    return h->d.gpu_refused ? *h->d.gpu_refused : vx_jobs_gl_info(h->d.jobs);
}

void vx_route_not_ready_reason(vx_http *h, char *out, size_t n)
{
    if (h->d.gpu_refused)
        snprintf(out, n,
                 "--require-gpu is set and the GL renderer \"%s\" is a software one: no job runs "
                 "here (is the GPU visible to EGL? NVIDIA needs NVIDIA_DRIVER_CAPABILITIES to "
                 "include graphics)",
                 h->d.gpu_refused->renderer);
    else if (h->stopping)
        snprintf(out, n, "the daemon is shutting down");
    else if (!vx_jobs_ready(h->d.jobs))
        snprintf(out, n, "the GL context is not up (starting, stopping or being rebuilt)");
    else
        snprintf(out, n, "the daemon is not ready");
}

/* What /readyz checks; ok is what it answers and /metrics' voxeld_ready. */
typedef struct {
    int gl, gpu, dd, journal, space, blob, db, cluster, ok;
} readiness;

static readiness ready_checks(vx_http *h)
{
    readiness k;
    k.gl = vx_jobs_ready(h->d.jobs);
    k.gpu = !h->d.gpu_refused;
    k.dd = vx_store_writable(h->d.store);
    k.journal = vx_jobs_state_intact(h->d.jobs);
    k.space = vx_route_disk_ok(h, NULL);
    k.blob = vx_store_reachable(h->d.store);
    vx_err dberr;
    vx_err_clear(&dberr);
    k.cluster = vx_jobs_cluster(h->d.jobs, NULL);
    k.db = vx_jobs_database_ok(h->d.jobs, &dberr);
    /* A full queue is backpressure (429 + Retry-After), not unreadiness. */
    k.ok = k.gl && k.gpu && k.dd && k.journal && k.space && k.blob && k.db && !h->stopping;
    return k;
}

int vx_route_readyz(vx_http *h, struct MHD_Connection *c, req *r)
{
    /* the database is asked for the queue only once it answered the
     * check (a lock held on the jobs table made /readyz wait out two
     * lock timeouts) */
    readiness k = ready_checks(h);
    size_t depth = k.db ? vx_jobs_queue_depth(h->d.jobs) : 0,
           cap = vx_jobs_queue_capacity(h->d.jobs);
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddStringToObject(doc, "status", k.ok ? "ready" : "not_ready");
    if (!k.ok) {
        char why[600];
        if (k.gl && k.gpu && !h->stopping)
            snprintf(why, sizeof why, "%s",
                     !k.dd ? "the data directory is not writable"
                     : !k.journal
                         ? "the job journal was removed or replaced in the data directory: new "
                           "jobs cannot be recorded; restart the daemon"
                     : !k.space && !h->d.cfg->min_free_disk ? "the data directory's disk is full"
                     : !k.space ? "the data directory has less free space than --min-free-disk"
                     : !k.blob  ? "the blob store (--blob-store) cannot be reached"
                                : "the database (--database) cannot be reached");
        else
            vx_route_not_ready_reason(h, why, sizeof why);
        cJSON_AddStringToObject(doc, "reason", why);
    }
    cJSON *q = cJSON_AddObjectToObject(doc, "queue");
    cJSON_AddNumberToObject(q, "depth", (double)depth);
    cJSON_AddNumberToObject(q, "capacity", (double)cap);
    cJSON_AddBoolToObject(q, "full", depth >= cap);
    cJSON *chk = cJSON_AddObjectToObject(doc, "checks");
    cJSON_AddBoolToObject(chk, "gl", k.gl);
    cJSON_AddBoolToObject(chk, "gpu", k.gpu);
    cJSON_AddBoolToObject(chk, "data_dir", k.dd);
    cJSON_AddBoolToObject(chk, "journal", k.journal);
    cJSON_AddBoolToObject(chk, "disk_space", k.space);
    cJSON *bs = cJSON_AddObjectToObject(doc, "blob_store");
    cJSON_AddStringToObject(bs, "backend", vx_store_backend(h->d.store));
    cJSON_AddBoolToObject(bs, "ok", k.blob);
    if (k.cluster) {
        cJSON *dbo = cJSON_AddObjectToObject(doc, "database");
        cJSON_AddBoolToObject(dbo, "ok", k.db);
        cJSON_AddStringToObject(dbo, "replica", vx_jobs_replica(h->d.jobs));
    }
    return vx_resp_json(c, r, k.ok ? 200 : 503, doc, NULL, NULL);
}

int vx_route_metrics(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_metrics_gauges g = {
        .queue_depth = vx_jobs_queue_depth(h->d.jobs),
        .queue_capacity = vx_jobs_queue_capacity(h->d.jobs),
        .running = vx_jobs_running(h->d.jobs),
        .meshes = vx_store_mesh_count(h->d.store),
        .results_bytes = vx_store_results_bytes(h->d.store),
        .disk_free_bytes = vx_route_disk_free(h),
        .min_free_disk = h->d.cfg->min_free_disk,
        .ready = ready_checks(h).ok,
        .gl = shown_gl_info(h),
        .start_time = h->d.start_time,
        .evictions = vx_store_results_evicted(h->d.store),
        .gl_context_loss = vx_jobs_gl_losses(h->d.jobs),
    };
    vx_pg_count *counts = NULL;
    if ((g.cluster = vx_jobs_cluster(h->d.jobs, &g.cs))) {
        vx_err err;
        if (vx_jobs_cluster_counts(h->d.jobs, &counts, &g.ncounts, &err)) g.ncounts = 0;
        g.counts = counts;
    }
    char *text = vx_metrics_render(&g);
    free(counts);
    return vx_resp_text(c, r, 200, text, "text/plain; version=0.0.4; charset=utf-8", NULL, NULL);
}

int vx_route_info(vx_http *h, struct MHD_Connection *c, req *r)
{
    const vx_config *cfg = h->d.cfg;
    vx_gl_info gi = shown_gl_info(h);
    cJSON *doc = cJSON_CreateObject();
    cJSON_AddStringToObject(doc, "name", "voxeld");
    cJSON_AddStringToObject(doc, "version", VX_VERSION);
    cJSON_AddNumberToObject(doc, "uptime_s", floor((vx_now() - h->d.start_time) * 1000) / 1000);
    cJSON *gl = cJSON_AddObjectToObject(doc, "gl");
    cJSON_AddStringToObject(gl, "vendor", gi.vendor);
    cJSON_AddStringToObject(gl, "renderer", gi.renderer);
    cJSON_AddStringToObject(gl, "version", gi.version);
    cJSON_AddStringToObject(gl, "glsl", gi.glsl);
    cJSON_AddStringToObject(gl, "device_kind", gi.device_kind[0] ? gi.device_kind : "surfaceless");
    cJSON_AddNumberToObject(gl, "device_index", gi.device_index);
    cJSON_AddBoolToObject(gl, "robust", gi.robust);
    cJSON *l = cJSON_AddObjectToObject(doc, "limits");
    cJSON_AddNumberToObject(l, "max_upload_bytes", (double)cfg->max_upload_bytes);
    cJSON_AddNumberToObject(l, "max_triangles", (double)cfg->max_triangles);
    cJSON_AddNumberToObject(l, "max_queued_jobs", (double)cfg->max_queued_jobs);
    cJSON_AddNumberToObject(l, "job_timeout_s", cfg->job_timeout_s);
    cJSON_AddNumberToObject(l, "max_wait_s", cfg->request_timeout_s);
    cJSON_AddNumberToObject(l, "request_timeout_s", cfg->request_timeout_s);
    cJSON_AddNumberToObject(l, "connection_timeout_s", cfg->connection_timeout_s);
    cJSON_AddNumberToObject(l, "header_timeout_s", cfg->header_timeout_s);
    cJSON_AddNumberToObject(l, "min_body_rate", (double)cfg->min_body_rate);
    cJSON_AddNumberToObject(l, "min_send_rate", (double)cfg->min_send_rate);
    cJSON_AddNumberToObject(l, "gl_stall_timeout_s", cfg->gl_stall_timeout_s);
    cJSON_AddNumberToObject(l, "max_uri_bytes", (double)cfg->max_uri_bytes);
    cJSON_AddNumberToObject(l, "max_header_bytes", (double)cfg->max_header_bytes);
    /* as in effect: lowered at start to what the descriptor limit leaves */
    cJSON_AddNumberToObject(l, "max_connections", (double)cfg->max_connections);
    cJSON_AddNumberToObject(l, "max_connections_per_ip", (double)cfg->max_connections_per_ip);
    cJSON_AddNumberToObject(l, "max_image_pixels", (double)cfg->max_image_pixels);
    cJSON_AddNumberToObject(l, "max_cc_valence", (double)cfg->max_cc_valence);
    cJSON_AddNumberToObject(l, "max_job_memory_bytes", (double)cfg->max_job_memory);
    cJSON_AddNumberToObject(l, "keep_memory_bytes", (double)cfg->keep_memory);
    cJSON_AddNumberToObject(l, "brick_threshold_cells", (double)cfg->brick_threshold);
    cJSON_AddNumberToObject(l, "max_json_bytes", (double)cfg->max_json_bytes);
    cJSON_AddNumberToObject(l, "min_free_disk_bytes", (double)cfg->min_free_disk);
    cJSON_AddNumberToObject(l, "max_parse_memory_bytes", (double)cfg->max_parse_memory);
    cJSON_AddNumberToObject(l, "results_max_bytes", (double)cfg->results_max_bytes);
    cJSON_AddNumberToObject(l, "results_max_age_s", cfg->results_max_age_s);
    cJSON_AddNumberToObject(l, "job_history", (double)cfg->job_history);
    cJSON_AddNumberToObject(l, "job_history_bytes", (double)cfg->job_history_bytes);
    cJSON_AddNumberToObject(l, "max_event_streams", (double)cfg->max_event_streams);
    cJSON_AddNumberToObject(l, "max_waits", (double)cfg->max_waits);
    cJSON_AddNumberToObject(l, "event_keepalive_s", cfg->event_keepalive_s);
    cJSON *kinds = cJSON_AddArrayToObject(doc, "kinds");
    for (size_t i = 0; i < vx_kind_count(); i++) {
        cJSON *k = cJSON_CreateObject();
        cJSON_AddStringToObject(k, "name", vx_kind_at(i)->name);
        cJSON_AddStringToObject(k, "summary", vx_kind_at(i)->summary);
        cJSON_AddItemToArray(kinds, k);
    }
    cJSON_AddBoolToObject(doc, "auth", h->auth.on);
    return vx_resp_json(c, r, 200, doc, NULL, NULL);
}

int vx_route_options(vx_http *h, struct MHD_Connection *c, req *r)
{
    (void)h;
    struct MHD_Response *resp =
        MHD_create_response_from_buffer(0, (void *)"", MHD_RESPMEM_PERSISTENT);
    if (!resp) return MHD_NO;
    const char *allow = vx_req_route_allow(r->route);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ALLOW, allow);
    if (vx_resp_cors_origin(c) &&
        vx_resp_header(c, MHD_HTTP_HEADER_ACCESS_CONTROL_REQUEST_METHOD)) {
        /* Allow-Origin and Vary come with every answer (vx_resp_queue). */
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_METHODS, allow);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_HEADERS,
                                "Authorization, Content-Type, Idempotency-Key, X-Request-Id, "
                                "Range, If-Range, If-None-Match, If-Match");
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_MAX_AGE, "600");
    }
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    return vx_resp_queue(c, r, 204, resp, 0);
}
