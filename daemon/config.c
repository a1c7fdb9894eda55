#include "config.h"

#include <ctype.h>
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <sched.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "util/fsutil.h"
#include "util/log.h"

typedef enum opt_type {
    T_STR,
    T_SIZE,
    T_COUNT,
    T_SECONDS,
    T_DEVICE,
    T_LEVEL,
    T_BOOL,
    T_LIST /* a string; each further use appends ",VALUE" */
} opt_type;

typedef struct opt_def {
    const char *name;
    opt_type type;
    size_t off;
    size_t len; /* strings */
    const char *help;
} opt_def;

#define F(field) offsetof(vx_config, field)
#define S(field) F(field), sizeof(((vx_config *)0)->field)

static const opt_def opts[] = {
    {"listen", T_STR, S(listen),
     "ADDR:PORT to listen on (IPv6 as [ADDR]:PORT; an empty ADDR, :PORT, = every IPv4 "
     "interface, [::]:PORT = every interface, IPv4 and IPv6; PORT 0 to 65535, 0 = any free)"},
    {"data-dir", T_STR, S(data_dir), "data directory (default $STATE_DIRECTORY or ./voxeld-data)"},
    {"cache-dir", T_STR, S(cache_dir), "cache directory (default $CACHE_DIRECTORY or DATA/cache)"},
    {"token-file", T_STR, S(token_file), "file holding the bearer token required on /v1 routes"},
    {"egl-device", T_DEVICE, F(egl_device), 0,
     "EGL device index (one that does not exist exits 2), or auto (default)"},
    {"log-level", T_LEVEL, F(log_level), 0, "error, warn, info (default) or debug"},
    {"gl-debug", T_BOOL, F(gl_debug), 0, "KHR_debug messages to the log: yes (default) or no"},
    {"require-gpu", T_BOOL, F(require_gpu), 0,
     "a software GL renderer (llvmpipe, softpipe, swrast) runs no job and /readyz answers 503: "
     "yes or no (default)"},
    {"http-threads", T_COUNT, F(http_threads), 0, "HTTP thread pool size (default 4; 1 to 1024)"},
    {"workers", T_COUNT, F(workers), 0,
     "CPU worker threads (default: the CPUs voxeld may use, its affinity and cgroup CPU limit; "
     "1 to 1024)"},
    {"max-upload-bytes", T_SIZE, F(max_upload_bytes), 0,
     "largest mesh upload (default 1G; at least 1)"},
    {"max-triangles", T_SIZE, F(max_triangles), 0,
     "most triangles in a mesh (default 20000000; 0 = no limit)"},
    {"max-queued-jobs", T_SIZE, F(max_queued_jobs), 0,
     "queued jobs before 429 (default 64; at least 1)"},
    {"job-timeout", T_SECONDS, F(job_timeout_s), 0,
     "longest a job may run, seconds (default 600; 0 = no limit)"},
    {"gl-stall-timeout", T_SECONDS, F(gl_stall_timeout_s), 0,
     "/livez answers 503 once the GL thread has been silent this long (a driver call that does "
     "not return), seconds (default 60; 0 = off, else at least 2)"},
    {"stop-timeout", T_SECONDS, F(stop_timeout_s), 0,
     "after SIGTERM, how long the running job (and answers being sent) may take to stop before "
     "voxeld exits 1 without it (it runs again at the next start), seconds (default 30; 0 = "
     "wait for the job, answers 30 s)"},
    {"request-timeout", T_SECONDS, F(request_timeout_s), 0,
     "longest a request is held by ?wait, seconds (default 60; 0 = ?wait answers at once)"},
    {"connection-timeout", T_SECONDS, F(connection_timeout_s), 0,
     "idle connections are closed after this, seconds (default 30; 0 = never)"},
    {"header-timeout", T_SECONDS, F(header_timeout_s), 0,
     "the whole request head must arrive within this, seconds (default 10; 0 = off)"},
    {"min-body-rate", T_SIZE, F(min_body_rate), 0,
     "slowest request body, bytes/s over 2 s windows after a 2 s grace (default 1024; 0 = off)"},
    {"min-send-rate", T_SIZE, F(min_send_rate), 0,
     "slowest reader of an answer, bytes/s over 10 s windows while the answer waits on the client "
     "(default 1024; 0 = off)"},
    {"max-uri-bytes", T_SIZE, F(max_uri_bytes), 0,
     "longest request target, path and query (default 16K; 256 to 128K)"},
    {"max-header-bytes", T_SIZE, F(max_header_bytes), 0,
     "largest request head, all header lines (default 64K; 1K to 128K)"},
    {"reuse-port", T_BOOL, F(reuse_port), 0,
     "share the port with other processes (SO_REUSEPORT): yes or no (default)"},
    {"max-connections", T_SIZE, F(max_connections), 0,
     "open connections in all (default 512; 1 to 1000000)"},
    {"max-connections-per-ip", T_SIZE, F(max_connections_per_ip), 0,
     "open connections from one IP (default 64; 0 = no limit)"},
    {"max-image-pixels", T_SIZE, F(max_image_pixels), 0,
     "largest rendered image, width*height (default 67108864; 0 = no limit)"},
    {"max-cc-valence", T_SIZE, F(max_cc_valence), 0,
     "gregory approximate-cc: most faces around a vertex, n-gons counted as vertices of n "
     "(its end caps cost the square; default 512; 0 = no limit)"},
    {"max-job-memory", T_SIZE, F(max_job_memory), 0,
     "memory one job may use (default 4G; 0 = no limit)"},
    {"keep-memory", T_SIZE, F(keep_memory), 0,
     "memory freed by jobs kept for the next job, beyond max-job-memory (default 256M; 0 = give "
     "it back at once)"},
    {"pretouch-memory", T_BOOL, F(pretouch_memory), 0,
     "map and touch keep-memory's bytes at start, so that the first jobs do not fault them in: "
     "yes or no (default)"},
    {"brick-threshold", T_SIZE, F(brick_threshold), 0,
     "voxelize grids of more cells run as bricks (vdb; default 1G = 1024^3; 0 = the default)"},
    {"max-json-bytes", T_SIZE, F(max_json_bytes), 0,
     "largest JSON request body (default 16M; at least 1)"},
    {"max-parse-memory", T_SIZE, F(max_parse_memory), 0,
     "worst-case memory of concurrent upload parses before 503 (default 8 x max-upload-bytes "
     "+ 256M; 0 = no limit)"},
    {"results-max-bytes", T_SIZE, F(results_max_bytes), 0,
     "results kept on disk before LRU eviction (default 10G; 0 = no limit)"},
    {"results-max-age", T_SECONDS, F(results_max_age_s), 0,
     "results unused this long are evicted, seconds (default 604800; 0 = never)"},
    {"blob-store", T_STR, S(blob_store),
     "where meshes, blobs and results live: file:///DIR (a shared dir) or "
     "s3://BUCKET/PREFIX?endpoint=URL&region=R (default: the data dir)"},
    {"blob-credentials", T_STR, S(blob_credentials),
     "s3: file with aws_access_key_id, aws_secret_access_key[, aws_session_token] "
     "(default: AWS_* environment)"},
    {"blob-cache-max-bytes", T_SIZE, F(blob_cache_max_bytes), 0,
     "s3: local copies kept in DATA/blobcache before LRU eviction (default 10G; 0 = no limit)"},
    {"blob-part-size", T_SIZE, F(blob_part_size), 0,
     "s3: objects over this go up in parts of it (default 64M; at least 5M)"},
    {"blob-timeout", T_SECONDS, F(blob_timeout_s), 0,
     "s3: connect timeout and longest stall of a transfer, seconds (default 30; 0 = the default)"},
    {"blob-retries", T_SIZE, F(blob_retries), 0,
     "s3: retries, with backoff, of a request that met a 5xx or connection error (default 3)"},
    {"database", T_STR, S(database),
     "postgresql://USER@HOST/DB: the job state and queue in PostgreSQL, shared by every replica "
     "given the same URL (cluster mode, with a shared --blob-store; default none: the local "
     "journal)"},
    {"replica-name", T_STR, S(replica_name),
     "this replica's name in job resources and claims, UTF-8 without blanks or control "
     "characters (default host name:port)"},
    {"lease-ttl", T_SECONDS, F(lease_ttl_s), 0,
     "cluster mode: a running job's lease, renewed every third of it; a replica silent this "
     "long loses its job to another (default 30; 0 = the default)"},
    {"max-attempts", T_COUNT, F(max_attempts), 0,
     "attempts a job gets before it fails (cluster mode); starts a job may see the daemon die "
     "during before it fails `interrupted` (local mode) (default 3; 1 to 1024)"},
    {"retry-backoff", T_SECONDS, F(retry_backoff_s), 0,
     "cluster mode: wait before a failed job's next attempt, doubled each attempt up to 60 s "
     "(default 1)"},
    {"min-free-disk", T_SIZE, F(min_free_disk), 0,
     "free space the data dir keeps: below it writes answer 507 (default 64M; 0 = only a full "
     "disk)"},
    {"cors-origin", T_LIST, S(cors_origin),
     "origin a browser may call the API from, SCHEME://HOST[:PORT] (repeat, or a comma list; * = "
     "any; default none)"},
    {"allowed-hosts", T_LIST, S(allowed_hosts),
     "Host names answered besides IP addresses, localhost, *.localhost and names without a dot "
     "(repeat, or a comma list; .NAME or *.NAME = NAME and the names under it; * = any; no port; "
     "default none: only those without --token-file, any with one)"},
    {"job-history", T_SIZE, F(job_history), 0,
     "finished jobs remembered (default 10000; at least 1)"},
    {"job-history-bytes", T_SIZE, F(job_history_bytes), 0,
     "memory the finished jobs remembered may take (default 64M; 0 = no limit)"},
    {"max-event-streams", T_SIZE, F(max_event_streams), 0,
     "open GET /v1/jobs/{id}/events streams before 503 (default 64; 0 = none: every one 503)"},
    {"max-waits", T_SIZE, F(max_waits), 0,
     "requests held by ?wait at once; past it a GET ?wait is 503 too_many_waits and a POST "
     "?wait answered at once (default 64; 0 = none held)"},
    {"event-keepalive", T_SECONDS, F(event_keepalive_s), 0,
     "idle time before an event stream gets a keepalive comment, seconds (default 15; 0 = the "
     "default)"},
};
#define NOPTS (sizeof opts / sizeof opts[0])

/* The CPUs this process may run on: its affinity mask (taskset, a
 * cpuset: docker --cpuset-cpus, Kubernetes' static CPU manager), and no
 * more than the cgroup v2 CPU limit rounds up to (docker --cpus, a pod's
 * limits.cpu). The online CPUs of the host were used: a container limited
 * to 2 CPUs on a 64-CPU node ran 64 workers, each job on one holding its
 * memory (--workers + 2 jobs at once). */
static int cpus_usable(void)
{
    cpu_set_t set;
    long n = 0;
    if (sched_getaffinity(0, sizeof set, &set) == 0) n = CPU_COUNT(&set);
    if (n <= 0) n = sysconf(_SC_NPROCESSORS_ONLN);
    FILE *f = fopen("/sys/fs/cgroup/cpu.max", "re");
    if (f) {
        char quota[32];
        unsigned long long period;
        if (fscanf(f, "%31s %llu", quota, &period) == 2 && strcmp(quota, "max") != 0 &&
            period > 0) {
            unsigned long long q = strtoull(quota, NULL, 10);
            long lim = (long)((q + period - 1) / period);
            if (lim >= 1 && (n <= 0 || lim < n)) n = lim;
        }
        fclose(f);
    }
    return n > 0 ? (n > 1024 ? 1024 : (int)n) : 2;
}

static void defaults(vx_config *c)
{
    memset(c, 0, sizeof *c);
    snprintf(c->listen, sizeof c->listen, "127.0.0.1:8080");
    const char *sd = getenv("STATE_DIRECTORY");
    /* systemd may pass several colon-separated directories: use the first. */
    if (sd && *sd) {
        snprintf(c->data_dir, sizeof c->data_dir, "%s", sd);
        char *colon = strchr(c->data_dir, ':');
        if (colon) *colon = 0;
    } else {
        snprintf(c->data_dir, sizeof c->data_dir, "voxeld-data");
    }
    const char *cd = getenv("CACHE_DIRECTORY");
    if (cd && *cd) {
        snprintf(c->cache_dir, sizeof c->cache_dir, "%s", cd);
        char *colon = strchr(c->cache_dir, ':');
        if (colon) *colon = 0;
    }
    c->egl_device = -1;
    c->log_level = VX_LOG_INFO;
    c->gl_debug = 1;
    c->http_threads = 4;
    c->workers = cpus_usable();
    c->max_upload_bytes = 1ull << 30;
    c->max_triangles = 20000000;
    c->lease_ttl_s = 30;
    c->max_attempts = 3;
    c->retry_backoff_s = 1;
    c->max_queued_jobs = 64;
    c->job_timeout_s = 600;
    c->stop_timeout_s = 30;
    c->gl_stall_timeout_s = 60;
    c->request_timeout_s = 60;
    c->connection_timeout_s = 30;
    c->header_timeout_s = 10;
    c->min_body_rate = 1024;
    c->min_send_rate = 1024;
    c->max_uri_bytes = 16 << 10;
    c->max_header_bytes = 64 << 10;
    c->max_connections = 512;
    c->max_connections_per_ip = 64;
    c->max_image_pixels = 8192ull * 8192ull;
    c->max_cc_valence = 512;
    c->max_job_memory = 4ull << 30;
    c->keep_memory = 256ull << 20;
    c->brick_threshold = 1ull << 30;
    c->max_json_bytes = 16ull << 20;
    c->max_parse_memory = 0; /* unless given: 8 x max_upload_bytes + 256M (vx_config_load) */
    c->results_max_bytes = 10ull << 30;
    c->results_max_age_s = 7 * 86400;
    c->blob_cache_max_bytes = 10ull << 30;
    c->blob_part_size = 64ull << 20;
    c->blob_timeout_s = 30;
    c->blob_retries = 3;
    c->job_history = 10000;
    c->min_free_disk = 64ull << 20;
    c->job_history_bytes = 64ull << 20;
    c->max_event_streams = 64;
    c->max_waits = 64;
    c->event_keepalive_s = 15;
}

/* The source that last set each list option: 1 the config file, 2 the
 * environment, 3 the command line. A list takes its values from the last
 * source that names it (a flag narrows what the file allowed), every use
 * within that source appended. */
static unsigned char list_source[NOPTS];
/* Whether each option was given at all (file, environment or flag). */
static unsigned char given[NOPTS];

/* 1 when s[0..n) is an origin a browser may send (SCHEME://HOST[:PORT],
 * the port not its scheme's default, which a browser leaves out; null, a
 * sandboxed or file: page's), *, or empty. */
static int origin_ok(const char *s, size_t n)
{
    if (n == 0 || (n == 1 && s[0] == '*') || (n == 4 && !strncasecmp(s, "null", 4))) return 1;
    size_t i = 0;
    if (!isalpha((unsigned char)s[0])) return 0;
    while (i < n && (isalnum((unsigned char)s[i]) || s[i] == '+' || s[i] == '-' || s[i] == '.'))
        i++;
    if (n - i < 4 || memcmp(s + i, "://", 3)) return 0;
    i += 3;
    const size_t host = i;
    if (s[i] == '[') { /* an IPv6 literal */
        while (i < n && s[i] != ']')
            i++;
        if (i == n) return 0;
        i++;
    } else {
        while (i < n && s[i] != ':' && !strchr("/?#@[] \t", s[i]))
            i++;
    }
    if (i == host) return 0;
    if (i < n && s[i] == ':') {
        unsigned long port = 0;
        size_t d = ++i;
        while (i < n && isdigit((unsigned char)s[i]) && i - d < 6)
            port = port * 10 + (unsigned long)(s[i++] - '0');
        if (i == d || s[d] == '0' || port > 65535) return 0;
        if ((port == 80 && !strncasecmp(s, "http:", 5)) ||
            (port == 443 && !strncasecmp(s, "https:", 6)))
            return 0;
    }
    return i == n;
}

static int set_opt(vx_config *c, const opt_def *d, const char *val, const char *where)
{
    char *base = (char *)c;
    uint64_t u;
    char *end;
    int over = 0; /* a list over its longest with the values before it */
    given[d - opts] = 1;
    /* an empty file name would leave /v1 without a token: refused, as an
     * empty token file is (VOXELD_TOKEN_FILE=$UNSET in a unit or .env) */
    if (!*val && !strcmp(d->name, "data-dir")) {
        vx_log_plain(VX_LOG_ERR,
                     "voxeld: %s: data-dir is empty (name the directory, or leave it out)\n",
                     where);
        return -1;
    }
    if (!*val && !strcmp(d->name, "token-file")) {
        vx_log_plain(VX_LOG_ERR,
                     "voxeld: %s: token-file is empty (name the file, or leave it out)\n", where);
        return -1;
    }
    /* a replica's name goes into the database (as text: UTF-8), its log
     * lines (unquoted) and job resources */
    if (!strcmp(d->name, "replica-name")) {
        const unsigned char *p = (const unsigned char *)val;
        for (size_t n = strlen(val), k; n; p += k, n -= k)
            if (*p <= ' ' || *p == 0x7f || !(k = vx_err_utf8_len(p, n))) {
                vx_log_plain(VX_LOG_ERR,
                             "voxeld: %s: replica-name must be UTF-8 without blanks or control "
                             "characters (byte %zu is 0x%02x)\n",
                             where, (size_t)(p - (const unsigned char *)val), *p);
                return -1;
            }
    }
    /* an Origin is SCHEME://HOST[:PORT], no path, no slash after it: a
     * value of another shape never matches a browser's, and was taken */
    if (!strcmp(d->name, "cors-origin")) {
        const char *bad_item = NULL;
        int bad_len = 0;
        for (const char *it = val; !bad_item;) {
            const char *comma = strchr(it, ',');
            int len = comma ? (int)(comma - it) : (int)strlen(it);
            const char *o = it; /* blanks around a list's items are not part of them */
            while (len && (*o == ' ' || *o == '\t'))
                o++, len--;
            while (len && (o[len - 1] == ' ' || o[len - 1] == '\t'))
                len--;
            if (!origin_ok(o, (size_t)len)) bad_item = o, bad_len = len;
            if (!comma) break;
            it = comma + 1;
        }
        if (bad_item) {
            vx_log_plain(VX_LOG_ERR,
                         "voxeld: %s: cors-origin takes origins as browsers send them, "
                         "SCHEME://HOST[:PORT] without a path or a slash after it, nor its "
                         "scheme's default port (or * or null): "
                         "'%.*s'\n",
                         where, bad_len > 200 ? 200 : bad_len, bad_item);
            return -1;
        }
    }
    /* a Host name, or .NAME, or *: a port or a path never matches one */
    if (!strcmp(d->name, "allowed-hosts") && strpbrk(val, ":/@[]\t")) {
        vx_log_plain(VX_LOG_ERR,
                     "voxeld: %s: allowed-hosts takes host names (.NAME for the names under NAME, "
                     "* for any), without a port: '%.200s'\n",
                     where, val);
        return -1;
    }
    if (d->type == T_LIST) {
        unsigned char src = !strcmp(where, "command line")        ? 3
                            : !strncmp(where, "environment ", 12) ? 2
                                                                  : 1;
        if (src > list_source[d - opts]) ((char *)base + d->off)[0] = 0;
        list_source[d - opts] = src;
    }
    switch (d->type) {
    case T_STR:
        if (strlen(val) >= d->len) goto bad;
        snprintf(base + d->off, d->len, "%s", val);
        return 0;
    case T_LIST: {
        char *s = base + d->off;
        size_t n = strlen(s);
        if (n + (n ? 1 : 0) + strlen(val) >= d->len) {
            over = 1; /* with what came before: said below */
            goto bad;
        }
        snprintf(s + n, d->len - n, "%s%s", n ? "," : "", val);
        return 0;
    }
    case T_SIZE:
        if (vx_parse_size(val, &u)) goto bad;
        *(uint64_t *)(base + d->off) = u;
        return 0;
    case T_COUNT: {
        errno = 0;
        long v = strtol(val, &end, 10);
        if (errno || *end || v < 1 || v > 1024) goto bad;
        *(int *)(base + d->off) = (int)v;
        return 0;
    }
    case T_SECONDS: {
        /* a decimal number: digits first (strtod also takes blanks, a
         * sign, hex and inf) */
        if (!isdigit((unsigned char)val[0]) || strspn(val, "0123456789.eE+-") != strlen(val))
            goto bad;
        errno = 0;
        double v = strtod(val, &end);
        /* at most 1e9 s (31 years): a library takes some of these as
         * 32-bit counts, which a bigger one would wrap */
        if (errno || *end || end == val || !isfinite(v) || v < 0 || v > 1e9) goto bad;
        *(double *)(base + d->off) = v;
        return 0;
    }
    case T_DEVICE: {
        if (strcmp(val, "auto") == 0) {
            *(int *)(base + d->off) = -1;
            return 0;
        }
        errno = 0;
        long v = strtol(val, &end, 10);
        if (errno || *end || end == val || v < 0 || v > 255) goto bad;
        *(int *)(base + d->off) = (int)v;
        return 0;
    }
    case T_LEVEL:
        if (vx_log_parse_level(val, (vx_log_level *)(base + d->off))) goto bad;
        return 0;
    case T_BOOL: /* as systemd's: yes/no, true/false, on/off, 1/0, any case */
        if (!strcasecmp(val, "yes") || !strcasecmp(val, "true") || !strcasecmp(val, "on") ||
            !strcmp(val, "1"))
            *(int *)(base + d->off) = 1;
        else if (!strcasecmp(val, "no") || !strcasecmp(val, "false") || !strcasecmp(val, "off") ||
                 !strcmp(val, "0"))
            *(int *)(base + d->off) = 0;
        else
            goto bad;
        return 0;
    }
bad:;
    static const char *want[] = {
        [T_SIZE] = "a whole number, K, M, G or T after it for 2^10, 2^20, 2^30, 2^40: 64, 64K, "
                   "1G",
        [T_COUNT] = "a whole number from 1 to 1024",
        [T_SECONDS] = "seconds, a decimal number from 0 to 1e9",
        [T_DEVICE] = "auto, or an index from 0 to 255",
        [T_LEVEL] = "error, warn, info or debug",
        [T_BOOL] = "yes or no (true/false, on/off, 1/0, any case)",
    };
    const char *w = (size_t)d->type < sizeof want / sizeof want[0] ? want[d->type] : NULL;
    char longest[64];
    if (over || (d->type == T_STR && strlen(val) >= d->len)) {
        snprintf(longest, sizeof longest, "at most %zu bytes%s", d->len - 1,
                 d->type == T_LIST ? " in all" : "");
        w = longest;
    }
    /* a value of 100 KB (a config line) is not echoed whole */
    vx_log_plain(VX_LOG_ERR, "voxeld: %s: invalid value for %s: '%.200s'%s%s%s%s\n", where, d->name,
                 val, strlen(val) > 200 ? "..." : "", w ? " (want " : "", w ? w : "", w ? ")" : "");
    return -1;
}

static const opt_def *find_opt(const char *name)
{
    for (size_t i = 0; i < NOPTS; i++)
        if (strcmp(opts[i].name, name) == 0) return &opts[i];
    return NULL;
}

static char *trim(char *s)
{
    while (isspace((unsigned char)*s))
        s++;
    char *e = s + strlen(s);
    while (e > s && isspace((unsigned char)e[-1]))
        *--e = 0;
    return s;
}

int vx_config_split_listen(const char *s, char host[256], char port[6])
{
    const char *colon, *h = s;
    if (s[0] == '[') { /* an IPv6 address: [127.0.0.1] or [] is none */
        const char *rb = strchr(s, ']');
        if (!rb || rb[1] != ':' || !memchr(s + 1, ':', (size_t)(rb - s - 1))) return -1;
        h = s + 1;
        colon = rb + 1;
    } else {
        colon = strrchr(s, ':');
        if (!colon || memchr(s, ':', (size_t)(colon - s))) return -1; /* IPv6 needs [] */
    }
    const char *p = colon + 1;
    size_t n = strspn(p, "0123456789"), hn = (size_t)(colon - h) - (s[0] == '[');
    if (n < 1 || n > 5 || p[n] || atol(p) > 65535 || hn > 255) return -1;
    memcpy(host, h, hn);
    host[hn] = 0;
    memcpy(port, p, n + 1);
    return 0;
}

static int load_file(vx_config *c, const char *path)
{
    int fd = vx_open_regular(path);
    FILE *f = fd >= 0 ? fdopen(fd, "r") : NULL;
    if (fd >= 0 && !f) close(fd);
    if (!f) {
        vx_log_plain(VX_LOG_ERR, "voxeld: cannot open config file %s: %s\n", path,
                     errno == EINVAL ? "not a regular file" : strerror(errno));
        return -1;
    }
    char *line = NULL, where[1200];
    size_t cap = 0;
    ssize_t n;
    int lineno = 0, rc = 0;
    while ((n = getline(&line, &cap, f)) >= 0) {
        lineno++;
        /* a UTF-8 byte order mark (an editor's) is no part of the first key */
        if (lineno == 1 && !strncmp(line, "\xef\xbb\xbf", 3)) {
            memmove(line, line + 3, (size_t)n - 2);
            n -= 3;
        }
        if ((size_t)n != strlen(line)) { /* a NUL would cut the value short */
            vx_log_plain(VX_LOG_ERR, "voxeld: %s:%d: a NUL byte in the line\n", path, lineno);
            rc = -1;
            continue;
        }
        /* a comment: '#' at the start or after a blank ("node#1" is a value) */
        for (char *h = line; *h; h++)
            if (*h == '#' && (h == line || isspace((unsigned char)h[-1]))) {
                *h = 0;
                break;
            }
        char *s = trim(line);
        if (!*s) continue;
        char *eq = strchr(s, '=');
        snprintf(where, sizeof where, "%s:%d", path, lineno);
        if (!eq) {
            vx_log_plain(VX_LOG_ERR, "voxeld: %s: expected key = value\n", where);
            rc = -1;
            continue;
        }
        *eq = 0;
        char *key = trim(s), *val = trim(eq + 1);
        const opt_def *d = find_opt(key);
        if (!d) {
            vx_log_plain(VX_LOG_ERR, "voxeld: %s: unknown key '%s'\n", where, key);
            rc = -1;
            continue;
        }
        if (set_opt(c, d, val, where)) rc = -1;
    }
    free(line);
    fclose(f);
    return rc;
}

/* The environment variable of a flag: VOXELD_ and the name upper-cased,
 * '-' as '_' (max-upload-bytes: VOXELD_MAX_UPLOAD_BYTES). */
static void env_name(const char *flag, char *out, size_t n)
{
    size_t o = (size_t)snprintf(out, n, "VOXELD_");
    for (; *flag && o + 1 < n; flag++)
        out[o++] = *flag == '-' ? '_' : (char)toupper((unsigned char)*flag);
    out[o] = 0;
}

/* VOXELD_* variables that are no option of the daemon's yet its own or its
 * clients' (voxelctl's server, token and daemon; the tests' hooks). */
static int env_known_other(const char *name, size_t len)
{
    static const char *const other[] = {"VOXELD_CONFIG", "VOXELD_URL", "VOXELD_TOKEN",
                                        "VOXELD_BIN"};
    for (size_t i = 0; i < sizeof other / sizeof other[0]; i++)
        if (strlen(other[i]) == len && !strncmp(name, other[i], len)) return 1;
    return !strncmp(name, "VOXELD_TEST_", 12);
}

/* Every flag set in the environment (VOXELD_*), over the config file. A
 * VOXELD_ variable that names no option (a misspelling) is warned about:
 * the prefix is shared with the clients' variables, so it is no error. */
static int load_env(vx_config *c)
{
    int rc = 0;
    for (size_t i = 0; i < NOPTS; i++) {
        char name[80], where[100];
        env_name(opts[i].name, name, sizeof name);
        const char *v = getenv(name);
        if (!v) continue;
        snprintf(where, sizeof where, "environment %s", name);
        if (set_opt(c, &opts[i], v, where)) rc = -1;
    }
    for (char **e = environ; *e; e++) {
        if (strncmp(*e, "VOXELD_", 7)) continue;
        size_t len = strcspn(*e, "=");
        int known = env_known_other(*e, len);
        for (size_t i = 0; i < NOPTS && !known; i++) {
            char name[80];
            env_name(opts[i].name, name, sizeof name);
            known = strlen(name) == len && !strncmp(*e, name, len);
        }
        if (!known)
            vx_log_plain(VX_LOG_WARN,
                         "voxeld: warning: %.*s names no option (ignored; see voxeld --help)\n",
                         (int)(len > 80 ? 80 : len), *e);
    }
    return rc;
}

void vx_config_usage(FILE *out)
{
    fprintf(out, "usage: voxeld [--listen ADDR:PORT] [--data-dir DIR] [options]\n"
                 "       voxeld run KIND FILE [voxelctl options]   (one job, no server)\n\n"
                 "Serves mesh jobs (voxel grids, renders, Gregory meshes) over HTTP/JSON on one\n"
                 "headless OpenGL context. Runs in the foreground and logs to stderr.\n\n"
                 "  --config FILE                 read options from FILE (key = value lines)\n");
    for (size_t i = 0; i < NOPTS; i++) {
        char flag[64];
        snprintf(flag, sizeof flag, "--%s %s", opts[i].name,
                 opts[i].type == T_BOOL                            ? "yes|no"
                 : opts[i].type == T_STR || opts[i].type == T_LIST ? "VALUE"
                 : opts[i].type == T_LEVEL                         ? "LEVEL"
                 : opts[i].type == T_DEVICE                        ? "N|auto"
                 : opts[i].type == T_SECONDS                       ? "SECONDS"
                                                                   : "N");
        fprintf(out, "  %-29s %s\n", flag, opts[i].help);
    }
    fprintf(out, "  --list-egl-devices            list EGL devices in the order tried, and exit\n"
                 "  --help                        this text\n"
                 "  --version                     print the version and exit\n\n"
                 "Sizes take K, M, G, T suffixes (powers of 1024).\n"
                 "Every option can also be set in the environment: VOXELD_ and its name in\n"
                 "capitals with '_' for '-' (VOXELD_MAX_UPLOAD_BYTES=2G, VOXELD_CONFIG=FILE).\n"
                 "Flags win over the environment, which wins over the config file.\n");
}

int vx_config_load(vx_config *c, int argc, char **argv)
{
    defaults(c);
    memset(list_source, 0, sizeof list_source);
    memset(given, 0, sizeof given);
    struct option lopts[NOPTS + 5];
    for (size_t i = 0; i < NOPTS; i++)
        lopts[i] = (struct option){opts[i].name, required_argument, NULL, (int)(256 + i)};
    lopts[NOPTS] = (struct option){"config", required_argument, NULL, 'c'};
    lopts[NOPTS + 1] = (struct option){"help", no_argument, NULL, 'h'};
    lopts[NOPTS + 2] = (struct option){"version", no_argument, NULL, 'V'};
    lopts[NOPTS + 3] = (struct option){"list-egl-devices", no_argument, NULL, 'L'};
    lopts[NOPTS + 4] = (struct option){0, 0, 0, 0};

    /* Pass 1: --config, --help, --version (the file comes before the flags). */
    const char *env_config = getenv("VOXELD_CONFIG");
    if (env_config) snprintf(c->config_file, sizeof c->config_file, "%s", env_config);
    int config_flag = 0;
    opterr = 0;
    optind = 1;
    int ch;
    while ((ch = getopt_long(argc, argv, "", lopts, NULL)) != -1) {
        if (ch == 'h') {
            vx_config_usage(stdout);
            return 1;
        }
        if (ch == 'V') {
            printf("voxeld %s\n", VX_VERSION);
            return 1;
        }
        if (ch == 'c') {
            if (!*optarg) {
                vx_log_plain(VX_LOG_ERR, "voxeld: --config needs a file name\n");
                return -1;
            }
            snprintf(c->config_file, sizeof c->config_file, "%s", optarg);
            config_flag = 1;
        }
    }
    if (env_config && !*env_config && !config_flag) { /* as --config '' (it was taken as unset) */
        vx_log_plain(VX_LOG_ERR, "voxeld: VOXELD_CONFIG is empty (name the file, or unset it)\n");
        return -1;
    }
    if (c->config_file[0] && load_file(c, c->config_file)) return -1;
    if (load_env(c)) return -1;

    /* Pass 2: flags override the environment and the file. */
    opterr = 1;
    optind = 1;
    while ((ch = getopt_long(argc, argv, "", lopts, NULL)) != -1) {
        if (ch == '?' || ch == ':') {
            vx_config_usage(stderr);
            return -1;
        }
        if (ch == 'L') c->list_devices = 1;
        if (ch >= 256 && set_opt(c, &opts[ch - 256], optarg, "command line")) return -1;
    }
    if (optind < argc) {
        vx_log_plain(VX_LOG_ERR, "voxeld: unexpected argument '%s'\n", argv[optind]);
        return -1;
    }
    if (!c->cache_dir[0]) snprintf(c->cache_dir, sizeof c->cache_dir, "%s/cache", c->data_dir);
    /* "0 = the default" as the value in effect (what /v1/info shows) */
    if (!c->brick_threshold) c->brick_threshold = 1ull << 30;
    if (!c->event_keepalive_s) c->event_keepalive_s = 15;
    if (!c->lease_ttl_s) c->lease_ttl_s = 30;
    if (!c->blob_timeout_s) c->blob_timeout_s = 30;
    /* Enough for one upload of the largest size in the costliest format
     * (vx_mesh_parse_cost: OBJ, 8 x the file). */
    if (!given[find_opt("max-parse-memory") - opts])
        c->max_parse_memory = c->max_upload_bytes > (UINT64_MAX - (256ull << 20)) / 8
                                  ? 0
                                  : 8 * c->max_upload_bytes + (256ull << 20);
    if (c->token_file[0]) {
        vx_err err;
        size_t len;
        char *tok = vx_read_file(c->token_file, sizeof c->token, &len, &err);
        if (!tok) {
            vx_log_plain(VX_LOG_ERR, "voxeld: token file %s: %s\n", c->token_file, err.message);
            return -1;
        }
        /* The token is what a client sends after "Bearer ": visible ASCII.
         * A NUL had cut it short silently (a binary token of 32 random
         * bytes could end after 2). */
        char *t = tok;
        while (t < tok + len && isspace((unsigned char)*t))
            t++;
        size_t tl = (size_t)(tok + len - t);
        while (tl && isspace((unsigned char)t[tl - 1]))
            tl--;
        for (size_t i = 0; i < tl; i++)
            if ((unsigned char)t[i] < 0x21 || (unsigned char)t[i] > 0x7e) {
                vx_log_plain(VX_LOG_ERR,
                             "voxeld: token file %s holds a byte that cannot be sent in an HTTP "
                             "header (byte %zu is 0x%02x; a token is visible ASCII, such as the "
                             "output of 'openssl rand -hex 32')\n",
                             c->token_file, (size_t)(t - tok) + i, (unsigned)(unsigned char)t[i]);
                free(tok);
                return -1;
            }
        if (tl >= sizeof c->token) { /* it was cut to its first 511 bytes, silently */
            vx_log_plain(VX_LOG_ERR,
                         "voxeld: token file %s holds a token of %zu bytes, over the %zu "
                         "taken\n",
                         c->token_file, tl, sizeof c->token - 1);
            free(tok);
            return -1;
        }
        snprintf(c->token, sizeof c->token, "%.*s", (int)tl, t);
        free(tok);
        if (!c->token[0]) {
            vx_log_plain(VX_LOG_ERR, "voxeld: token file %s is empty\n", c->token_file);
            return -1;
        }
    }
    char host[256], port[6];
    if (vx_config_split_listen(c->listen, host, port)) {
        vx_log_plain(VX_LOG_ERR,
                     "voxeld: listen: '%s' is not ADDR:PORT ([ADDR]:PORT for IPv6, PORT from 0 to "
                     "65535)\n",
                     c->listen);
        return -1;
    }
    /* Replicas read each other's meshes and results: with the data dir as
     * the store a replica would claim jobs whose bytes are elsewhere. */
    if (c->database[0] && !c->blob_store[0]) {
        vx_log_plain(VX_LOG_ERR,
                     "voxeld: database: cluster mode needs a --blob-store every replica "
                     "shares (file:///DIR or s3://BUCKET/PREFIX?endpoint=URL), not the data "
                     "dir\n");
        return -1;
    }
    if (c->blob_part_size < (5ull << 20)) {
        vx_log_plain(VX_LOG_ERR,
                     "voxeld: blob-part-size must be at least 5M (S3's smallest part)\n");
        return -1;
    }
    if (c->max_connections < 1 || c->max_connections > 1000000) {
        vx_log_plain(VX_LOG_ERR, "voxeld: max-connections must be from 1 to 1000000\n");
        return -1;
    }
    /* 0 would refuse every upload, every JSON request, or remember no job
     * (GET /v1/jobs/{id} 404 the moment a job ends): a mistake, not a limit */
    static const struct {
        const char *name;
        size_t off;
    } at_least_1[] = {{"max-upload-bytes", F(max_upload_bytes)},
                      {"max-json-bytes", F(max_json_bytes)},
                      {"job-history", F(job_history)}};
    for (size_t i = 0; i < sizeof at_least_1 / sizeof at_least_1[0]; i++)
        if (*(const uint64_t *)((const char *)c + at_least_1[i].off) < 1) {
            vx_log_plain(VX_LOG_ERR, "voxeld: %s must be at least 1\n", at_least_1[i].name);
            return -1;
        }
    if (c->max_queued_jobs < 1) {
        vx_log_plain(VX_LOG_ERR, "voxeld: max-queued-jobs must be at least 1\n");
        return -1;
    }
    /* Below these not even GET /livez fits: health checks could never pass. */
    if (c->max_uri_bytes < 256) {
        vx_log_plain(VX_LOG_ERR, "voxeld: max-uri-bytes must be at least 256\n");
        return -1;
    }
    if (c->max_header_bytes < 1024) {
        vx_log_plain(VX_LOG_ERR, "voxeld: max-header-bytes must be at least 1K\n");
        return -1;
    }
    /* Above these libmicrohttpd's own 256 KiB a connection answers first
     * (its HTML 414 or 431): a larger limit would never be the one met. */
    if (c->max_uri_bytes > VX_CONFIG_MAX_HEAD) {
        vx_log_plain(VX_LOG_ERR, "voxeld: max-uri-bytes must be at most 128K\n");
        return -1;
    }
    if (c->max_header_bytes > VX_CONFIG_MAX_HEAD) {
        vx_log_plain(VX_LOG_ERR, "voxeld: max-header-bytes must be at most 128K\n");
        return -1;
    }
    /* The GL thread says it is alive about once a second: a shorter limit
     * would find an idle, healthy thread silent. */
    if (c->gl_stall_timeout_s > 0 && c->gl_stall_timeout_s < 2) {
        vx_log_plain(VX_LOG_ERR,
                     "voxeld: gl-stall-timeout must be 0 (off) or at least 2 seconds (the GL "
                     "thread says it is alive about once a second)\n");
        return -1;
    }
    return 0;
}
