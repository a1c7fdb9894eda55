#include "jobs/journal.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "util/fsutil.h"
#include "util/log.h"

struct vx_journal {
    char path[2048];
    int fd;
    pthread_mutex_t lock;
};

vx_journal *vx_journal_open(const char *path, vx_err *err)
{
    vx_journal *j = calloc(1, sizeof *j);
    if (!j) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    snprintf(j->path, sizeof j->path, "%s", path);
    j->fd = open(path, O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0640);
    if (j->fd < 0) {
        vx_err_set(err, VX_EIO, "journal_failed", "open %s: %s", path, strerror(errno));
        free(j);
        return NULL;
    }
    pthread_mutex_init(&j->lock, NULL);
    return j;
}

void vx_journal_close(vx_journal *j)
{
    if (!j) return;
    if (j->fd >= 0) {
        fdatasync(j->fd);
        close(j->fd);
    }
    pthread_mutex_destroy(&j->lock);
    free(j);
}

long vx_journal_replay(vx_journal *j, void (*fn)(const cJSON *rec, void *ud), void *ud, vx_err *err)
{
    FILE *f = fopen(j->path, "rbe");
    if (!f) return vx_err_set(err, VX_EIO, "journal_failed", "open %s: %s", j->path, strerror(errno));
    char *line = NULL;
    size_t cap = 0;
    ssize_t n;
    long count = 0, lineno = 0;
    while ((n = getline(&line, &cap, f)) > 0) {
        lineno++;
        if (line[n - 1] != '\n') {
            /* Torn tail: written partly before a crash, never acknowledged. */
            VX_WARN("journal.torn_tail", "path=%s line=%ld bytes=%zd", j->path, lineno, n);
            break;
        }
        cJSON *rec = cJSON_Parse(line);
        if (!rec) {
            VX_WARN("journal.bad_record", "path=%s line=%ld", j->path, lineno);
            continue;
        }
        fn(rec, ud);
        cJSON_Delete(rec);
        count++;
    }
    free(line);
    fclose(f);
    return count;
}

static int write_all(int fd, const char *p, size_t n)
{
    while (n) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

int vx_journal_append(vx_journal *j, const cJSON *rec, vx_err *err)
{
    char *text = cJSON_PrintUnformatted(rec);
    if (!text) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    size_t n = strlen(text);
    text[n] = '\n'; /* the NUL goes: we write n + 1 bytes exactly */
    pthread_mutex_lock(&j->lock);
    int rc = write_all(j->fd, text, n + 1);
    if (rc == 0) rc = fdatasync(j->fd);
    int e = errno;
    pthread_mutex_unlock(&j->lock);
    free(text);
    if (rc != 0) {
        VX_ERROR("journal.append_failed", "path=%s error=%d", j->path, e);
        return vx_err_set(err, VX_EIO, "journal_failed", "journal write failed: %s", strerror(e));
    }
    return 0;
}

int vx_journal_compact(vx_journal *j, cJSON *const *recs, size_t n, vx_err *err)
{
    char tmp[2100];
    snprintf(tmp, sizeof tmp, "%s.compact", j->path);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
    if (fd < 0) return vx_err_set(err, VX_EIO, "journal_failed", "open %s: %s", tmp, strerror(errno));
    int rc = 0;
    for (size_t i = 0; i < n && rc == 0; i++) {
        char *text = cJSON_PrintUnformatted(recs[i]);
        if (!text) {
            rc = -1;
            break;
        }
        size_t len = strlen(text);
        text[len] = '\n';
        rc = write_all(fd, text, len + 1);
        free(text);
    }
    if (rc == 0) rc = fsync(fd);
    close(fd);
    if (rc != 0) {
        unlink(tmp);
        return vx_err_set(err, VX_EIO, "journal_failed", "compacting %s failed", j->path);
    }
    pthread_mutex_lock(&j->lock);
    rc = rename(tmp, j->path);
    if (rc == 0) {
        int nfd = open(j->path, O_RDWR | O_APPEND | O_CLOEXEC);
        if (nfd >= 0) {
            close(j->fd);
            j->fd = nfd;
        } else {
            rc = -1;
        }
    }
    pthread_mutex_unlock(&j->lock);
    if (rc != 0) return vx_err_set(err, VX_EIO, "journal_failed", "rename %s failed", tmp);
    char dir[2048];
    snprintf(dir, sizeof dir, "%s", j->path);
    char *slash = strrchr(dir, '/');
    if (slash) *slash = 0;
    return vx_fsync_dir(slash ? dir : ".", err);
}

long vx_journal_size(vx_journal *j)
{
    struct stat st;
    pthread_mutex_lock(&j->lock);
    long n = fstat(j->fd, &st) == 0 ? (long)st.st_size : -1;
    pthread_mutex_unlock(&j->lock);
    return n;
}
