#include "util/log.h"

#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>

static vx_log_level g_level = VX_LOG_INFO;
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;

/* A child forked while another thread logs (util/child.h) must not inherit
 * the lock held: fork waits for the line in progress. */
static void fork_prepare(void)
{
    pthread_mutex_lock(&g_lock);
}
static void fork_done(void)
{
    pthread_mutex_unlock(&g_lock);
}
__attribute__((constructor)) static void log_atfork(void)
{
    pthread_atfork(fork_prepare, fork_done, fork_done);
}

/* 1 when stderr is the journal's stream (systemd sets JOURNAL_STREAM to its
 * device:inode): then each line starts with its syslog priority, <3> to
 * <7>, which journald takes as the level. Elsewhere (a container runtime,
 * a terminal, a file) the prefix would only be noise. */
static int journal_prefix(void)
{
    static int known = -1;
    int k = __atomic_load_n(&known, __ATOMIC_ACQUIRE);
    if (k >= 0) return k;
    const char *js = getenv("JOURNAL_STREAM");
    unsigned long long dev, ino;
    struct stat st;
    k = js && sscanf(js, "%llu:%llu", &dev, &ino) == 2 && fstat(2, &st) == 0 &&
        (unsigned long long)st.st_dev == dev && (unsigned long long)st.st_ino == ino;
    __atomic_store_n(&known, k, __ATOMIC_RELEASE);
    return k;
}

void vx_log_set_level(vx_log_level level)
{
    g_level = level;
}
vx_log_level vx_log_get_level(void)
{
    return g_level;
}

int vx_log_parse_level(const char *s, vx_log_level *out)
{
    static const struct {
        const char *name;
        vx_log_level level;
    } map[] = {{"error", VX_LOG_ERR},
               {"warn", VX_LOG_WARN},
               {"warning", VX_LOG_WARN},
               {"info", VX_LOG_INFO},
               {"debug", VX_LOG_DEBUG}};
    for (size_t i = 0; i < sizeof map / sizeof map[0]; i++) {
        if (strcasecmp(s, map[i].name) == 0) {
            *out = map[i].level;
            return 0;
        }
    }
    return -1;
}

static const char *level_name(vx_log_level l)
{
    switch (l) {
    case VX_LOG_ERR:
        return "error";
    case VX_LOG_WARN:
        return "warn";
    case VX_LOG_INFO:
        return "info";
    default:
        return "debug";
    }
}

void vx_log(vx_log_level level, const char *event, const char *fmt, ...)
{
    if (level > g_level) return;
    char line[2048];
    struct timespec ts;
    struct tm tm;
    clock_gettime(CLOCK_REALTIME, &ts);
    gmtime_r(&ts.tv_sec, &tm);
    int n = journal_prefix() ? snprintf(line, sizeof line, "<%d>", (int)level) : 0;
    int m = snprintf(line + n, sizeof line - (size_t)n,
                     "ts=%04d-%02d-%02dT%02d:%02d:%02d.%03ldZ level=%s event=%s", tm.tm_year + 1900,
                     tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                     ts.tv_nsec / 1000000, level_name(level), event);
    if (n < 0 || m < 0) return;
    n += m;
    if (fmt && fmt[0] && (size_t)n < sizeof line - 2) {
        line[n++] = ' ';
        va_list ap;
        va_start(ap, fmt);
        int k = vsnprintf(line + n, sizeof line - (size_t)n, fmt, ap);
        va_end(ap);
        if (k > 0) n += k;
    }
    if ((size_t)n >= sizeof line - 1) n = (int)sizeof line - 2;
    /* One message is one line: newlines inside values would split it. */
    for (int i = 0; i < n; i++)
        if (line[i] == '\n' || line[i] == '\r') line[i] = ' ';
    line[n++] = '\n';
    pthread_mutex_lock(&g_lock);
    fwrite(line, 1, (size_t)n, stderr);
    fflush(stderr);
    pthread_mutex_unlock(&g_lock);
}

int vx_log_rate_ok(vx_log_rate *r, unsigned burst, unsigned *dropped)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    double now = (double)ts.tv_sec + ts.tv_nsec * 1e-9;
    pthread_mutex_lock(&r->lock);
    *dropped = 0;
    if (now - r->window >= 1.0) {
        *dropped = r->dropped;
        r->window = now;
        r->shown = r->dropped = 0;
    }
    int show = r->shown < burst;
    if (show)
        r->shown++;
    else
        r->dropped++;
    pthread_mutex_unlock(&r->lock);
    return show;
}

const char *vx_log_quote(char *buf, unsigned long size, const char *s)
{
    if (!s) s = "";
    int bare = s[0] != 0;
    for (const char *p = s; *p; p++)
        if (*p == ' ' || *p == '"' || *p == '=' || *p == '\\' || (unsigned char)*p < 0x20) bare = 0;
    if (bare) {
        snprintf(buf, size, "%s", s);
        return buf;
    }
    size_t o = 0;
    if (size < 3) {
        if (size) buf[0] = 0;
        return buf;
    }
    buf[o++] = '"';
    for (const char *p = s; *p && o + 3 < size; p++) {
        if (*p == '"' || *p == '\\') buf[o++] = '\\';
        buf[o++] = ((unsigned char)*p < 0x20) ? ' ' : *p;
    }
    buf[o++] = '"';
    buf[o] = 0;
    return buf;
}
