/* voxeld: configuration, signals, sd_notify and the wiring of store, jobs
 * (GL thread + workers) and the HTTP API. */
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <malloc.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <systemd/sd-daemon.h>
#include <time.h>
#include <unistd.h>

#include "config.h"
#include "http.h"
#include "kinds.h"
#include "jobs/jobs.h"
#include "metrics.h"
#include "store/blob.h"
#include "store/store.h"
#include "util/bigmem.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/stop.h"

/* The jobs hooks need the HTTP layer, which starts after the jobs, and the
 * job table, which exists before any job runs. */
static vx_http *g_http;
static vx_jobs *g_jobs;

static void on_job_finished(void *ud, const char *jid, const char *kind, const char *state,
                            double run_s)
{
    /* Called without the registry lock: the job's error code and queue
     * wait come from its JSON (gone when the history dropped it at once). */
    vx_jobs *jobs = __atomic_load_n(&g_jobs, __ATOMIC_ACQUIRE);
    vx_err e;
    cJSON *doc = jobs ? vx_jobs_get(jobs, jid, NULL, &e) : NULL;
    const cJSON *code =
        cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(doc, "error"), "code");
    const cJSON *qms = cJSON_GetObjectItemCaseSensitive(
        cJSON_GetObjectItemCaseSensitive(doc, "timings"), "queue_ms");
    double queue_s = run_s >= 0 && cJSON_IsNumber(qms) ? qms->valuedouble / 1e3 : -1;
    const char *c = !strcmp(state, "failed") ? (cJSON_GetStringValue(code) ?: "unknown") : NULL;
    vx_metrics_job(kind, state, run_s, queue_s, c);
    cJSON_Delete(doc);
}

static void on_job_changed(void *ud, const char *jid, int terminal)
{
    vx_http *h = __atomic_load_n(&g_http, __ATOMIC_ACQUIRE);
    vx_http_job_changed(h, jid, terminal);
}

/* When the GL thread last said it was alive (/livez's check). */
static _Atomic double g_gl_alive_at;
/* VOXELD_TEST_GL_STALL=S (tests only): the GL thread's third ping stalls
 * it for S seconds, as a driver call that does not return would. */
static double g_test_stall_s;

/* Whether systemd watches this process (WATCHDOG_USEC set, WATCHDOG_PID
 * unset or this pid: sd_watchdog_enabled), and its period, read at start. */
static int g_watchdog;
static uint64_t g_watchdog_usec;

/* The GL thread pings the systemd watchdog through the jobs' alive hook,
 * when there is one, and notes the time for /livez. */
static void on_jobs_alive(void *ud)
{
    (void)ud;
    static int pings; /* GL thread only */
    if (g_test_stall_s > 0 && ++pings == 3) {
        struct timespec ts = {.tv_sec = (time_t)g_test_stall_s};
        nanosleep(&ts, NULL);
    }
    atomic_store(&g_gl_alive_at, vx_mono());
    if (g_watchdog) sd_notify(0, "WATCHDOG=1");
}

/* VOXELD_TEST_LOSE_CONTEXT=N (tests only): the next N GL stages run as if
 * the context had been lost, since a real reset cannot be provoked on
 * llvmpipe. Read once at start; GL thread afterwards. */
static int g_lose_context;

static int on_lose_context(void *ud)
{
    if (g_lose_context <= 0) return 0;
    g_lose_context--;
    return 1;
}

static int list_devices(void)
{
    vx_gl_device devs[32];
    vx_err err;
    int n = vx_gl_list_devices(devs, 32, &err);
    if (n < 0) {
        vx_log_plain(VX_LOG_ERR, "voxeld: %s\n", err.message);
        return 1;
    }
    printf("%d EGL device(s), in the order --egl-device auto tries them:\n", n);
    for (int i = 0; i < n; i++)
        printf("  %d  %-9s %s\n", devs[i].index, devs[i].kind, devs[i].name);
    return 0;
}

/* Raises the soft descriptor limit to the hard one, and fits the
 * connection limit into what is left after the daemon's own files: each
 * connection may hold two descriptors (its socket, an upload's temp file).
 * Past the limit libmicrohttpd's accept failed with EMFILE, answered no
 * request, and logged that at every try. -1 when too few are left for
 * any connection. */
static int fit_fd_limit(vx_config *cfg)
{
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl) != 0) return 0;
    if (rl.rlim_cur != rl.rlim_max) {
        rl.rlim_cur = rl.rlim_max;
        if (setrlimit(RLIMIT_NOFILE, &rl) != 0) getrlimit(RLIMIT_NOFILE, &rl);
    }
    if (rl.rlim_cur == RLIM_INFINITY) return 0;
    /* the store, the journal, the GL driver, each job's files, the HTTP
     * threads' epoll and event descriptors */
    uint64_t reserve = 32 + 4 * (uint64_t)cfg->http_threads + 4 * (uint64_t)cfg->workers;
    uint64_t fit = rl.rlim_cur > reserve ? (rl.rlim_cur - reserve) / 2 : 0;
    if (fit < 1) {
        vx_log_plain(
            VX_LOG_ERR,
            "voxeld: %llu file descriptors (ulimit -n) leave none for connections: it needs "
            "%llu for itself and 2 a connection\n",
            (unsigned long long)rl.rlim_cur, (unsigned long long)reserve);
        return -1;
    }
    if (cfg->max_connections > fit) {
        VX_WARN("http.fd_limit",
                "nofile=%llu max_connections=%llu effective=%llu action=\"raise ulimit -n "
                "(LimitNOFILE=) for more connections\"",
                (unsigned long long)rl.rlim_cur, (unsigned long long)cfg->max_connections,
                (unsigned long long)fit);
        cfg->max_connections = fit;
    }
    return 0;
}

/* Held requests (?wait holds, event streams) are never swept for headroom:
 * together they may take at most half of --max-connections (as in effect),
 * so that a prompt client always finds a slot. Lowered with a warning. */
static void fit_holds(vx_config *cfg)
{
    uint64_t half = cfg->max_connections / 2;
    if (cfg->max_waits + cfg->max_event_streams <= half) return;
    uint64_t waits = cfg->max_waits, streams = cfg->max_event_streams;
    /* shared in proportion to what was asked */
    cfg->max_waits = (uint64_t)((double)waits * (double)half / ((double)waits + (double)streams));
    if (cfg->max_waits > half) cfg->max_waits = half;
    /* a share rounded down to 0 is 1 where the half has room: 0 is not a
     * smaller limit but "none held" (every GET ?wait 503) */
    if (waits && !cfg->max_waits && half >= 2) cfg->max_waits = 1;
    cfg->max_event_streams = half - cfg->max_waits;
    if (streams && !cfg->max_event_streams && cfg->max_waits >= 2) {
        cfg->max_waits--;
        cfg->max_event_streams = 1;
    }
    VX_WARN("http.holds_limit",
            "max_connections=%llu max_waits=%llu max_event_streams=%llu effective_waits=%llu "
            "effective_streams=%llu action=\"raise --max-connections for more held requests\"",
            (unsigned long long)cfg->max_connections, (unsigned long long)waits,
            (unsigned long long)streams, (unsigned long long)cfg->max_waits,
            (unsigned long long)cfg->max_event_streams);
}

/* Blocks the signals the main thread takes synchronously, into *sigs. */
static void block_signals(sigset_t *sigs)
{
    /* Signals are taken synchronously by the main thread: block them
     * before any thread starts so every thread inherits the mask. */
    sigemptyset(sigs);
    sigaddset(sigs, SIGTERM);
    sigaddset(sigs, SIGINT);
    sigaddset(sigs, SIGHUP);
    sigaddset(sigs, SIGUSR1); /* logged and ignored, as SIGHUP: they killed it */
    sigaddset(sigs, SIGUSR2);
    pthread_sigmask(SIG_BLOCK, sigs, NULL);
    signal(SIGPIPE, SIG_IGN);
}

/* Builds the job runner's desc from the configuration. */
static vx_jobs_desc make_jobs_desc(const vx_config *cfg, vx_store *store, int have_cache)
{
    vx_jobs_desc jd = {
        .store = store,
        .kinds = &vx_daemon_kinds,
        .cache_dir = have_cache ? cfg->cache_dir : NULL,
        .limits = {.max_upload_bytes = cfg->max_upload_bytes,
                   .max_triangles = cfg->max_triangles,
                   .max_image_pixels = cfg->max_image_pixels,
                   .max_cc_valence = cfg->max_cc_valence,
                   .max_job_memory = cfg->max_job_memory,
                   .brick_threshold = cfg->brick_threshold,
                   .job_timeout_s = cfg->job_timeout_s},
        .max_queued = cfg->max_queued_jobs,
        .history = cfg->job_history,
        .history_bytes = cfg->job_history_bytes,
        .workers = cfg->workers,
        .max_interruptions = cfg->max_attempts,
        .gl = {.pick_device = cfg->egl_device >= 0,
               .device = cfg->egl_device,
               .debug = cfg->gl_debug,
               .robust = 1},
        .hooks = {.finished = on_job_finished,
                  .changed = on_job_changed,
                  .alive = on_jobs_alive,
                  .lose_context = on_lose_context},
    };
    return jd;
}

/* --require-gpu: the renderer a context on the configured device gets,
 * asked before the job runner starts (it would at once run the jobs the
 * journal queued again). 1 = a software one (*out filled), 0 = hardware,
 * -1 = no context at all (the runner's own start then says why). */
static int probe_software_gl(const vx_config *cfg, vx_gl_info *out)
{
    vx_jobs_desc jd = make_jobs_desc(cfg, NULL, 0);
    vx_err err;
    vx_gl *gl = vx_gl_new(&jd.gl, &err);
    if (!gl) return -1;
    *out = *vx_gl_get_info(gl);
    vx_gl_free(gl);
    return vx_gl_info_software(out);
}

/* The replica name: --replica-name, else host name:port. */
static void replica_name(const vx_config *cfg, char out[128])
{
    if (cfg->replica_name[0]) {
        snprintf(out, 128, "%s", cfg->replica_name);
        return;
    }
    char host[64] = "voxeld";
    gethostname(host, sizeof host - 1);
    const char *colon = strrchr(cfg->listen, ':');
    int port = colon ? atoi(colon + 1) : 0;
    if (port > 0)
        snprintf(out, 128, "%s:%d", host, port);
    else
        snprintf(out, 128, "%s:pid%d", host, (int)getpid());
}

/* Whether a failed start was a bad option's value (exit 2) that only the
 * store, the queue or EGL could tell: a file:// store that is not absolute,
 * a malformed s3:// or database URL, an --egl-device index with no device. */
static int bad_option(const vx_err *err)
{
    return !strcmp(err->code, "bad_blob_store") || !strcmp(err->code, "invalid_database_url") ||
           !strcmp(err->code, "bad_egl_device");
}

/* The start-up's stop hook: SIGTERM or SIGINT (blocked until the daemon
 * serves, so pending) ends a wait for the database. */
static int startup_stop(void *ud, vx_err *err)
{
    (void)ud;
    sigset_t p;
    if (sigpending(&p) || !(sigismember(&p, SIGTERM) || sigismember(&p, SIGINT))) return 0;
    return vx_err_set(err, VX_ECANCELED, "stopped", "a signal came while starting");
}

/* Opens the job runner and, when start, starts its GL thread; NULL (logged)
 * on failure. Not started, it keeps its queue and runs nothing. */
static vx_jobs *open_jobs(const vx_config *cfg, vx_store *store, int start, vx_err *err)
{
    vx_err cerr;
    int have_cache = vx_mkdirs(cfg->cache_dir, &cerr) == 0;
    if (!have_cache)
        VX_WARN("voxeld.no_cache_dir", "path=%s code=%s", VX_Q(cfg->cache_dir), cerr.code);
    vx_jobs_desc jd = make_jobs_desc(cfg, store, have_cache);
    char replica[128];
    replica_name(cfg, replica);
    jd.replica = replica;
    vx_pg_desc pd = {.url = cfg->database,
                     .replica = replica,
                     .lease_s = cfg->lease_ttl_s,
                     .max_attempts = cfg->max_attempts,
                     .backoff_s = cfg->retry_backoff_s};
    if (cfg->database[0]) jd.database = &pd;
    const char *lose = getenv("VOXELD_TEST_LOSE_CONTEXT");
    g_lose_context = lose && atoi(lose) > 0 ? atoi(lose) : 0;
    const char *stall = getenv("VOXELD_TEST_GL_STALL");
    g_test_stall_s = stall ? atof(stall) : 0;
    atomic_store(&g_gl_alive_at, vx_mono());
    vx_stop_set(startup_stop, NULL);
    vx_jobs *jobs = vx_jobs_open(&jd, err);
    vx_stop_set(NULL, NULL);
    __atomic_store_n(&g_jobs, jobs, __ATOMIC_RELEASE);
    if (!jobs && !strcmp(err->code, "stopped")) {
        VX_INFO("voxeld.stop", "stage=database reason=signal");
        return NULL;
    }
    if (!jobs) {
        VX_ERROR("voxeld.fatal", "stage=%s code=%s message=%s",
                 cfg->database[0] ? "database" : "journal", err->code,
                 vx_log_quote((char[600]){0}, 600, err->message));
        if (cfg->database[0]) vx_log_plain(VX_LOG_ERR, "voxeld: --database: %s\n", err->message);
        return NULL;
    }
    if (start && vx_jobs_start(jobs, err)) {
        char q[600];
        VX_ERROR("voxeld.fatal", "stage=gl code=%s message=%s", err->code,
                 vx_log_quote(q, sizeof q, err->message));
        if (bad_option(err))
            vx_log_plain(VX_LOG_ERR, "voxeld: --egl-device: %s (voxeld --list-egl-devices)\n",
                         err->message);
        else
            vx_log_plain(VX_LOG_ERR, "voxeld: cannot create the OpenGL context: %s\n",
                         err->message);
        __atomic_store_n(&g_jobs, NULL, __ATOMIC_RELEASE);
        vx_jobs_free(jobs);
        return NULL;
    }
    return jobs;
}

/* After SIGTERM: a job that does not stop (stuck in a loop that never
 * checks for a stop, or in a driver call) would keep the process alive
 * until systemd or the kubelet kills it. Past the limit it exits 1: the
 * journal holds everything acknowledged (each change was fsync'd), and
 * the running job is queued again at the next start (counted as an
 * interruption, see --max-attempts). */
/* When the jobs had stopped (vx_mono; 0 until then). */
static _Atomic double g_jobs_stopped_at;
#define STOP_HTTP_GRACE_S 2.0 /* vx_http_stop's grace for requests arriving */
#define STOP_ANSWERS_S 30.0   /* and for answers being sent, with --stop-timeout 0 */

static void sleep_s(double s)
{
    struct timespec ts = {.tv_sec = (time_t)s, .tv_nsec = (long)((s - (time_t)s) * 1e9)};
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR)
        ;
}

static void *stop_watchdog(void *arg)
{
    double s = *(double *)arg;
    sleep_s(s);
    /* The jobs stopped in time: what is left is the server's own stop,
     * given the requests' grace and a second more past the jobs' stop (a
     * --stop-timeout under that grace exited 1 with an idle keep-alive
     * connection open, saying a job had not stopped where there was none). */
    const double at = atomic_load(&g_jobs_stopped_at);
    if (at > 0) {
        const double left = at + STOP_HTTP_GRACE_S + 1.0 - vx_mono();
        if (left > 0) sleep_s(left);
        VX_ERROR("voxeld.stop_timeout",
                 "seconds=%g action=\"exit 1: the jobs stopped, the server did not (a request "
                 "or the store)\"",
                 s);
        _exit(1);
    }
    VX_ERROR("voxeld.stop_timeout",
             "seconds=%g action=\"exit 1: the running job did not stop; it runs again at the "
             "next start\"",
             s);
    _exit(1);
    return NULL;
}

static void start_stop_watchdog(double seconds)
{
    static double limit;
    if (seconds <= 0) return;
    limit = seconds;
    pthread_t t;
    if (pthread_create(&t, NULL, stop_watchdog, &limit) == 0) pthread_detach(t);
}

/* Waits for SIGTERM/SIGINT, running the once-a-minute maintenance meanwhile.
 * The GL thread pings the systemd watchdog (on_jobs_alive); when it does
 * not run (--require-gpu refused a software renderer) the main thread
 * pings it instead, at half the watchdog's period: the daemon serves, and
 * systemd would otherwise kill and restart it every WatchdogSec. */
static void serve_until_signal(const sigset_t *sigs, vx_store *store, vx_jobs *jobs,
                               int ping_watchdog)
{
    double ping_s = 0;
    if (ping_watchdog && g_watchdog) {
        ping_s = (double)g_watchdog_usec / 2e6;
        if (ping_s < 0.05) ping_s = 0.05;
        sd_notify(0, "WATCHDOG=1");
    }
    double next_maint = vx_mono() + 60;
    for (;;) {
        double wait_s = next_maint - vx_mono();
        if (ping_s > 0 && ping_s < wait_s) wait_s = ping_s;
        if (wait_s < 0) wait_s = 0;
        struct timespec ts = {.tv_sec = (time_t)wait_s,
                              .tv_nsec = (long)((wait_s - (double)(time_t)wait_s) * 1e9)};
        int sig = sigtimedwait(sigs, NULL, &ts);
        if (sig == SIGTERM || sig == SIGINT) {
            VX_INFO("voxeld.signal", "signal=%s", sig == SIGTERM ? "TERM" : "INT");
            break;
        }
        if (sig == SIGHUP || sig == SIGUSR1 || sig == SIGUSR2)
            VX_INFO("voxeld.signal", "signal=%s action=none",
                    sig == SIGHUP    ? "HUP"
                    : sig == SIGUSR1 ? "USR1"
                                     : "USR2");
        if (ping_s > 0) sd_notify(0, "WATCHDOG=1");
        if (vx_mono() >= next_maint) {     /* once a minute */
            vx_store_results_evict(store); /* the age budget */
            vx_jobs_maintain(jobs, 16L << 20);
            next_maint = vx_mono() + 60;
        }
    }
}

/* `voxeld run KIND FILE [voxelctl options]`: one job without a server, as
 * `voxelctl --local KIND FILE ...` (the voxelctl installed beside voxeld,
 * else on PATH). Returns only if it cannot be started. */
static int run_one_job(int argc, char **argv)
{
    char self[4096], ctl[4200];
    ssize_t k = readlink("/proc/self/exe", self, sizeof self - 1);
    char *slash = k > 0 ? (self[k] = 0, strrchr(self, '/')) : NULL;
    if (slash) *slash = 0;
    snprintf(ctl, sizeof ctl, "%s/voxelctl", slash ? self : ".");
    if (!slash || access(ctl, X_OK) != 0) snprintf(ctl, sizeof ctl, "voxelctl");
    char **av = calloc((size_t)argc + 1, sizeof *av);
    if (!av) return 1;
    av[0] = ctl;
    av[1] = "--local";
    for (int i = 2; i < argc; i++)
        av[i] = argv[i];
    execvp(ctl, av);
    vx_log_plain(VX_LOG_ERR, "voxeld: run needs voxelctl (%s): %s\n", ctl, strerror(errno));
    free(av);
    return 1;
}

/* A job's big buffers, and glibc's heap, stay mapped after the job for the
 * next one, up to bytes: on a virtual machine that returns freed memory to
 * its host (free page reporting), every page faulted in afresh costs a host
 * fault, which was half of a 1024^3 voxelize job's time or more (spot,
 * `summary`: 80-130 ms, 28-43 with the default; bench/RESULTS.md). The heap
 * serves blocks up to 32 MiB itself (M_MMAP_THRESHOLD; glibc's own threshold
 * moves with each block freed) and keeps up to that much free at the top of
 * each thread's arena (M_TRIM_THRESHOLD), or bytes if less: a whole keep
 * in each of a dozen arenas had the HTTP threads hold their JSON parse
 * peaks, and the jobs' own heap (crossing lists, 22 MB a bunny 1024^3 job)
 * fits the 32 MiB (no job was slower for the cap). */
static void keep_memory(uint64_t bytes, int pretouch)
{
    if (!bytes) return;
    size_t keep = bytes > SIZE_MAX / 2 ? SIZE_MAX / 2 : (size_t)bytes;
    vx_bigmem_keep(keep);
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, keep > (32 << 20) ? 32 << 20 : (int)keep);
    if (!pretouch) return;
    /* The first job's grid faulted in too (spot 1024^3 `summary`: its
     * first job 130 ms, the next ones 30-40): all of it mapped now. */
    double t0 = vx_mono();
    size_t n = vx_bigmem_pretouch(keep);
    VX_INFO("memory.pretouched", "bytes=%zu ms=%.1f", n, (vx_mono() - t0) * 1e3);
}

/* Descriptors 0 to 2 closed by whoever started us (`voxeld 2>&-`): the
 * files opened next would take them, and the log (fd 2) went into the
 * data dir's lock file. They are /dev/null instead. */
static void hold_std_fds(void)
{
    int fd;
    while ((fd = open("/dev/null", O_RDWR)) >= 0 && fd <= 2)
        ;
    if (fd > 2) close(fd);
}

int main(int argc, char **argv)
{
    hold_std_fds();
    if (argc > 1 && !strcmp(argv[1], "run")) return run_one_job(argc, argv);
    /* Before anything else: a SIGTERM in the first milliseconds took the
     * default action (exit 143) instead of a clean stop. */
    sigset_t sigs;
    block_signals(&sigs);
    vx_config cfg;
    int rc = vx_config_load(&cfg, argc, argv);
    if (rc) return rc > 0 ? 0 : 2;
    vx_log_set_level(cfg.log_level);
    g_watchdog = sd_watchdog_enabled(0, &g_watchdog_usec) > 0 && g_watchdog_usec > 0;
    /* Files 0640 and dirs 0750 at most, as the systemd unit's UMask=0027:
     * the writers' own modes (fopen's 0666, OpenVDB's) are no wider then.
     * A stricter umask stays. */
    umask(umask(027) | 027);
    vx_metrics_init(cfg.job_timeout_s);
    if (cfg.list_devices) return list_devices();

    if (fit_fd_limit(&cfg)) return 2;
    fit_holds(&cfg);
    keep_memory(cfg.keep_memory, cfg.pretouch_memory);

    double start = vx_now();
    VX_INFO("voxeld.start", "version=%s pid=%d data_dir=%s workers=%d http_threads=%d", VX_VERSION,
            (int)getpid(), VX_Q(cfg.data_dir), cfg.workers, cfg.http_threads);
    vx_err err;
    vx_err_clear(&err);
    /* A port in use (or a host that does not resolve) fails here, before
     * the journal is replayed and the GL thread starts its queued jobs. */
    if (vx_http_check_listen(&cfg, &err)) {
        VX_ERROR("voxeld.fatal", "stage=http code=%s message=%s", err.code,
                 vx_log_quote((char[600]){0}, 600, err.message));
        return 1;
    }
    vx_blob_conf bc = {
        .url = cfg.blob_store,
        .credentials_file = cfg.blob_credentials,
        .cache_max_bytes = cfg.blob_cache_max_bytes,
        .part_size = cfg.blob_part_size,
        .timeout_s = cfg.blob_timeout_s,
        .retries = cfg.blob_retries ? (int)(cfg.blob_retries > 100 ? 100 : cfg.blob_retries) : -1};
    const vx_blob_ops *bo = vx_blob_backend(cfg.blob_store, &err);
    if (!bo) { /* a bad option: exit 2, said on stderr as the others are */
        vx_log_plain(VX_LOG_ERR, "voxeld: --blob-store: %s\n", err.message);
        VX_ERROR("voxeld.fatal", "stage=store code=%s message=%s", err.code,
                 vx_log_quote((char[600]){0}, 600, err.message));
        return 2;
    }
    vx_store_desc sd = {.results_max_bytes = cfg.results_max_bytes,
                        .results_max_age_s = cfg.results_max_age_s,
                        .blob_ops = bo,
                        .blob_conf = &bc};
    /* A shared store out of reach for now (an S3 server starting beside
     * the replicas): tried again each second for 30 s, as the database
     * is, then given up (the supervisor restarts the daemon). */
    vx_store *store;
    for (double give_up = vx_mono() + 30;;) {
        store = vx_store_open(cfg.data_dir, &sd, &err);
        if (store || err.kind != VX_EUNAVAIL || strcmp(err.code, "blob_store_unreachable") ||
            vx_mono() > give_up)
            break;
        VX_WARN("store.blob_wait", "code=%s message=%s", err.code,
                vx_log_quote((char[600]){0}, 600, err.message));
        int stopped = 0;
        for (int i = 0; i < 20 && !(stopped = startup_stop(NULL, &err) != 0); i++)
            sleep_s(0.05);
        if (stopped) {
            VX_INFO("voxeld.stop", "stage=store reason=signal");
            return 0;
        }
    }
    if (!store) {
        VX_ERROR("voxeld.fatal", "stage=store code=%s message=%s", err.code,
                 vx_log_quote((char[600]){0}, 600, err.message));
        if (!bad_option(&err)) { /* where said (the message has no path: clients see them) */
            int blob = !strncmp(err.code, "blob", 4);
            vx_log_plain(VX_LOG_ERR, "voxeld: %s %s: %s\n", blob ? "blob store" : "data dir",
                         blob ? cfg.blob_store : cfg.data_dir, err.message);
            return 1;
        }
        vx_log_plain(VX_LOG_ERR, "voxeld: --blob-store: %s\n", err.message);
        return 2;
    }
    vx_gl_info refused;
    int soft = cfg.require_gpu && probe_software_gl(&cfg, &refused) == 1;
    vx_jobs *jobs = open_jobs(&cfg, store, !soft, &err);
    if (!jobs) {
        vx_store_close(store);
        if (!strcmp(err.code, "stopped")) return 0;
        return bad_option(&err) ? 2 : 1;
    }
    vx_gl_info gi = soft ? refused : vx_jobs_gl_info(jobs);
    char qr[300], qv[200];
    vx_log_quote(qr, sizeof qr, gi.renderer);
    vx_log_quote(qv, sizeof qv, gi.version);
    if (soft) {
        VX_ERROR("voxeld.gpu_required",
                 "device_kind=%s device_index=%d renderer=%s version=%s action=\"no job runs, "
                 "/readyz answers 503\"",
                 gi.device_kind[0] ? gi.device_kind : "surfaceless", gi.device_index, qr, qv);
        vx_log_plain(
            VX_LOG_ERR,
            "voxeld: --require-gpu: the GL renderer \"%s\" is a software one, so no job will "
            "run and /readyz answers 503 (is the GPU visible to EGL? NVIDIA needs "
            "NVIDIA_DRIVER_CAPABILITIES to include graphics; voxeld --list-egl-devices)\n",
            gi.renderer);
    } else {
        VX_INFO("gl.ready", "device_kind=%s device_index=%d renderer=%s version=%s robust=%d",
                gi.device_kind, gi.device_index, qr, qv, gi.robust);
    }

    vx_http_desc hd = {.cfg = &cfg,
                       .store = store,
                       .jobs = jobs,
                       .start_time = start,
                       .gpu_refused = soft ? &refused : NULL,
                       .gl_alive_at = soft ? NULL : &g_gl_alive_at};
    vx_http *http = vx_http_start(&hd, &err);
    if (!http) {
        VX_ERROR("voxeld.fatal", "stage=http code=%s message=%s", err.code,
                 vx_log_quote((char[600]){0}, 600, err.message));
        vx_jobs_free(jobs);
        vx_store_close(store);
        return 1;
    }
    __atomic_store_n(&g_http, http, __ATOMIC_RELEASE);
    sd_notifyf(0, "READY=1\nSTATUS=serving on %s (port %d), GL: %s%s", cfg.listen,
               vx_http_port(http), gi.renderer,
               soft ? " (software: --require-gpu refuses it, no job runs)" : "");
    VX_INFO("voxeld.ready", "port=%d", vx_http_port(http));

    serve_until_signal(&sigs, store, jobs, soft);

    sd_notify(0, "STOPPING=1");
    start_stop_watchdog(cfg.stop_timeout_s);
    /* VOXELD_TEST_STOP_HANG=1 (tests only): the jobs never stop, as a job
     * stuck where it checks for no stop would not */
    const char *hang = getenv("VOXELD_TEST_STOP_HANG");
    if (hang && atoi(hang) > 0)
        for (;;)
            pause();
    /* Order (issue #2): stop accepting, answer every held request, let the
     * running job finish or go back to the queue, flush the journal. */
    vx_http_quiesce(http);
    vx_jobs_stop(jobs);
    atomic_store(&g_jobs_stopped_at, vx_mono());
    /* answers being sent: the watchdog bounds them, or with none (0 = wait
     * for the job) STOP_ANSWERS_S */
    vx_http_stop(http, STOP_HTTP_GRACE_S, cfg.stop_timeout_s > 0 ? 0 : STOP_ANSWERS_S);
    __atomic_store_n(&g_http, NULL, __ATOMIC_RELEASE);
    __atomic_store_n(&g_jobs, NULL, __ATOMIC_RELEASE);
    vx_jobs_free(jobs);
    vx_store_close(store);
    VX_INFO("voxeld.exit", "status=0");
    return 0;
}
