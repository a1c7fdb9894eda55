#include "util/fsutil.h"

#include <dirent.h>
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include "util/log.h"

/* Logs the path (operators need it) and fills err without it (clients must
 * not see server paths); the kind follows errno (ENOSPC: VX_ENOSPC). */
static int io_fail(vx_err *err, const char *code, const char *op, const char *path)
{
    int e = errno;
    char q[600], r[200];
    VX_WARN("fs.failed", "op=%s path=%s error=%d reason=%s", op, vx_log_quote(q, sizeof q, path), e,
            vx_log_quote(r, sizeof r, strerror(e)));
    vx_err_set(err, vx_err_io_kind(e), code, "%s failed: %s", op, strerror(e));
    errno = e; /* for the caller, after the log's own calls */
    return -1;
}

int vx_mkdirs(const char *path, vx_err *err)
{
    char buf[VX_PATH_MAX];
    if (snprintf(buf, sizeof buf, "%s", path) >= (int)sizeof buf)
        return vx_err_set(err, VX_EIO, "path_too_long", "a configured path is too long");
    for (char *p = buf + 1; *p; p++) {
        if (*p != '/') continue;
        *p = 0;
        if (mkdir(buf, 0750) != 0 && errno != EEXIST) return io_fail(err, "io_error", "mkdir", buf);
        *p = '/';
    }
    if (mkdir(buf, 0750) != 0 && errno != EEXIST) return io_fail(err, "io_error", "mkdir", buf);
    return 0;
}

int vx_mkdir_again(const char *dir)
{
    if (errno != ENOENT) return 0;
    if (mkdir(dir, 0750) != 0) {
        if (errno == EEXIST) return 1; /* another request made it meanwhile */
        if (errno != ENOSPC && errno != EDQUOT) errno = ENOENT; /* a full disk stays one */
        return 0;
    }
    char q[600];
    VX_WARN("store.dir_made_again", "path=%s", vx_log_quote(q, sizeof q, dir));
    return 1;
}

int vx_fsync_dir(const char *dir, vx_err *err)
{
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return io_fail(err, "fsync_failed", "open directory", dir);
    int rc = fsync(fd);
    int e = errno;
    close(fd);
    errno = e;
    if (rc != 0) return io_fail(err, "fsync_failed", "fsync directory", dir);
    return 0;
}

int vx_write_atomic(const char *path, const void *data, size_t len, vx_err *err)
{
    char tmp[VX_PATH_MAX], dir[VX_PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s.tmp.%d", path, (int)gettid());
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
    if (fd < 0) return io_fail(err, "write_failed", "create", tmp);
    const char *p = data;
    size_t left = len;
    while (left) {
        ssize_t n = write(fd, p, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            int e = n == 0 ? ENOSPC : errno;
            close(fd);
            unlink(tmp);
            errno = e;
            return io_fail(err, "write_failed", "write", tmp);
        }
        p += n;
        left -= (size_t)n;
    }
    if (fsync(fd) != 0 || close(fd) != 0) {
        int e = errno;
        unlink(tmp);
        errno = e;
        return io_fail(err, "write_failed", "fsync", tmp);
    }
    if (rename(tmp, path) != 0) {
        int e = errno;
        unlink(tmp);
        errno = e;
        return io_fail(err, "write_failed", "rename", path);
    }
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (slash) *slash = 0;
    return vx_fsync_dir(slash ? dir : ".", err);
}

int vx_open_regular(const char *path)
{
    /* O_NONBLOCK: a FIFO in a file's place would block the open until a
     * writer came (start-up hung, deaf to SIGTERM) */
    int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) return -1;
    struct stat st;
    int e = fstat(fd, &st) != 0   ? errno
            : S_ISREG(st.st_mode) ? 0
            : S_ISDIR(st.st_mode) ? EISDIR
                                  : EINVAL;
    if (!e) return fd;
    close(fd);
    errno = e;
    return -1;
}

char *vx_read_file(const char *path, size_t max, size_t *len, vx_err *err)
{
    int fd = vx_open_regular(path);
    if (fd < 0 && (errno == EINVAL || errno == EISDIR)) {
        vx_err_set(err, VX_EIO, "read_failed", "cannot read the file: not a regular file");
        return NULL;
    }
    FILE *f = fd >= 0 ? fdopen(fd, "rb") : NULL;
    if (!f) {
        int e = errno;
        if (fd >= 0) close(fd);
        vx_err_set(err, e == ENOENT ? VX_ENOTFOUND : VX_EIO, "read_failed",
                   "cannot open the file: %s", strerror(e));
        return NULL;
    }
    size_t cap = 4096, n = 0;
    char *buf = malloc(cap);
    while (buf) {
        if (n + 1 >= cap) {
            if (cap > max) {
                free(buf);
                fclose(f);
                vx_err_set(err, VX_ETOOBIG, "file_too_big", "the file is larger than %zu bytes",
                           max);
                return NULL;
            }
            char *nb = realloc(buf, cap * 2);
            if (!nb) break;
            buf = nb;
            cap *= 2;
        }
        size_t r = fread(buf + n, 1, cap - n - 1, f);
        n += r;
        if (r == 0) break;
    }
    int bad = !buf || ferror(f);
    fclose(f);
    if (bad) {
        free(buf);
        vx_err_set(err, VX_EIO, "read_failed", "reading the file failed");
        return NULL;
    }
    buf[n] = 0;
    if (len) *len = n;
    return buf;
}

int vx_remove_tree(const char *path)
{
    DIR *d = opendir(path);
    if (!d) return unlink(path) == 0 || errno == ENOENT ? 0 : -1;
    struct dirent *e;
    int rc = 0;
    while ((e = readdir(d))) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        char sub[VX_PATH_MAX];
        snprintf(sub, sizeof sub, "%s/%s", path, e->d_name);
        if (e->d_type == DT_DIR)
            rc |= vx_remove_tree(sub);
        else if (unlink(sub) != 0)
            rc = -1;
    }
    closedir(d);
    if (rmdir(path) != 0) rc = -1;
    return rc;
}

uint64_t vx_tree_bytes(const char *path)
{
    DIR *d = opendir(path);
    if (!d) return 0;
    uint64_t total = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        char sub[VX_PATH_MAX];
        struct stat st;
        snprintf(sub, sizeof sub, "%s/%s", path, e->d_name);
        if (lstat(sub, &st) != 0) continue;
        if (S_ISDIR(st.st_mode))
            total += vx_tree_bytes(sub);
        else if (S_ISREG(st.st_mode))
            total += (uint64_t)st.st_size;
    }
    closedir(d);
    return total;
}

void vx_rfc3339(double t, char out[32])
{
    /* to the nearest microsecond first: x.356 read back as x.35599999...
     * is still .356 (and within year 0 to 9999) */
    if (!(t >= 0)) t = 0;
    if (t > 253402300799.999) t = 253402300799.999;
    const long long us = llround(t * 1e6);
    time_t s = (time_t)(us / 1000000);
    struct tm tm;
    gmtime_r(&s, &tm);
    int ms = (int)(us % 1000000 / 1000);
    if (ms < 0) ms = 0;
    snprintf(out, 32, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1,
             tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, ms);
}

const char *vx_path_base(const char *path)
{
    const char *s = strrchr(path, '/');
    return s ? s + 1 : path;
}

int vx_parse_size(const char *s, uint64_t *out)
{
    char *end;
    errno = 0;
    /* digits first: strtoull would skip blanks and take a sign (" -1" was
     * 2^64 - 1) */
    if (!s || !isdigit((unsigned char)*s)) return -1;
    unsigned long long v = strtoull(s, &end, 10);
    if (errno || end == s) return -1;
    uint64_t mul = 1;
    switch (*end) {
    case 0:
    case 'B': /* 64B, below */
    case 'b':
        break;
    case 'k':
    case 'K':
        mul = 1ull << 10;
        end++;
        break;
    case 'm':
    case 'M':
        mul = 1ull << 20;
        end++;
        break;
    case 'g':
    case 'G':
        mul = 1ull << 30;
        end++;
        break;
    case 't':
    case 'T':
        mul = 1ull << 40;
        end++;
        break;
    default:
        return -1;
    }
    /* 64KiB, 64KB, 64B, in any case as the K (64kib was refused, 64kB taken) */
    if (mul > 1 && (end[0] == 'i' || end[0] == 'I') && (end[1] == 'B' || end[1] == 'b'))
        end += 2;
    else if (*end == 'B' || *end == 'b')
        end++;
    if (*end) return -1;
    if (v > UINT64_MAX / mul) return -1;
    *out = v * mul;
    return 0;
}

int vx_disk_free(const char *dir, uint64_t *free_bytes)
{
    struct statvfs sv;
    if (statvfs(dir, &sv) != 0) return -1;
    *free_bytes = (uint64_t)sv.f_bavail * (uint64_t)sv.f_frsize;
    return 0;
}

void vx_scrub_path(char *msg, const char *dir)
{
    size_t n = dir ? strlen(dir) : 0;
    while (n > 1 && dir[n - 1] == '/')
        n--;
    if (n < 2) return;
    for (char *p = msg; (p = strstr(p, dir));) {
        size_t cut = n + (p[n] == '/');
        if (strncmp(p, dir, n) != 0) break;
        memmove(p, p + cut, strlen(p + cut) + 1);
    }
}

int vx_write_all(int fd, const void *p, size_t n)
{
    const char *c = p;
    while (n) {
        ssize_t w = write(fd, c, n);
        if (w < 0 && errno == EINTR) continue;
        if (w == 0) errno = ENOSPC;
        if (w <= 0) return -1;
        c += w;
        n -= (size_t)w;
    }
    return 0;
}

int vx_copy_file(const char *src, const char *dst)
{
    int in = open(src, O_RDONLY | O_CLOEXEC);
    if (in < 0) return -1;
    int out = open(dst, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (out < 0) {
        int e = errno;
        close(in);
        errno = e;
        return -1;
    }
    static const char zeros[1 << 16];
    char *buf = malloc(sizeof zeros);
    struct stat st;
    int e = buf && fstat(in, &st) == 0 ? 0 : errno ? errno : ENOMEM;
    off_t at = 0;
    while (!e && at < st.st_size) {
        off_t data = lseek(in, at, SEEK_DATA); /* past a hole: nothing to read */
        if (data < 0 && errno == ENXIO) break; /* a hole to the end */
        if (data > at) at = data;
        ssize_t n = pread(in, buf, sizeof zeros, at);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) e = errno;
        if (n <= 0) break;
        if (memcmp(buf, zeros, (size_t)n) != 0 &&
            (lseek(out, at, SEEK_SET) < 0 || vx_write_all(out, buf, (size_t)n)))
            e = errno;
        at += n;
    }
    if (!e && ftruncate(out, st.st_size) != 0) e = errno;
    if (!e && fsync(out) != 0) e = errno;
    if (close(out) != 0 && !e) e = errno;
    close(in);
    free(buf);
    if (e) {
        unlink(dst);
        errno = e;
        return -1;
    }
    return 0;
}

int vx_write_new(const char *path, const void *data, size_t n)
{
    int fd = open(path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (fd < 0) return -1;
    int e = vx_write_all(fd, data, n) ? errno : 0;
    if (!e && fsync(fd) != 0) e = errno;
    if (close(fd) != 0 && !e) e = errno;
    if (e) {
        unlink(path);
        errno = e;
        return -1;
    }
    return 0;
}
