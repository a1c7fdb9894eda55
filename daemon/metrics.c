#include "metrics.h"

#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>
#include <dirent.h>

#include "util/bigmem.h"

#define NBUCKETS 16
typedef struct buckets {
    int n;
    double le[NBUCKETS];
} buckets;
static const buckets req_buckets = {
    14, {0.001, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60}};
/* Job durations: these, cut at the job timeout, which is the last bucket. */
static const double job_le[] = {0.01, 0.05, 0.1, 0.25, 0.5, 1,   2.5, 5,
                                10,   30,   60,  120,  300, 600, 1800};
static buckets job_buckets;
static const buckets wait_buckets = {
    14, {0.001, 0.005, 0.01, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 300}};

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

/* Rows of voxeld_http_requests_total: every route x method label x status
 * the daemon answers is at most 17 x 8 x ~50; the table grows to that. A
 * fixed 256 rows were full after one pass of a scanner (every route with
 * every method, with and without a token), after which no new series, a
 * first 201 or 500 included, was ever counted. */
#define MAXROWS 8192
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static req_counter *g_req;
static size_t g_nreq, g_capreq;
static hist g_req_hist[32];
static size_t g_nreq_hist;
static job_counter g_job[64];
static size_t g_njob;
static hist g_job_hist[32];
static size_t g_njob_hist;
static uint64_t g_bytes_in, g_bytes_out;

typedef struct fail_counter {
    char kind[32], code[48];
    uint64_t n;
} fail_counter;
/* kind x error code: ~100 codes exist in all, a kind meets a share of them */
#define MAXFAIL 512
static fail_counter g_fail[MAXFAIL];
static size_t g_nfail;
static hist g_wait[1];
static size_t g_nwait;

void vx_metrics_init(double job_timeout_s)
{
    double t = job_timeout_s > 0 ? job_timeout_s : 600;
    int n = 0;
    for (size_t i = 0; i < sizeof job_le / sizeof job_le[0] && n < NBUCKETS - 1; i++)
        if (job_le[i] < t) job_buckets.le[n++] = job_le[i];
    job_buckets.le[n++] = t;
    job_buckets.n = n;
}

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

static void hist_add(hist *h, const buckets *b, double v)
{
    if (!h) return;
    for (int i = 0; i < b->n; i++)
        if (v <= b->le[i]) h->counts[i]++;
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
    if (i == g_nreq && g_nreq == g_capreq && g_capreq < MAXROWS) {
        size_t cap = g_capreq ? 2 * g_capreq : 256;
        req_counter *np = realloc(g_req, cap * sizeof *np);
        if (np) {
            g_req = np;
            g_capreq = cap;
        }
    }
    if (i == g_nreq && g_nreq < g_capreq) {
        snprintf(g_req[i].route, sizeof g_req[i].route, "%s", route);
        snprintf(g_req[i].method, sizeof g_req[i].method, "%s", method);
        g_req[i].status = status;
        g_req[i].n = 0;
        g_nreq++;
    }
    if (i < g_nreq) g_req[i].n++;
    hist_add(hist_get(g_req_hist, &g_nreq_hist, 32, route), &req_buckets, seconds);
    g_bytes_in += bytes_in;
    g_bytes_out += bytes_out;
    pthread_mutex_unlock(&g_lock);
}

void vx_metrics_job(const char *kind, const char *state, double run_s, double queue_s,
                    const char *code)
{
    if (!job_buckets.n) vx_metrics_init(0);
    pthread_mutex_lock(&g_lock);
    if (code) {
        size_t k;
        for (k = 0; k < g_nfail; k++)
            if (!strcmp(g_fail[k].kind, kind) && !strcmp(g_fail[k].code, code)) break;
        if (k == g_nfail && g_nfail < MAXFAIL) {
            snprintf(g_fail[k].kind, sizeof g_fail[k].kind, "%s", kind);
            snprintf(g_fail[k].code, sizeof g_fail[k].code, "%s", code);
            g_fail[k].n = 0;
            g_nfail++;
        }
        if (k < g_nfail) g_fail[k].n++;
    }
    if (queue_s >= 0) hist_add(hist_get(g_wait, &g_nwait, 1, "all"), &wait_buckets, queue_s);
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
    if (run_s >= 0) hist_add(hist_get(g_job_hist, &g_njob_hist, 32, kind), &job_buckets, run_s);
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
                        const buckets *bk)
{
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < bk->n; k++)
            sb_printf(b, "%s_bucket{%s=\"%s\",le=\"%g\"} %llu\n", name, label, h[i].label,
                      bk->le[k], (unsigned long long)h[i].counts[k]);
        sb_printf(b, "%s_bucket{%s=\"%s\",le=\"+Inf\"} %llu\n", name, label, h[i].label,
                  (unsigned long long)h[i].n);
        sb_printf(b, "%s_sum{%s=\"%s\"} %.6f\n", name, label, h[i].label, h[i].sum);
        sb_printf(b, "%s_count{%s=\"%s\"} %llu\n", name, label, h[i].label,
                  (unsigned long long)h[i].n);
    }
}

/* The standard process_* family, from /proc/self and the rlimits. */
static void process_render(sbuf *b, double start_time)
{
    long page = sysconf(_SC_PAGESIZE);
    unsigned long long vsz = 0, rss = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    if (f) {
        if (fscanf(f, "%llu %llu", &vsz, &rss) != 2) vsz = rss = 0;
        fclose(f);
    }
    struct rusage ru;
    double cpu = 0;
    if (getrusage(RUSAGE_SELF, &ru) == 0)
        cpu = (double)ru.ru_utime.tv_sec + ru.ru_utime.tv_usec / 1e6 + (double)ru.ru_stime.tv_sec +
              ru.ru_stime.tv_usec / 1e6;
    long fds = 0;
    DIR *d = opendir("/proc/self/fd");
    if (d) {
        struct dirent *e;
        while ((e = readdir(d)))
            fds += e->d_name[0] != '.';
        closedir(d);
        fds--; /* the directory's own fd */
    }
    struct rlimit rl;
    double maxfds = getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY
                        ? (double)rl.rlim_cur
                        : -1;
    sb_printf(b,
              "# HELP process_cpu_seconds_total User and system CPU time spent, in seconds.\n"
              "# TYPE process_cpu_seconds_total counter\nprocess_cpu_seconds_total %.3f\n"
              "# HELP process_resident_memory_bytes Resident memory size in bytes.\n"
              "# TYPE process_resident_memory_bytes gauge\nprocess_resident_memory_bytes %llu\n"
              "# HELP process_virtual_memory_bytes Virtual memory size in bytes.\n"
              "# TYPE process_virtual_memory_bytes gauge\nprocess_virtual_memory_bytes %llu\n"
              "# HELP process_open_fds Open file descriptors.\n"
              "# TYPE process_open_fds gauge\nprocess_open_fds %ld\n"
              "# HELP process_max_fds Most open file descriptors allowed (RLIMIT_NOFILE).\n"
              "# TYPE process_max_fds gauge\nprocess_max_fds %.0f\n"
              "# HELP process_start_time_seconds Start time of the process since the epoch.\n"
              "# TYPE process_start_time_seconds gauge\nprocess_start_time_seconds %.3f\n",
              cpu, rss * (unsigned long long)page, vsz * (unsigned long long)page, fds, maxfds,
              start_time);
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
                &req_buckets);
    sb_printf(&b,
              "# HELP voxeld_http_bytes_received_total Request body bytes received.\n"
              "# TYPE voxeld_http_bytes_received_total counter\n"
              "voxeld_http_bytes_received_total %llu\n"
              "# HELP voxeld_http_bytes_sent_total Response body bytes sent (of an answer cut "
              "short, the bytes the client acknowledged, its head included).\n"
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
    if (!job_buckets.n) vx_metrics_init(0);
    hist_render(&b, "voxeld_job_duration_seconds", "kind", g_job_hist, g_njob_hist, &job_buckets);
    sb_printf(&b, "# HELP voxeld_jobs_failed_total Failed jobs, by kind and error code.\n"
                  "# TYPE voxeld_jobs_failed_total counter\n");
    for (size_t i = 0; i < g_nfail; i++)
        sb_printf(&b, "voxeld_jobs_failed_total{kind=\"%s\",code=\"%s\"} %llu\n", g_fail[i].kind,
                  g_fail[i].code, (unsigned long long)g_fail[i].n);
    sb_printf(&b, "# HELP voxeld_job_queue_wait_seconds Time jobs that ran waited in the queue "
                  "(created to started).\n"
                  "# TYPE voxeld_job_queue_wait_seconds histogram\n");
    if (g_nwait) {
        /* One series, no label. */
        const hist *w = &g_wait[0];
        for (int k = 0; k < wait_buckets.n; k++)
            sb_printf(&b, "voxeld_job_queue_wait_seconds_bucket{le=\"%g\"} %llu\n",
                      wait_buckets.le[k], (unsigned long long)w->counts[k]);
        sb_printf(&b,
                  "voxeld_job_queue_wait_seconds_bucket{le=\"+Inf\"} %llu\n"
                  "voxeld_job_queue_wait_seconds_sum %.6f\n"
                  "voxeld_job_queue_wait_seconds_count %llu\n",
                  (unsigned long long)w->n, w->sum, (unsigned long long)w->n);
    }
    pthread_mutex_unlock(&g_lock);

    /* UINT64_MAX: statvfs failed (the data dir removed): unknown, not 16 EiB */
    char free_s[32] = "NaN";
    if (g->disk_free_bytes != UINT64_MAX)
        snprintf(free_s, sizeof free_s, "%llu", (unsigned long long)g->disk_free_bytes);
    sb_printf(
        &b,
        "# HELP voxeld_queue_depth Jobs waiting for the GL thread.\n# TYPE voxeld_queue_depth "
        "gauge\n"
        "voxeld_queue_depth %zu\n"
        "# HELP voxeld_queue_capacity Jobs that may wait before requests get 429.\n"
        "# TYPE voxeld_queue_capacity gauge\nvoxeld_queue_capacity %zu\n"
        "# HELP voxeld_jobs_running Jobs running now.\n# TYPE voxeld_jobs_running gauge\n"
        "voxeld_jobs_running %zu\n"
        "# HELP voxeld_meshes Meshes in the store (cluster mode: the mesh catalog, every "
        "replica's).\n# TYPE voxeld_meshes gauge\nvoxeld_meshes %zu\n"
        "# HELP voxeld_results_bytes Bytes of job results on disk.\n"
        "# TYPE voxeld_results_bytes gauge\nvoxeld_results_bytes %llu\n"
        "# HELP voxeld_data_dir_free_bytes Bytes still free for the data dir.\n"
        "# TYPE voxeld_data_dir_free_bytes gauge\nvoxeld_data_dir_free_bytes %s\n"
        "# HELP voxeld_data_dir_min_free_bytes Free-space floor: below it writes answer 507.\n"
        "# TYPE voxeld_data_dir_min_free_bytes gauge\nvoxeld_data_dir_min_free_bytes %llu\n"
        "# HELP voxeld_ready 1 when ready to run jobs (what /readyz answers 200 for).\n# TYPE "
        "voxeld_ready gauge\n"
        "voxeld_ready %d\n"
        "# HELP voxeld_results_evicted_total Job results removed by the results budget.\n"
        "# TYPE voxeld_results_evicted_total counter\nvoxeld_results_evicted_total %llu\n"
        "# HELP voxeld_gl_context_losses_total GL contexts lost during a job.\n"
        "# TYPE voxeld_gl_context_losses_total counter\nvoxeld_gl_context_losses_total %llu\n"
        "# HELP voxeld_kept_memory_bytes Big job buffers freed and kept mapped for the next "
        "job (keep-memory).\n"
        "# TYPE voxeld_kept_memory_bytes gauge\nvoxeld_kept_memory_bytes %zu\n",
        g->queue_depth, g->queue_capacity, g->running, g->meshes,
        (unsigned long long)g->results_bytes, free_s, (unsigned long long)g->min_free_disk,
        g->ready, (unsigned long long)g->evictions, (unsigned long long)g->gl_context_loss,
        vx_bigmem_kept());
    if (g->cluster) {
        sb_printf(&b, "# HELP voxeld_cluster_jobs Jobs in the shared database by state and kind "
                      "(every replica's: the autoscaler's view).\n"
                      "# TYPE voxeld_cluster_jobs gauge\n");
        for (size_t i = 0; i < g->ncounts; i++)
            sb_printf(&b, "voxeld_cluster_jobs{state=\"%s\",kind=\"%s\"} %ld\n", g->counts[i].state,
                      g->counts[i].kind, g->counts[i].n);
        sb_printf(
            &b,
            "# HELP voxeld_cluster_claims_total Jobs this replica claimed.\n"
            "# TYPE voxeld_cluster_claims_total counter\nvoxeld_cluster_claims_total %llu\n"
            "# HELP voxeld_cluster_lease_losses_total Runs stopped here because their lease "
            "moved on.\n"
            "# TYPE voxeld_cluster_lease_losses_total counter\n"
            "voxeld_cluster_lease_losses_total %llu\n"
            "# HELP voxeld_cluster_stale_completions_total Results of this replica another "
            "attempt had already won.\n"
            "# TYPE voxeld_cluster_stale_completions_total counter\n"
            "voxeld_cluster_stale_completions_total %llu\n"
            "# HELP voxeld_cluster_retries_total Failed attempts here handed back for another "
            "try.\n"
            "# TYPE voxeld_cluster_retries_total counter\nvoxeld_cluster_retries_total %llu\n"
            "# HELP voxeld_cluster_requeued_expired_total Expired leases (any replica's) this "
            "replica re-queued.\n"
            "# TYPE voxeld_cluster_requeued_expired_total counter\n"
            "voxeld_cluster_requeued_expired_total %llu\n",
            (unsigned long long)g->cs.claims, (unsigned long long)g->cs.lease_losses,
            (unsigned long long)g->cs.stale_completions, (unsigned long long)g->cs.retries,
            (unsigned long long)g->cs.requeued_expired);
    }
    process_render(&b, g->start_time);
    sb_printf(&b,
              "# HELP voxeld_info Build and GL context information.\n# TYPE voxeld_info gauge\n"
              "voxeld_info{version=\"%s\",gl_vendor=\"%s\",gl_renderer=\"%s\",gl_version=\"%s\","
              "device_kind=\"%s\"} 1\n",
              VX_VERSION, esc(e1, sizeof e1, g->gl.vendor), esc(e2, sizeof e2, g->gl.renderer),
              esc(e3, sizeof e3, g->gl.version), g->gl.device_kind);
    return b.p;
}
