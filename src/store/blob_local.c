/* The POSIX byte stores (blob.h): keys are paths under a root dir, the
 * data dir (local) or a shared dir that other daemons may use too (file). */
#include "store/blob.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <time.h>
#include <sys/stat.h>
#include <unistd.h>

#include "util/fsutil.h"
#include "util/path.h"

struct vx_blob {
    char dir[VX_PATH_MAX];
    char tag[40];     /* staged names: the pid, and on a shared dir a random tag */
    atomic_ulong seq; /* staged names */
};

static vx_blob *root_open(const char *root, int shared, vx_err *err)
{
    vx_blob *b = calloc(1, sizeof *b);
    if (!b) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    if (snprintf(b->dir, sizeof b->dir, "%s", root) >= (int)sizeof b->dir / 2) {
        free(b);
        vx_err_set(err, VX_EIO, "path_too_long", "blob store path too long");
        return NULL;
    }
    /* Two hosts may run daemons with the same pid on one shared dir. */
    uint64_t r = 0;
    if (shared && getrandom(&r, sizeof r, 0) != (ssize_t)sizeof r) r = (uint64_t)time(NULL);
    if (shared)
        snprintf(b->tag, sizeof b->tag, "%lu-%016llx", (unsigned long)getpid(),
                 (unsigned long long)r);
    else
        snprintf(b->tag, sizeof b->tag, "%lu", (unsigned long)getpid());
    return b;
}

static vx_blob *local_open(const char *data_dir, const vx_blob_conf *conf, vx_err *err)
{
    (void)conf;
    return root_open(data_dir, 0, err);
}

/* file:///DIR: DIR must be absolute; it is made when missing. */
static vx_blob *file_open(const char *data_dir, const vx_blob_conf *conf, vx_err *err)
{
    (void)data_dir;
    const char *url = conf ? conf->url : NULL;
    if (!url || strncmp(url, "file://", 7) != 0 || url[7] != '/') {
        vx_err_set(err, VX_EINVAL, "bad_blob_store", "--blob-store file:// needs an absolute dir");
        return NULL;
    }
    if (vx_mkdirs(url + 7, err)) return NULL;
    return root_open(url + 7, 1, err);
}

static void local_close(vx_blob *b)
{
    free(b);
}

static int local_path(vx_blob *b, const char *key, char *buf, size_t n)
{
    if (snprintf(buf, n, "%s/%s", b->dir, key) >= (int)n) {
        errno = ENAMETOOLONG;
        return -1;
    }
    return 0;
}

/* After an ENOENT on path: its dir made again when that dir alone is
 * missing (DATA/meshes removed behind the daemon: vx_mkdir_again). 1 when
 * it is there, so that the caller tries once more. */
static int remake_parent(const char *path)
{
    char dir[VX_PATH_MAX];
    const char *slash = strrchr(path, '/');
    if (errno != ENOENT || !slash || slash == path || (size_t)(slash - path) >= sizeof dir)
        return 0;
    memcpy(dir, path, (size_t)(slash - path));
    dir[slash - path] = 0;
    return vx_mkdir_again(dir);
}

/* DATA/<ns>/tmp-<pid>-<seq>, written and fsync'd. */
static int local_stage(vx_blob *b, const char *ns, const void *data, size_t n, char *tmp,
                       size_t tmpn)
{
    char dir[VX_PATH_MAX];
    if (local_path(b, ns, dir, sizeof dir)) return -1;
    unsigned long seq = atomic_fetch_add(&b->seq, 1) + 1;
    snprintf(tmp, tmpn, "%s/tmp-%s-%lu", dir, b->tag, seq);
    if (vx_write_new(tmp, data, n) == 0) return 0;
    return remake_parent(tmp) ? vx_write_new(tmp, data, n) : -1;
}

static void local_discard(vx_blob *b, const char *tmp)
{
    (void)b;
    unlink(tmp);
}

/* src copied into a staged object beside key (another file system than
 * the data dir's: a shared mount), fsync'd, renamed onto key; src goes. */
static int copy_put(vx_blob *b, const char *src, const char *path)
{
    char tmp[VX_PATH_MAX];
    unsigned long seq = atomic_fetch_add(&b->seq, 1) + 1;
    const char *slash = strrchr(path, '/');
    if (snprintf(tmp, sizeof tmp, "%.*s/tmp-%s-%lu", (int)(slash - path), path, b->tag, seq) >=
        (int)sizeof tmp) {
        errno = ENAMETOOLONG;
        return -1;
    }
    if (vx_copy_file(src, tmp)) return -1;
    if (rename(tmp, path) != 0) {
        int e = errno;
        unlink(tmp);
        errno = e;
        return -1;
    }
    unlink(src);
    return 0;
}

static int local_put_file(vx_blob *b, const char *src, const char *key)
{
    char path[VX_PATH_MAX];
    if (local_path(b, key, path, sizeof path)) return -1;
    if (rename(src, path) == 0 || (remake_parent(path) && rename(src, path) == 0)) return 0;
    return errno == EXDEV ? copy_put(b, src, path) : -1;
}

static int local_put_bytes(vx_blob *b, const char *key, const void *data, size_t n, vx_err *err)
{
    char path[VX_PATH_MAX];
    if (local_path(b, key, path, sizeof path))
        return vx_err_set(err, VX_EIO, "path_too_long", "a path is too long");
    if (vx_write_atomic(path, data, n, err) == 0) return 0;
    return remake_parent(path) ? vx_write_atomic(path, data, n, err) : -1;
}

static char *local_read(vx_blob *b, const char *key, size_t max, size_t *n, vx_err *err)
{
    char path[VX_PATH_MAX];
    if (local_path(b, key, path, sizeof path)) {
        vx_err_set(err, VX_EIO, "path_too_long", "a path is too long");
        return NULL;
    }
    return vx_read_file(path, max, n, err);
}

static int local_stat(vx_blob *b, const char *key, uint64_t *bytes, double *mtime)
{
    char path[VX_PATH_MAX];
    struct stat st;
    if (local_path(b, key, path, sizeof path) || stat(path, &st) != 0) return -1;
    int prefix = S_ISDIR(st.st_mode);
    if (prefix) {
        if (bytes) *bytes = vx_tree_bytes(path);
    } else if (access(path, R_OK) != 0) {
        return -1;
    } else if (bytes) {
        *bytes = (uint64_t)st.st_size;
    }
    if (mtime) *mtime = (double)st.st_mtim.tv_sec + st.st_mtim.tv_nsec * 1e-9;
    return prefix;
}

static int local_touch(vx_blob *b, const char *key)
{
    char path[VX_PATH_MAX];
    if (local_path(b, key, path, sizeof path)) return -1;
    return utimensat(AT_FDCWD, path, NULL, 0) == 0 ? 0 : -1;
}

static int local_move(vx_blob *b, const char *from, const char *to)
{
    char f[VX_PATH_MAX], t[VX_PATH_MAX];
    if (local_path(b, from, f, sizeof f) || local_path(b, to, t, sizeof t)) return -1;
    return rename(f, t) == 0 ? 0 : -1;
}

static int local_remove(vx_blob *b, const char *key)
{
    char path[VX_PATH_MAX];
    if (local_path(b, key, path, sizeof path)) return -1;
    return unlink(path) == 0 || errno == ENOENT ? 0 : -1;
}

static int local_remove_prefix(vx_blob *b, const char *prefix)
{
    char path[VX_PATH_MAX];
    if (local_path(b, prefix, path, sizeof path)) return -1;
    return vx_remove_tree(path);
}

static int local_make_prefix(vx_blob *b, const char *prefix, vx_err *err)
{
    char path[VX_PATH_MAX];
    if (local_path(b, prefix, path, sizeof path))
        return vx_err_set(err, VX_EIO, "path_too_long", "a configured path is too long");
    return vx_mkdirs(path, err);
}

static int local_sync(vx_blob *b, const char *ns, vx_err *err)
{
    char path[VX_PATH_MAX];
    if (local_path(b, ns, path, sizeof path))
        return vx_err_set(err, VX_EIO, "path_too_long", "a path is too long");
    return vx_fsync_dir(path, err);
}

static int local_list(vx_blob *b, const char *ns, int (*fn)(const char *name, void *ud), void *ud)
{
    char path[VX_PATH_MAX];
    if (local_path(b, ns, path, sizeof path)) return -1;
    DIR *d = opendir(path);
    if (!d) return -1;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0) continue;
        if (fn(e->d_name, ud)) break;
    }
    closedir(d);
    return 0;
}

static int local_ping(vx_blob *b)
{
    char path[VX_PATH_MAX];
    if (local_path(b, "meshes", path, sizeof path)) return 0;
    if (access(path, W_OK | X_OK) == 0) return 1;
    /* removed behind the daemon: made again, as an upload would */
    char probe[VX_PATH_MAX + 8];
    snprintf(probe, sizeof probe, "%s/x", path);
    return remake_parent(probe) && access(path, W_OK | X_OK) == 0;
}

#define VX_POSIX_OPS                                                                               \
    .close = local_close, .stage = local_stage, .discard = local_discard,                          \
    .put_file = local_put_file, .put_bytes = local_put_bytes, .read = local_read,                  \
    .stat = local_stat, .touch = local_touch, .move = local_move, .remove = local_remove,          \
    .remove_prefix = local_remove_prefix, .make_prefix = local_make_prefix, .sync = local_sync,    \
    .list = local_list, .path = local_path, .ping = local_ping

const vx_blob_ops vx_blob_local = {.name = "local", .open = local_open, VX_POSIX_OPS};
const vx_blob_ops vx_blob_file = {.name = "file", .shared = 1, .open = file_open, VX_POSIX_OPS};

const vx_blob_ops *vx_blob_backend(const char *url, vx_err *err)
{
    if (!url || !*url) return &vx_blob_local;
    if (strncmp(url, "file://", 7) == 0) return &vx_blob_file;
    if (strncmp(url, "s3://", 5) == 0) return &vx_blob_s3;
    vx_err_set(err, VX_EINVAL, "bad_blob_store",
               "--blob-store takes file:///DIR or s3://BUCKET/PREFIX?endpoint=URL&region=R");
    return NULL;
}
