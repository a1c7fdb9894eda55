#include "metrics.h"

#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NBUCKETS 12
static const double req_buckets[NBUCKETS] = {0.001, 0.0025, 0.005, 0.01, 0.025, 0.05,
                                             0.1,   0.25,   0.5,   1,    2.5,   10};
static const double job_buckets[NBUCKETS] = {0.01, 0.025, 0.05, 0.1, 0.25, 0.5,
                                             1,    2.5,   5,    10,  30,   120};

typedef struct hist {
    char label[64];
    uint64_t counts[NBUCKETS];
    uint64_t n;
    double sum;
} hist;

typedef struct req_counter {
    char route[48], method[12];
    int status;
    uint64_t n;
} req_counter;

typedef struct job_counter {
    char kind[32], state[16];
    uint64_t n;
} job_counter;

#define MAXROWS 256
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static req_counter g_req[MAXROWS];
static size_t g_nreq;
static hist g_req_hist[32];
static size_t g_nreq_hist;
static job_counter g_job[64];
static size_t g_njob;
static hist g_job_hist[32];
static size_t g_njob_hist;
static uint64_t g_bytes_in, g_bytes_out;

static hist *hist_get(hist *h, size_t *n, size_t max, const char *label)
{
    for (size_t i = 0; i < *n; i++)
        if (strcmp(h[i].label, label) == 0) return &h[i];
    if (*n == max) return NULL;
    hist *x = &h[(*n)++];
    memset(x, 0, sizeof *x);
    snprintf(x->label, sizeof x->label, "%s", label);
    return x;
}

static void hist_add(hist *h, const double *buckets, double v)
{
    if (!h) return;
    for (int i = 0; i < NBUCKETS; i++)
        if (v <= buckets[i]) h->counts[i]++;
    h->n++;
    h->sum += v;
}

void vx_metrics_request(const char *route, const char *method, int status, double seconds,
                        uint64_t bytes_in, uint64_t bytes_out)
{
    pthread_mutex_lock(&g_lock);
    size_t i;
    for (i = 0; i < g_nreq; i++)
        if (g_req[i].status == status && !strcmp(g_req[i].route, route) &&
            !strcmp(g_req[i].method, method))
            break;
    if (i == g_nreq && g_nreq < MAXROWS) {
        snprintf(g_req[i].route, sizeof g_req[i].route, "%s", route);
        snprintf(g_req[i].method, sizeof g_req[i].method, "%s", method);
        g_req[i].status = status;
        g_req[i].n = 0;
        g_nreq++;
    }
    if (i < g_nreq) g_req[i].n++;
    hist_add(hist_get(g_req_hist, &g_nreq_hist, 32, route), req_buckets, seconds);
    g_bytes_in += bytes_in;
    g_bytes_out += bytes_out;
    pthread_mutex_unlock(&g_lock);
}

void vx_metrics_job(const char *kind, const char *state, double run_s)
{
    pthread_mutex_lock(&g_lock);
    size_t i;
    for (i = 0; i < g_njob; i++)
        if (!strcmp(g_job[i].kind, kind) && !strcmp(g_job[i].state, state)) break;
    if (i == g_njob && g_njob < 64) {
        snprintf(g_job[i].kind, sizeof g_job[i].kind, "%s", kind);
        snprintf(g_job[i].state, sizeof g_job[i].state, "%s", state);
        g_job[i].n = 0;
        g_njob++;
    }
    if (i < g_njob) g_job[i].n++;
    if (run_s >= 0) hist_add(hist_get(g_job_hist, &g_njob_hist, 32, kind), job_buckets, run_s);
    pthread_mutex_unlock(&g_lock);
}

typedef struct sbuf {
    char *p;
    size_t n, cap;
} sbuf;

static void sb_printf(sbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_printf(sbuf *b, const char *fmt, ...)
{
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        int k = vsnprintf(b->p ? b->p + b->n : NULL, b->p ? b->cap - b->n : 0, fmt, ap);
        va_end(ap);
        if (k < 0) return;
        if (b->p && b->n + (size_t)k < b->cap) {
            b->n += (size_t)k;
            return;
        }
        size_t cap = (b->cap ? b->cap * 2 : 8192) + (size_t)k;
        char *np = realloc(b->p, cap);
        if (!np) return;
        b->p = np;
        b->cap = cap;
    }
}

/* Label values escape backslash, quote and newline. */
static const char *esc(char *buf, size_t n, const char *s)
{
    size_t o = 0;
    for (; *s && o + 2 < n; s++) {
        if (*s == '\\' || *s == '"') buf[o++] = '\\';
        if (*s == '\n') {
            buf[o++] = '\\';
            buf[o++] = 'n';
            continue;
        }
        buf[o++] = *s;
    }
    buf[o] = 0;
    return buf;
}

static void hist_render(sbuf *b, const char *name, const char *label, const hist *h, size_t n,
                        const double *buckets)
{
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < NBUCKETS; k++)
            sb_printf(b, "%s_bucket{%s=\"%s\",le=\"%g\"} %llu\n", name, label, h[i].label,
                      buckets[k], (unsigned long long)h[i].counts[k]);
        sb_printf(b, "%s_bucket{%s=\"%s\",le=\"+Inf\"} %llu\n", name, label, h[i].label,
                  (unsigned long long)h[i].n);
        sb_printf(b, "%s_sum{%s=\"%s\"} %.6f\n", name, label, h[i].label, h[i].sum);
        sb_printf(b, "%s_count{%s=\"%s\"} %llu\n", name, label, h[i].label,
                  (unsigned long long)h[i].n);
    }
}

char *vx_metrics_render(const vx_metrics_gauges *g)
{
    sbuf b = {0};
    char e1[300], e2[300], e3[300];
    pthread_mutex_lock(&g_lock);
    sb_printf(
        &b,
        "# HELP voxeld_http_requests_total HTTP requests answered, by route, method and status.\n"
        "# TYPE voxeld_http_requests_total counter\n");
    for (size_t i = 0; i < g_nreq; i++)
        sb_printf(&b, "voxeld_http_requests_total{route=\"%s\",method=\"%s\",status=\"%d\"} %llu\n",
                  g_req[i].route, g_req[i].method, g_req[i].status, (unsigned long long)g_req[i].n);
    sb_printf(&b, "# HELP voxeld_http_request_duration_seconds Time from request headers to the "
                  "end of the response.\n"
                  "# TYPE voxeld_http_request_duration_seconds histogram\n");
    hist_render(&b, "voxeld_http_request_duration_seconds", "route", g_req_hist, g_nreq_hist,
                req_buckets);
    sb_printf(&b,
              "# HELP voxeld_http_bytes_received_total Request body bytes received.\n"
              "# TYPE voxeld_http_bytes_received_total counter\n"
              "voxeld_http_bytes_received_total %llu\n"
              "# HELP voxeld_http_bytes_sent_total Response body bytes sent.\n"
              "# TYPE voxeld_http_bytes_sent_total counter\n"
              "voxeld_http_bytes_sent_total %llu\n",
              (unsigned long long)g_bytes_in, (unsigned long long)g_bytes_out);
    sb_printf(&b, "# HELP voxeld_jobs_total Jobs that reached a final state, by kind and state.\n"
                  "# TYPE voxeld_jobs_total counter\n");
    for (size_t i = 0; i < g_njob; i++)
        sb_printf(&b, "voxeld_jobs_total{kind=\"%s\",state=\"%s\"} %llu\n", g_job[i].kind,
                  g_job[i].state, (unsigned long long)g_job[i].n);
    sb_printf(&b, "# HELP voxeld_job_duration_seconds Run time of jobs that ran, by kind.\n"
                  "# TYPE voxeld_job_duration_seconds histogram\n");
    hist_render(&b, "voxeld_job_duration_seconds", "kind", g_job_hist, g_njob_hist, job_buckets);
    pthread_mutex_unlock(&g_lock);

    sb_printf(
        &b,
        "# HELP voxeld_queue_depth Jobs waiting for the GL thread.\n# TYPE voxeld_queue_depth "
        "gauge\n"
        "voxeld_queue_depth %zu\n"
        "# HELP voxeld_queue_capacity Jobs that may wait before requests get 429.\n"
        "# TYPE voxeld_queue_capacity gauge\nvoxeld_queue_capacity %zu\n"
        "# HELP voxeld_jobs_running Jobs running now.\n# TYPE voxeld_jobs_running gauge\n"
        "voxeld_jobs_running %zu\n"
        "# HELP voxeld_meshes Meshes in the store.\n# TYPE voxeld_meshes gauge\nvoxeld_meshes %zu\n"
        "# HELP voxeld_results_bytes Bytes of job results on disk.\n"
        "# TYPE voxeld_results_bytes gauge\nvoxeld_results_bytes %llu\n"
        "# HELP voxeld_data_dir_free_bytes Bytes still free for the data dir.\n"
        "# TYPE voxeld_data_dir_free_bytes gauge\nvoxeld_data_dir_free_bytes %llu\n"
        "# HELP voxeld_data_dir_min_free_bytes Free-space floor: below it writes answer 507.\n"
        "# TYPE voxeld_data_dir_min_free_bytes gauge\nvoxeld_data_dir_min_free_bytes %llu\n"
        "# HELP voxeld_up 1 when ready to run jobs.\n# TYPE voxeld_up gauge\nvoxeld_up %d\n"
        "# HELP process_start_time_seconds Start time of the process since the epoch.\n"
        "# TYPE process_start_time_seconds gauge\nprocess_start_time_seconds %.3f\n",
        g->queue_depth, g->queue_capacity, g->running, g->meshes,
        (unsigned long long)g->results_bytes, (unsigned long long)g->disk_free_bytes,
        (unsigned long long)g->min_free_disk, g->ready, g->start_time);
    sb_printf(&b,
              "# HELP voxeld_info Build and GL context information.\n# TYPE voxeld_info gauge\n"
              "voxeld_info{version=\"%s\",gl_vendor=\"%s\",gl_renderer=\"%s\",gl_version=\"%s\","
              "device_kind=\"%s\"} 1\n",
              VX_VERSION, esc(e1, sizeof e1, g->gl.vendor), esc(e2, sizeof e2, g->gl.renderer),
              esc(e3, sizeof e3, g->gl.version), g->gl.device_kind);
    return b.p;
}
