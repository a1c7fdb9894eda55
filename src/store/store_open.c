/* The store's life: open (lock, load the index), close, probes (store.h). */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <unistd.h>

#include "store/store_int.h"
#include "util/fsutil.h"
#include "util/log.h"

/* The refusal of a second daemon, with the owner's pid from the lock file
 * when it is there to read. */
static int locked_by_another(const vx_store *s, int fd, vx_err *err)
{
    char pid[32] = "";
    ssize_t n = fd >= 0 ? pread(fd, pid, sizeof pid - 1, 0) : -1;
    if (n > 0) pid[n] = 0;
    pid[strcspn(pid, "\n")] = 0;
    return vx_err_set(err, VX_EBUSY, "data_dir_locked",
                      "the data dir %s is in use by another voxeld (pid %s): one daemon per data "
                      "dir",
                      s->dir, pid[0] ? pid : "unknown");
}

/* One daemon per data dir: exclusive flocks on the directory itself and on
 * DATA/voxeld.lock, held until vx_store_close (or the process dies: the
 * kernel drops them, so a kill -9 never leaves a stale lock). The file
 * holds the owner's pid, for the message a second daemon prints; the
 * directory's lock holds when the file is deleted (a second daemon had
 * then made a new one and started beside the first). A file system that
 * takes no lock on a directory has the file's alone. */
static int lock_dir(vx_store *s, vx_err *err)
{
    char p[VX_PATH_MAX];
    snprintf(p, sizeof p, "%s/voxeld.lock", s->dir);
    int dfd = open(s->dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0 && flock(dfd, LOCK_EX | LOCK_NB) != 0) {
        int e = errno;
        close(dfd);
        dfd = -1;
        if (e == EWOULDBLOCK) {
            int pfd = open(p, O_RDONLY | O_CLOEXEC);
            locked_by_another(s, pfd, err);
            if (pfd >= 0) close(pfd);
            return -1;
        }
    }
    s->dir_lock_fd = dfd;
    int fd = open(p, O_RDWR | O_CREAT | O_CLOEXEC, 0640);
    if (fd < 0)
        return vx_err_set(err, VX_EIO, "data_dir_lock", "cannot open the lock file %s: %s", p,
                          strerror(errno));
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
        int e = errno;
        if (e == EWOULDBLOCK) locked_by_another(s, fd, err);
        close(fd);
        if (e == EWOULDBLOCK) return -1;
        return vx_err_set(err, VX_EIO, "data_dir_lock", "cannot lock %s: %s", p, strerror(e));
    }
    char pid[32];
    int n = snprintf(pid, sizeof pid, "%d\n", (int)getpid());
    /* Best effort: the lock itself is what counts, and a full disk must not
     * stop the daemon from starting (it then serves reads). */
    if (ftruncate(fd, 0) != 0 || pwrite(fd, pid, (size_t)n, 0) != n)
        VX_WARN("store.lock_pid_unwritten", "error=%d", errno);
    s->lock_fd = fd;
    return 0;
}

vx_store *vx_store_open(const char *data_dir, const vx_store_desc *desc, vx_err *err)
{
    vx_store *s = calloc(1, sizeof *s);
    if (!s) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    vx_sorted_init(&s->meshes, vx_store_entry_id);
    if (snprintf(s->dir, sizeof s->dir, "%s", data_dir) >= (int)sizeof s->dir / 2) {
        free(s);
        vx_err_set(err, VX_EIO, "path_too_long", "data dir path too long");
        return NULL;
    }
    if (desc) s->desc = *desc;
    s->ops = s->desc.blob_ops ? s->desc.blob_ops : &vx_blob_local;
    s->lock_fd = s->dir_lock_fd = -1;
    pthread_mutex_init(&s->lock, NULL);
    /* The dir and its lock before anything in it is touched; then the byte
     * store's namespaces, and DATA/tmp (uploads in flight, always local). */
    if (vx_mkdirs(s->dir, err) || lock_dir(s, err) ||
        !(s->blob = s->ops->open(s->dir, s->desc.blob_conf, err)) ||
        s->ops->make_prefix(s->blob, "meshes", err) ||
        s->ops->make_prefix(s->blob, "results", err)) {
        vx_store_close(s);
        return NULL;
    }
    char tmp[VX_PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s/tmp", s->dir);
    vx_remove_tree(tmp);
    if (vx_mkdirs(tmp, err)) {
        vx_store_close(s);
        return NULL;
    }
    /* A store that cannot be listed would leave this daemon with an empty
     * index it never reloads (and every result answering 410, uncounted by
     * the budget): refuse to start instead. A shared store may be out of
     * reach for now (a supervisor retries); in the data dir it is a
     * meshes/ or results/ that is no directory or not the daemon's to
     * read (chmod 000, a plain file in its place). Both are listed, even
     * when the first fails. */
    const char *unlisted = NULL;
    int e = 0;
    if (vx_store_load_meshes(s)) {
        e = errno;
        unlisted = "meshes";
    }
    if (vx_store_load_results(s) && !unlisted) {
        e = errno;
        unlisted = "results";
    }
    if (unlisted && s->ops->shared) {
        /* a listing that is not there: the bucket (or the shared dir) is */
        vx_err_set(err, vx_err_io_kind(e), "blob_store_unreachable",
                   "cannot list the %s blob store: %s", s->ops->name,
                   e == ENOENT ? "no such bucket or directory (create it first)" : strerror(e));
        vx_store_close(s);
        return NULL;
    }
    if (unlisted) {
        char p[VX_PATH_MAX];
        snprintf(p, sizeof p, "%s/%s", s->dir, unlisted);
        VX_ERROR("store.unlistable", "path=%s error=%d", VX_Q(p), e);
        vx_err_set(err, VX_EIO, "data_dir_unusable",
                   "cannot list %s/%s: %s (it must be a directory the daemon can read and "
                   "write)",
                   s->dir, unlisted, strerror(e));
        vx_store_close(s);
        return NULL;
    }
    VX_INFO("store.open", "dir=%s meshes=%zu results=%zu results_bytes=%llu", VX_Q(s->dir),
            s->meshes.n, s->nresults, (unsigned long long)s->results_bytes);
    return s;
}

void vx_store_close(vx_store *s)
{
    if (!s) return;
    for (size_t i = 0; i < s->meshes.n; i++) {
        mesh_entry *e = s->meshes.items[i];
        free(e->meta);
        free(e);
    }
    vx_sorted_free(&s->meshes);
    free(s->blobs);
    free(s->results);
    if (s->blob) s->ops->close(s->blob);
    pthread_mutex_destroy(&s->lock);
    if (s->lock_fd >= 0) close(s->lock_fd); /* drops the flock */
    if (s->dir_lock_fd >= 0) close(s->dir_lock_fd);
    free(s);
}

const char *vx_store_backend(const vx_store *s)
{
    return s->ops->name;
}

int vx_store_reachable(vx_store *s)
{
    return !s->ops->ping || s->ops->ping(s->blob);
}

const char *vx_store_dir(const vx_store *s)
{
    return s->dir;
}

int store_tmp_again(vx_store *s)
{
    char tmp[VX_PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s/tmp", s->dir);
    return vx_mkdir_again(tmp);
}

int vx_store_writable(vx_store *s)
{
    char p[VX_PATH_MAX];
    snprintf(p, sizeof p, "%s/tmp/.probe.%d", s->dir, (int)gettid());
    int fd = open(p, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0 && store_tmp_again(s)) fd = open(p, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    /* a full disk (or quota) is a writable dir without room: the free
     * space check's to report (507), not a read-only one's (503) */
    if (fd < 0) return errno == ENOSPC || errno == EDQUOT;
    int ok = write(fd, "x", 1) == 1 || errno == ENOSPC || errno == EDQUOT;
    close(fd);
    unlink(p);
    return ok;
}
