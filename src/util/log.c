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

void vx_log_plain(vx_log_level level, const char *fmt, ...)
{
    char line[4096];
    int n = journal_prefix() ? snprintf(line, sizeof line, "<%d>", (int)level) : 0;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line + n, sizeof line - (size_t)n, fmt, ap);
    va_end(ap);
    fputs(line, stderr);
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

/* The UTF-8 sequence at p (n bytes left): its length, and its code point
 * in *cp; 0 when it is not valid UTF-8 (overlong, a surrogate, cut). */
static int utf8_at(const unsigned char *p, int n, unsigned *cp)
{
    int len = p[0] >= 0xf0 ? 4 : p[0] >= 0xe0 ? 3 : p[0] >= 0xc0 ? 2 : 0;
    if (!len || len > n || p[0] > 0xf4) return 0;
    unsigned c = p[0] & (0x7fu >> len);
    for (int k = 1; k < len; k++) {
        if ((p[k] & 0xc0) != 0x80) return 0;
        c = c << 6 | (p[k] & 0x3fu);
    }
    static const unsigned min[5] = {0, 0, 0x80, 0x800, 0x10000};
    if (c < min[len] || c > 0x10ffff || (c >= 0xd800 && c <= 0xdfff)) return 0;
    *cp = c;
    return len;
}

/* One message is one line a terminal shows as it is: line ends and tabs
 * become spaces (a value that may hold them is quoted: vx_log_quote); the
 * other controls (C0, DEL: a space there would split a bare value into
 * two fields), bytes that are not UTF-8, C1 controls (NEL, the 8-bit CSI),
 * the line and paragraph separators and the bidi controls (which reorder
 * what a viewer shows) become '?'. In place (never longer); the new
 * length. */
static int clean_line(char *line, int n)
{
    int o = 0;
    for (int i = 0; i < n;) {
        const unsigned char b = (unsigned char)line[i];
        if (b < 0x80) {
            line[o++] = b == '\n' || b == '\r' || b == '\t' ? ' '
                        : b < 0x20 || b == 0x7f             ? '?'
                                                            : (char)b;
            i++;
            continue;
        }
        unsigned c = 0;
        const int len = utf8_at((const unsigned char *)line + i, n - i, &c);
        const int bad = !len || c <= 0x9f || c == 0x061c || c == 0x200e || c == 0x200f ||
                        (c >= 0x2028 && c <= 0x202e) || (c >= 0x2066 && c <= 0x2069);
        if (bad) {
            line[o++] = '?';
            i += len ? len : 1;
        } else {
            for (int k = 0; k < len; k++)
                line[o++] = line[i++];
        }
    }
    return o;
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
    n = clean_line(line, n);
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
