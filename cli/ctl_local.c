/* --local: a private voxeld for one command (ctl.h). It runs on
 * 127.0.0.1, port 0 (any free one), with a temporary data dir; its log is
 * read until the ready line gives the port, then drained by a thread (and
 * its last lines shown if it fails to start). */
#include <errno.h>
#include <ftw.h>
#include <limits.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "ctl.h"

static pid_t g_pid;
static char g_dir[PATH_MAX];
static FILE *g_log;
static pthread_t g_drain;
static int g_draining;
static pthread_mutex_t g_stop_mu = PTHREAD_MUTEX_INITIALIZER;
static const int g_signals[] = {SIGINT, SIGTERM, SIGHUP, SIGQUIT};
static atomic_int g_interrupted;

int ctl_local_interrupted(void)
{
    return atomic_load(&g_interrupted);
}

static void signal_set(sigset_t *set)
{
    sigemptyset(set);
    for (size_t i = 0; i < sizeof g_signals / sizeof g_signals[0]; i++)
        sigaddset(set, g_signals[i]);
}

static void stop_locked(void);

/* Interrupted (Ctrl-C, kill): the private voxeld is stopped and its data
 * dir removed, then the signal ends the process as it would have. The
 * signals are blocked in every other thread and waited for here. */
static void *signal_main(void *arg)
{
    (void)arg;
    sigset_t set;
    signal_set(&set);
    int sig = 0;
    while (sigwait(&set, &sig) != 0)
        ;
    /* The lock is kept to the end: the main thread, which sees its voxeld
     * go and would exit 1, waits in ctl_local_stop until the signal ends
     * the process. */
    atomic_store(&g_interrupted, 1);
    pthread_mutex_lock(&g_stop_mu);
    ctl_cmds_remove_temp(); /* (the handlers of ctl_cmds.c never run here) */
    /* the job dies with its private server: nothing to cancel later */
    static const char msg[] = "\nvoxelctl: interrupted; the private voxeld (--local) and its "
                              "job are stopped\n";
    ssize_t w = write(2, msg, sizeof msg - 1);
    (void)w;
    stop_locked();
    signal(sig, SIG_DFL);
    pthread_sigmask(SIG_UNBLOCK, &set, NULL);
    raise(sig);
    _exit(128 + sig);
}

/* The voxeld to start: $VOXELD_BIN, the one next to this program, or PATH. */
static void find_voxeld(char *out, size_t n)
{
    const char *env = getenv("VOXELD_BIN");
    if (env && *env) {
        snprintf(out, n, "%s", env);
        return;
    }
    char self[PATH_MAX];
    ssize_t k = readlink("/proc/self/exe", self, sizeof self - 1);
    if (k > 0) {
        self[k] = 0;
        char *slash = strrchr(self, '/');
        if (slash) {
            *slash = 0;
            snprintf(out, n, "%s/voxeld", self);
            if (access(out, X_OK) == 0) return;
        }
    }
    snprintf(out, n, "voxeld");
}

static void *drain_main(void *arg)
{
    char line[4096];
    while (fgets(line, sizeof line, g_log))
        ;
    return NULL;
}

static int rm_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw)
{
    remove(path);
    return 0;
}

/* The environment of the private voxeld, made before the fork (the child
 * of a threaded process calls nothing that may lock): the caller's, less
 * what ties a daemon to a service it may run beside: its token file (its
 * own client got 401), blob store, database and config file (the one job
 * went to the shared store and queue), its listener, dirs and name, and
 * systemd's variables (READY=1 and STOPPING=1 of another process went to
 * NOTIFY_SOCKET). Tuning (VOXELD_EGL_DEVICE, VOXELD_MAX_JOB_MEMORY, ...)
 * stays. NULL without memory. */
static char **private_environment(void)
{
    static const char *const service[] = {"NOTIFY_SOCKET=",
                                          "WATCHDOG_USEC=",
                                          "WATCHDOG_PID=",
                                          "LISTEN_FDS=",
                                          "LISTEN_PID=",
                                          "LISTEN_FDNAMES=",
                                          "STATE_DIRECTORY=",
                                          "CACHE_DIRECTORY=",
                                          "JOURNAL_STREAM=",
                                          "VOXELD_CONFIG=",
                                          "VOXELD_TOKEN_FILE=",
                                          "VOXELD_BLOB_STORE=",
                                          "VOXELD_BLOB_CREDENTIALS=",
                                          "VOXELD_DATABASE=",
                                          "VOXELD_REPLICA_NAME=",
                                          "VOXELD_LISTEN=",
                                          "VOXELD_DATA_DIR=",
                                          "VOXELD_CACHE_DIR=",
                                          "VOXELD_REUSE_PORT=",
                                          "VOXELD_CORS_ORIGIN=",
                                          "VOXELD_ALLOWED_HOSTS=",
                                          "VOXELD_LOG_LEVEL="};
    extern char **environ;
    size_t n = 0;
    while (environ && environ[n])
        n++;
    char **env = calloc(n + 1, sizeof *env);
    if (!env) return NULL;
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        int drop = 0;
        for (size_t j = 0; j < sizeof service / sizeof service[0] && !drop; j++)
            drop = !strncmp(environ[i], service[j], strlen(service[j]));
        if (!drop) env[k++] = environ[i];
    }
    return env;
}

int ctl_local_start(ctl *c)
{
    /* Before any thread (libcurl's resolver, the log drain) is made, so
     * every one inherits the blocked signals. */
    sigset_t set;
    pthread_t sig_thread;
    signal_set(&set);
    pthread_sigmask(SIG_BLOCK, &set, NULL);
    if (pthread_create(&sig_thread, NULL, signal_main, NULL) == 0)
        pthread_detach(sig_thread);
    else
        pthread_sigmask(SIG_UNBLOCK, &set, NULL);
    const char *tmp = getenv("TMPDIR");
    snprintf(g_dir, sizeof g_dir, "%s/voxelctl.XXXXXX", tmp && *tmp ? tmp : "/tmp");
    if (!mkdtemp(g_dir)) {
        fprintf(stderr, "voxelctl: cannot make a temporary directory: %s\n", strerror(errno));
        return -1;
    }
    char bin[PATH_MAX], data[PATH_MAX + 8];
    find_voxeld(bin, sizeof bin);
    snprintf(data, sizeof data, "%s/data", g_dir);
    int fds[2];
    char **env = private_environment();
    if (!env || pipe(fds)) {
        free(env);
        return -1;
    }
    g_pid = fork();
    if (g_pid < 0) {
        free(env);
        return -1;
    }
    if (g_pid == 0) {
        pthread_sigmask(SIG_UNBLOCK, &set, NULL); /* exec keeps the mask */
        prctl(PR_SET_PDEATHSIG, SIGTERM);         /* voxelctl killed: so is its voxeld */
        dup2(fds[1], 2);
        close(fds[0]);
        close(fds[1]);
        char *argv[] = {bin,  "--listen",    "127.0.0.1:0", "--data-dir",
                        data, "--log-level", "info",        NULL};
        execvpe(bin, argv, env);
        fprintf(stderr, "voxelctl: cannot run %s: %s\n", bin, strerror(errno));
        _exit(127);
    }
    free(env);
    close(fds[1]);
    g_log = fdopen(fds[0], "r");
    char line[4096], last[8][512];
    int nlast = 0, port = 0;
    while (!port && fgets(line, sizeof line, g_log)) {
        snprintf(last[nlast++ % 8], sizeof last[0], "%s", line);
        const char *p = strstr(line, "event=voxeld.ready");
        if (p && (p = strstr(p, "port="))) port = atoi(p + 5);
    }
    if (!port) {
        fprintf(stderr, "voxelctl: the local voxeld (%s) did not start:\n", bin);
        for (int i = nlast > 8 ? nlast - 8 : 0; i < nlast; i++)
            fprintf(stderr, "  %s", last[i % 8]);
        ctl_local_stop();
        return -1;
    }
    g_draining = pthread_create(&g_drain, NULL, drain_main, NULL) == 0;
    snprintf(c->server, sizeof c->server, "http://127.0.0.1:%d", port);
    c->token[0] = 0;
    return 0;
}

static void stop_locked(void)
{
    if (g_pid > 0) {
        kill(g_pid, SIGTERM);
        int st;
        while (waitpid(g_pid, &st, 0) < 0 && errno == EINTR)
            ;
        g_pid = 0;
    }
    if (g_draining) pthread_join(g_drain, NULL); /* EOF once voxeld is gone */
    g_draining = 0;
    if (g_log) fclose(g_log);
    g_log = NULL;
    if (g_dir[0]) nftw(g_dir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
    g_dir[0] = 0;
}

void ctl_local_stop(void)
{
    pthread_mutex_lock(&g_stop_mu); /* the signal thread and the main one */
    stop_locked();
    pthread_mutex_unlock(&g_stop_mu);
}
