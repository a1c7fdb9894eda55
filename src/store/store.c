/* Content-addressed mesh store and result budget (store.h). */
#include "store/store.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <nettle/sha2.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include "mesh/intake.h"
#include "util/fsutil.h"
#include "util/log.h"

typedef struct mesh_entry {
    char id[65];
    char ext[8];
    char *meta; /* the metadata as compact JSON text (a fifth of a cJSON tree); NULL once deleted */
    int pins;   /* unfinished jobs using it */
    int deleted; /* gone from the API; the file stays while pinned */
} mesh_entry;

typedef struct blob_entry {
    char id[65];
    int pins;
} blob_entry;

typedef struct result_entry {
    char jid[48];
    uint64_t bytes;
    double last_access; /* wall clock, so it survives restarts via mtime */
} result_entry;

struct vx_store {
    char dir[2048];
    vx_store_desc desc;
    pthread_mutex_t lock;
    mesh_entry *meshes; /* sorted by id */
    size_t nmeshes, capmeshes;
    size_t ndeleted; /* entries of meshes[] that are deleted */
    blob_entry *blobs;
    size_t nblobs, capblobs;
    result_entry *results;
    size_t nresults, capresults;
    uint64_t results_bytes;
    unsigned long upload_seq;
    int lock_fd; /* DATA/voxeld.lock, flock'd for the store's life */
};

struct vx_upload {
    vx_store *s;
    int fd;
    char path[2300];
    struct sha256_ctx sha;
    uint64_t bytes;
    unsigned char head[64];
    size_t nhead;
    char buf[1 << 16]; /* write coalescing: network chunks are small */
    size_t nbuf;
};

int vx_store_valid_mesh_id(const char *id)
{
    if (!id || strlen(id) != 64) return 0;
    for (int i = 0; i < 64; i++)
        if (!((id[i] >= '0' && id[i] <= '9') || (id[i] >= 'a' && id[i] <= 'f'))) return 0;
    return 1;
}

static int valid_jid(const char *s)
{
    size_t n = strlen(s);
    if (n == 0 || n >= sizeof(((result_entry *)0)->jid)) return 0;
    for (size_t i = 0; i < n; i++)
        if (!((s[i] >= '0' && s[i] <= '9') || (s[i] >= 'a' && s[i] <= 'f'))) return 0;
    return 1;
}

/* Binary search: index of id, or the insertion point with *found = 0. */
static size_t mesh_find(vx_store *s, const char *id, int *found)
{
    size_t lo = 0, hi = s->nmeshes;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        int c = strcmp(s->meshes[mid].id, id);
        if (c == 0) {
            *found = 1;
            return mid;
        }
        if (c < 0)
            lo = mid + 1;
        else
            hi = mid;
    }
    *found = 0;
    return lo;
}

/* Takes meta on success (0), not on failure (-1). The index keeps each
 * mesh's metadata as printed JSON, parsed again for each GET: about 0.6 KB
 * a mesh instead of 3 KB of cJSON nodes. */
static int mesh_insert(vx_store *s, const char *id, const char *ext, cJSON *meta, int deleted)
{
    char *text = NULL;
    if (!deleted && !(text = cJSON_PrintUnformatted(meta))) return -1;
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found) {
        free(s->meshes[at].meta);
        s->meshes[at].meta = text;
        cJSON_Delete(meta);
        return 0;
    }
    if (s->nmeshes == s->capmeshes) {
        size_t cap = s->capmeshes ? 2 * s->capmeshes : 64;
        mesh_entry *n = realloc(s->meshes, cap * sizeof *n);
        if (!n) {
            free(text);
            return -1;
        }
        s->meshes = n;
        s->capmeshes = cap;
    }
    memmove(s->meshes + at + 1, s->meshes + at, (s->nmeshes - at) * sizeof *s->meshes);
    mesh_entry *e = &s->meshes[at];
    snprintf(e->id, sizeof e->id, "%s", id);
    snprintf(e->ext, sizeof e->ext, "%s", ext);
    e->meta = text;
    e->pins = 0;
    e->deleted = deleted;
    cJSON_Delete(meta);
    if (deleted) s->ndeleted++;
    s->nmeshes++;
    return 0;
}

/* Removes entry `at` and its files (data, metadata or tombstone). Caller
 * holds the lock and fsyncs the meshes dir. */
static void mesh_remove_locked(vx_store *s, size_t at)
{
    mesh_entry *e = &s->meshes[at];
    char path[2300];
    /* Metadata first: without it the mesh no longer exists, even if the
     * process dies before the data file is gone (load_meshes cleans up). */
    snprintf(path, sizeof path, "%s/meshes/%s.json", s->dir, e->id);
    unlink(path);
    snprintf(path, sizeof path, "%s/meshes/%s.deleted", s->dir, e->id);
    unlink(path);
    snprintf(path, sizeof path, "%s/meshes/%s.%s", s->dir, e->id, e->ext);
    unlink(path);
    VX_INFO("store.mesh_removed", "mesh=%s", e->id);
    free(e->meta);
    if (e->deleted) s->ndeleted--;
    memmove(s->meshes + at, s->meshes + at + 1, (s->nmeshes - at - 1) * sizeof *s->meshes);
    s->nmeshes--;
}

static void fsync_meshes_dir(vx_store *s)
{
    char path[2100];
    snprintf(path, sizeof path, "%s/meshes", s->dir);
    vx_fsync_dir(path, NULL);
}

/* One metadata file, DATA/meshes/<id><suffix> (".json", or ".deleted" for a
 * deleted mesh that jobs still held): the entry, when its data file is
 * there. */
static void load_one(vx_store *s, const char *dir, const char *id, const char *suffix)
{
    char path[2300];
    snprintf(path, sizeof path, "%s/%s%s", dir, id, suffix);
    int deleted = strcmp(suffix, ".deleted") == 0;
    int found;
    mesh_find(s, id, &found);
    if (found) { /* a re-upload of a deleted mesh that was cut short */
        if (deleted) unlink(path);
        return;
    }
    char *text = vx_read_file(path, 1 << 20, NULL, NULL);
    cJSON *meta = text ? cJSON_Parse(text) : NULL;
    free(text);
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(meta, "format");
    if (!cJSON_IsString(fmt)) {
        VX_WARN("store.bad_metadata", "path=%s", path);
        cJSON_Delete(meta);
        return;
    }
    const char *ext = vx_intake_ext_of_name(fmt->valuestring);
    char mpath[2300];
    snprintf(mpath, sizeof mpath, "%s/%s.%s", dir, id, ext);
    if (access(mpath, R_OK) != 0) {
        VX_WARN("store.missing_mesh_file", "path=%s", mpath);
        cJSON_Delete(meta);
        if (deleted) unlink(path);
        return;
    }
    if (mesh_insert(s, id, ext, meta, deleted)) cJSON_Delete(meta);
}

static void load_meshes(vx_store *s)
{
    char dir[2100];
    snprintf(dir, sizeof dir, "%s/meshes", s->dir);
    /* Pass 0: metadata; 1: tombstones of deleted meshes (vx_store_collect
     * removes those no unfinished job pins); 2: data files without either. */
    for (int pass = 0; pass < 3; pass++) {
        DIR *d = opendir(dir);
        if (!d) return;
        struct dirent *e;
        while ((e = readdir(d))) {
            char id[65];
            const char *dot = strchr(e->d_name, '.');
            if (!dot || dot - e->d_name != 64) continue;
            memcpy(id, e->d_name, 64);
            id[64] = 0;
            if (!vx_store_valid_mesh_id(id)) continue;
            int meta = strcmp(dot, ".json") == 0, tomb = strcmp(dot, ".deleted") == 0;
            if (pass == 0 && meta) load_one(s, dir, id, dot);
            if (pass == 1 && tomb) load_one(s, dir, id, dot);
            if (pass == 2 && !meta && !tomb) {
                /* A mesh file without metadata is a commit that never
                 * finished: it was never acknowledged, so it can go. */
                int found;
                mesh_find(s, id, &found);
                if (!found) {
                    char path[2300];
                    snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
                    unlink(path);
                }
            }
        }
        closedir(d);
    }
}

static int result_add_locked(vx_store *s, const char *jid, uint64_t bytes, double t)
{
    for (size_t i = 0; i < s->nresults; i++)
        if (strcmp(s->results[i].jid, jid) == 0) {
            s->results_bytes -= s->results[i].bytes;
            s->results[i].bytes = bytes;
            s->results[i].last_access = t;
            s->results_bytes += bytes;
            return 0;
        }
    if (s->nresults == s->capresults) {
        size_t cap = s->capresults ? 2 * s->capresults : 64;
        result_entry *n = realloc(s->results, cap * sizeof *n);
        if (!n) return -1;
        s->results = n;
        s->capresults = cap;
    }
    result_entry *e = &s->results[s->nresults++];
    snprintf(e->jid, sizeof e->jid, "%s", jid);
    e->bytes = bytes;
    e->last_access = t;
    s->results_bytes += bytes;
    return 0;
}

static void load_results(vx_store *s)
{
    char dir[2100];
    snprintf(dir, sizeof dir, "%s/results", s->dir);
    DIR *d = opendir(dir);
    if (!d) return;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] == '.' || !valid_jid(e->d_name)) continue;
        char path[2300];
        struct stat st;
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (stat(path, &st) != 0 || !S_ISDIR(st.st_mode)) continue;
        double t = (double)st.st_mtim.tv_sec + st.st_mtim.tv_nsec * 1e-9;
        result_add_locked(s, e->d_name, vx_tree_bytes(path), t);
    }
    closedir(d);
}

/* One daemon per data dir: an exclusive flock on DATA/voxeld.lock, held
 * until vx_store_close (or the process dies: the kernel drops it, so a
 * kill -9 never leaves a stale lock). The file holds the owner's pid, for
 * the message a second daemon prints. */
static int lock_dir(vx_store *s, vx_err *err)
{
    char p[2100];
    snprintf(p, sizeof p, "%s/voxeld.lock", s->dir);
    int fd = open(p, O_RDWR | O_CREAT | O_CLOEXEC, 0640);
    if (fd < 0)
        return vx_err_set(err, VX_EIO, "data_dir_lock", "cannot open the lock file %s: %s", p,
                          strerror(errno));
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
        int e = errno;
        char pid[32] = "";
        ssize_t n = pread(fd, pid, sizeof pid - 1, 0);
        close(fd);
        if (n > 0) pid[n] = 0;
        pid[strcspn(pid, "\n")] = 0;
        if (e == EWOULDBLOCK)
            return vx_err_set(
                err, VX_EBUSY, "data_dir_locked",
                "the data dir %s is in use by another voxeld (pid %s): one daemon per data dir",
                s->dir, pid[0] ? pid : "unknown");
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
    if (snprintf(s->dir, sizeof s->dir, "%s", data_dir) >= (int)sizeof s->dir) {
        free(s);
        vx_err_set(err, VX_EIO, "path_too_long", "data dir path too long");
        return NULL;
    }
    if (desc) s->desc = *desc;
    s->lock_fd = -1;
    pthread_mutex_init(&s->lock, NULL);
    static const char *subs[] = {"", "/meshes", "/results", "/tmp"};
    for (size_t i = 0; i < 4; i++) {
        char p[2100];
        snprintf(p, sizeof p, "%s%s", s->dir, subs[i]);
        if (vx_mkdirs(p, err)) {
            vx_store_close(s);
            return NULL;
        }
        if (i == 0 && lock_dir(s, err)) { /* before anything in it is touched */
            vx_store_close(s);
            return NULL;
        }
    }
    char tmp[2100];
    snprintf(tmp, sizeof tmp, "%s/tmp", s->dir);
    vx_remove_tree(tmp);
    if (vx_mkdirs(tmp, err)) {
        vx_store_close(s);
        return NULL;
    }
    load_meshes(s);
    load_results(s);
    VX_INFO("store.open", "dir=%s meshes=%zu results=%zu results_bytes=%llu", s->dir, s->nmeshes,
            s->nresults, (unsigned long long)s->results_bytes);
    return s;
}

void vx_store_close(vx_store *s)
{
    if (!s) return;
    for (size_t i = 0; i < s->nmeshes; i++)
        free(s->meshes[i].meta);
    free(s->meshes);
    free(s->blobs);
    free(s->results);
    pthread_mutex_destroy(&s->lock);
    if (s->lock_fd >= 0) close(s->lock_fd); /* drops the flock */
    free(s);
}

const char *vx_store_dir(const vx_store *s)
{
    return s->dir;
}

int vx_store_writable(vx_store *s)
{
    char p[2200];
    snprintf(p, sizeof p, "%s/tmp/.probe.%d", s->dir, (int)gettid());
    int fd = open(p, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) return 0;
    int ok = write(fd, "x", 1) == 1;
    close(fd);
    unlink(p);
    return ok;
}

/* --- uploads ------------------------------------------------------------ */

vx_upload *vx_upload_begin(vx_store *s, vx_err *err)
{
    vx_upload *u = calloc(1, sizeof *u);
    if (!u) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    pthread_mutex_lock(&s->lock);
    unsigned long seq = ++s->upload_seq;
    pthread_mutex_unlock(&s->lock);
    u->s = s;
    snprintf(u->path, sizeof u->path, "%s/tmp/upload-%lu-%lu", s->dir, (unsigned long)getpid(),
             seq);
    u->fd = open(u->path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (u->fd < 0) {
        int e = errno;
        VX_ERROR("store.upload_create_failed", "path=%s error=%d", u->path, e);
        vx_err_set(err, vx_err_io_kind(e), e == ENOSPC ? "insufficient_storage" : "upload_failed",
                   "cannot store the upload: %s", strerror(e));
        free(u);
        return NULL;
    }
    sha256_init(&u->sha);
    return u;
}

static int upload_flush(vx_upload *u, vx_err *err)
{
    size_t off = 0;
    while (off < u->nbuf) {
        ssize_t n = write(u->fd, u->buf + off, u->nbuf - off);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            int e = n == 0 ? ENOSPC : errno;
            return vx_err_set(err, vx_err_io_kind(e),
                              e == ENOSPC || e == EDQUOT ? "insufficient_storage" : "upload_failed",
                              "cannot store the upload: %s", strerror(e));
        }
        off += (size_t)n;
    }
    u->nbuf = 0;
    return 0;
}

int vx_upload_write(vx_upload *u, const void *data, size_t n, vx_err *err)
{
    const unsigned char *p = data;
    sha256_update(&u->sha, n, p);
    if (u->nhead < sizeof u->head) {
        size_t k = sizeof u->head - u->nhead < n ? sizeof u->head - u->nhead : n;
        memcpy(u->head + u->nhead, p, k);
        u->nhead += k;
    }
    u->bytes += n;
    while (n) {
        size_t k = sizeof u->buf - u->nbuf < n ? sizeof u->buf - u->nbuf : n;
        memcpy(u->buf + u->nbuf, p, k);
        u->nbuf += k;
        p += k;
        n -= k;
        if (u->nbuf == sizeof u->buf && upload_flush(u, err)) return -1;
    }
    return 0;
}

uint64_t vx_upload_bytes(const vx_upload *u)
{
    return u->bytes;
}

const unsigned char *vx_upload_head(const vx_upload *u, size_t *n)
{
    *n = u->nhead;
    return u->head;
}

const char *vx_upload_path(const vx_upload *u)
{
    return u->path;
}

int vx_upload_finish(vx_upload *u, char id[65], vx_err *err)
{
    if (upload_flush(u, err)) return -1;
    if (fsync(u->fd) != 0)
        return vx_err_set(err, vx_err_io_kind(errno),
                          errno == ENOSPC ? "insufficient_storage" : "upload_failed",
                          "cannot store the upload: %s", strerror(errno));
    uint8_t digest[SHA256_DIGEST_SIZE];
    sha256_digest(&u->sha, sizeof digest, digest);
    for (int i = 0; i < SHA256_DIGEST_SIZE; i++)
        sprintf(id + 2 * i, "%02x", digest[i]);
    return 0;
}

void vx_upload_abort(vx_upload *u)
{
    if (!u) return;
    if (u->fd >= 0) close(u->fd);
    unlink(u->path);
    free(u);
}

/* --- meshes ------------------------------------------------------------- */

/* Upload u has the bytes of deleted mesh `at`, whose file jobs still hold:
 * it becomes a stored mesh again (metadata back, tombstone gone). Caller
 * holds the lock and frees u. */
static int mesh_revive_locked(vx_store *s, size_t at, vx_upload *u, const char *ext,
                              const cJSON *meta, vx_err *err)
{
    mesh_entry *e = &s->meshes[at];
    char dir[2100], path[2300], old[2300];
    snprintf(dir, sizeof dir, "%s/meshes", s->dir);
    close(u->fd);
    u->fd = -1;
    if (strcmp(e->ext, ext) != 0) { /* read as another format this time */
        snprintf(old, sizeof old, "%s/%s.%s", dir, e->id, e->ext);
        snprintf(path, sizeof path, "%s/%s.%s", dir, e->id, ext);
        if (rename(u->path, path) != 0)
            return vx_err_set(err, VX_EIO, "store_failed", "cannot store mesh %s: %s", e->id,
                              strerror(errno));
        unlink(old);
        snprintf(e->ext, sizeof e->ext, "%s", ext);
    }
    char *text = cJSON_PrintUnformatted(meta);
    char *copy = text ? strdup(text) : NULL;
    snprintf(path, sizeof path, "%s/%s.json", dir, e->id);
    int rc = -1;
    if (!text || !copy) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    } else if (vx_fsync_dir(dir, NULL) || vx_write_atomic(path, text, strlen(text), NULL)) {
        vx_err_set(err, VX_EIO, "store_failed", "cannot store the metadata of mesh %s", e->id);
    } else {
        snprintf(path, sizeof path, "%s/%s.deleted", dir, e->id);
        unlink(path);
        vx_fsync_dir(dir, NULL);
        e->meta = copy;
        copy = NULL;
        e->deleted = 0;
        s->ndeleted--;
        VX_INFO("store.mesh_revived", "mesh=%s pins=%d", e->id, e->pins);
        rc = 0;
    }
    free(text);
    free(copy);
    return rc;
}

int vx_store_mesh_commit(vx_store *s, vx_upload *u, const char *id, const char *ext,
                         const cJSON *meta, int *existed, vx_err *err)
{
    char dir[2100], path[2300], mpath[2300];
    snprintf(dir, sizeof dir, "%s/meshes", s->dir);
    snprintf(path, sizeof path, "%s/%s.%s", dir, id, ext);
    snprintf(mpath, sizeof mpath, "%s/%s.json", dir, id);
    *existed = 0;
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found && !s->meshes[at].deleted) {
        pthread_mutex_unlock(&s->lock);
        *existed = 1;
        vx_upload_abort(u);
        return 0;
    }
    if (found) { /* deleted, its file kept for jobs: the same bytes again */
        int rc = mesh_revive_locked(s, at, u, ext, meta, err);
        pthread_mutex_unlock(&s->lock);
        vx_upload_abort(u);
        return rc;
    }
    close(u->fd);
    u->fd = -1;
    int rc = -1;
    char *text = cJSON_PrintUnformatted(meta);
    if (!text) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    } else if (rename(u->path, path) != 0) {
        int e = errno;
        VX_ERROR("store.rename_failed", "path=%s error=%d", path, e);
        vx_err_set(err, vx_err_io_kind(e), "store_failed", "cannot store the mesh: %s",
                   strerror(e));
    } else if (vx_fsync_dir(dir, err) == 0 &&
               vx_write_atomic(mpath, text, strlen(text), err) == 0) {
        cJSON *copy = cJSON_Duplicate(meta, 1);
        if (copy && mesh_insert(s, id, ext, copy, 0) == 0)
            rc = 0;
        else {
            cJSON_Delete(copy);
            vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        }
    }
    pthread_mutex_unlock(&s->lock);
    free(text);
    vx_upload_abort(u);
    if (rc) {
        unlink(mpath);
        unlink(path);
    }
    return rc;
}

cJSON *vx_store_mesh_meta(vx_store *s, const char *id, vx_err *err)
{
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found && s->meshes[at].deleted) found = 0;
    cJSON *copy = found && s->meshes[at].meta ? cJSON_Parse(s->meshes[at].meta) : NULL;
    pthread_mutex_unlock(&s->lock);
    if (!found) vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    return copy;
}

int vx_store_mesh_path(vx_store *s, const char *id, char *buf, size_t n, vx_err *err)
{
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found) snprintf(buf, n, "%s/meshes/%s.%s", s->dir, id, s->meshes[at].ext);
    pthread_mutex_unlock(&s->lock);
    if (!found) return vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    return 0;
}

int vx_store_mesh_delete(vx_store *s, const char *id, vx_err *err)
{
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (!found || s->meshes[at].deleted) {
        pthread_mutex_unlock(&s->lock);
        return vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    }
    mesh_entry *e = &s->meshes[at];
    if (e->pins == 0) {
        mesh_remove_locked(s, at);
    } else {
        /* Jobs still use it: the metadata becomes a tombstone (the mesh is
         * gone for the API, also after a restart) and the file stays until
         * the last of them finishes. */
        char from[2300], to[2300];
        snprintf(from, sizeof from, "%s/meshes/%s.json", s->dir, id);
        snprintf(to, sizeof to, "%s/meshes/%s.deleted", s->dir, id);
        if (rename(from, to) != 0) {
            int e2 = errno;
            pthread_mutex_unlock(&s->lock);
            return vx_err_set(err, VX_EIO, "store_failed", "cannot delete mesh %.80s: %s", id,
                              strerror(e2));
        }
        VX_INFO("store.mesh_deleted", "mesh=%s kept_for_jobs=%d", id, e->pins);
        free(e->meta);
        e->meta = NULL;
        e->deleted = 1;
        s->ndeleted++;
    }
    pthread_mutex_unlock(&s->lock);
    char path[2100];
    snprintf(path, sizeof path, "%s/meshes", s->dir);
    return vx_fsync_dir(path, err);
}

int vx_store_mesh_pin(vx_store *s, const char *id, int deleted_ok, vx_err *err)
{
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found && (deleted_ok || !s->meshes[at].deleted))
        s->meshes[at].pins++;
    else
        found = 0;
    pthread_mutex_unlock(&s->lock);
    if (!found) return vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    return 0;
}

void vx_store_mesh_unpin(vx_store *s, const char *id)
{
    pthread_mutex_lock(&s->lock);
    int found, removed = 0;
    size_t at = mesh_find(s, id, &found);
    if (found && s->meshes[at].pins > 0 && --s->meshes[at].pins == 0 && s->meshes[at].deleted) {
        mesh_remove_locked(s, at);
        removed = 1;
    }
    pthread_mutex_unlock(&s->lock);
    if (removed) fsync_meshes_dir(s);
}

cJSON *vx_store_mesh_list(vx_store *s, const char *after, int limit, char next[65])
{
    cJSON *arr = cJSON_CreateArray();
    next[0] = 0;
    pthread_mutex_lock(&s->lock);
    size_t i = 0;
    if (after && *after) {
        int found;
        i = mesh_find(s, after, &found);
        if (found) i++;
    }
    int n = 0;
    size_t last = 0;
    for (; i < s->nmeshes; i++) {
        if (s->meshes[i].deleted) continue;
        if (n == limit) { /* another one after this page */
            if (n > 0) snprintf(next, 65, "%s", s->meshes[last].id);
            break;
        }
        cJSON *m = cJSON_Parse(s->meshes[i].meta);
        if (m) cJSON_AddItemToArray(arr, m);
        last = i;
        n++;
    }
    pthread_mutex_unlock(&s->lock);
    return arr;
}

size_t vx_store_mesh_count(vx_store *s)
{
    pthread_mutex_lock(&s->lock);
    size_t n = s->nmeshes - s->ndeleted;
    pthread_mutex_unlock(&s->lock);
    return n;
}

/* --- blobs -------------------------------------------------------------- */

static blob_entry *blob_find_locked(vx_store *s, const char *id)
{
    for (size_t i = 0; i < s->nblobs; i++)
        if (strcmp(s->blobs[i].id, id) == 0) return &s->blobs[i];
    return NULL;
}

static blob_entry *blob_add_locked(vx_store *s, const char *id)
{
    if (s->nblobs == s->capblobs) {
        size_t cap = s->capblobs ? 2 * s->capblobs : 16;
        blob_entry *n = realloc(s->blobs, cap * sizeof *n);
        if (!n) return NULL;
        s->blobs = n;
        s->capblobs = cap;
    }
    blob_entry *e = &s->blobs[s->nblobs++];
    snprintf(e->id, sizeof e->id, "%s", id);
    e->pins = 0;
    return e;
}

static void blob_path(const vx_store *s, const char *id, char *buf, size_t n)
{
    snprintf(buf, n, "%s/blobs/%s.json", s->dir, id);
}

/* Writes and fsyncs a temp file in DATA/blobs; messages name no path. */
static int blob_write_tmp(vx_store *s, const void *data, size_t n, char *tmp, size_t tmpn,
                          vx_err *err)
{
    char dir[2100];
    snprintf(dir, sizeof dir, "%s/blobs", s->dir);
    if (vx_mkdirs(dir, NULL))
        return vx_err_set(err, VX_EIO, "store_failed", "cannot make the blob store: %s",
                          strerror(errno));
    pthread_mutex_lock(&s->lock);
    unsigned long seq = ++s->upload_seq;
    pthread_mutex_unlock(&s->lock);
    snprintf(tmp, tmpn, "%s/tmp-%lu-%lu", dir, (unsigned long)getpid(), seq);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (fd < 0)
        return vx_err_set(err, vx_err_io_kind(errno), "store_failed",
                          "cannot store the job's inline data: %s", strerror(errno));
    int e = vx_write_all(fd, data, n) ? errno : 0;
    if (!e && fsync(fd) != 0) e = errno;
    if (close(fd) != 0 && !e) e = errno;
    if (e) {
        unlink(tmp);
        return vx_err_set(err, vx_err_io_kind(e), "store_failed",
                          "cannot store the job's inline data: %s", strerror(e));
    }
    return 0;
}

int vx_store_blob_put(vx_store *s, const void *data, size_t n, char id[65], vx_err *err)
{
    struct sha256_ctx sha;
    uint8_t digest[SHA256_DIGEST_SIZE];
    sha256_init(&sha);
    sha256_update(&sha, n, data);
    sha256_digest(&sha, sizeof digest, digest);
    for (int i = 0; i < SHA256_DIGEST_SIZE; i++)
        sprintf(id + 2 * i, "%02x", digest[i]);
    pthread_mutex_lock(&s->lock);
    blob_entry *e = blob_find_locked(s, id);
    if (e) e->pins++;
    pthread_mutex_unlock(&s->lock);
    if (e) return 0;
    /* Written outside the lock; renamed into place (or dropped, when a
     * concurrent put of the same bytes won) under it, so that a blob is
     * never removed between its rename and its pin. */
    char tmp[2300], path[2300], dir[2100];
    if (blob_write_tmp(s, data, n, tmp, sizeof tmp, err)) return -1;
    blob_path(s, id, path, sizeof path);
    snprintf(dir, sizeof dir, "%s/blobs", s->dir);
    int rc = 0;
    pthread_mutex_lock(&s->lock);
    e = blob_find_locked(s, id);
    if (e) {
        e->pins++;
        unlink(tmp);
    } else if (!(e = blob_add_locked(s, id))) {
        unlink(tmp);
        rc = vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    } else if (rename(tmp, path) != 0 || vx_fsync_dir(dir, NULL) != 0) {
        int e2 = errno;
        unlink(tmp);
        s->nblobs--;
        rc = vx_err_set(err, vx_err_io_kind(e2), "store_failed",
                        "cannot store the job's inline data: %s", strerror(e2));
    } else {
        e->pins = 1;
    }
    pthread_mutex_unlock(&s->lock);
    return rc;
}

int vx_store_blob_pin(vx_store *s, const char *id, vx_err *err)
{
    char path[2300];
    if (!vx_store_valid_mesh_id(id))
        return vx_err_set(err, VX_ENOTFOUND, "blob_not_found", "no blob %.80s", id);
    blob_path(s, id, path, sizeof path);
    pthread_mutex_lock(&s->lock);
    blob_entry *e = blob_find_locked(s, id);
    if (!e && access(path, R_OK) == 0) e = blob_add_locked(s, id);
    if (e) e->pins++;
    pthread_mutex_unlock(&s->lock);
    if (!e) return vx_err_set(err, VX_ENOTFOUND, "blob_not_found", "no blob %.80s", id);
    return 0;
}

void vx_store_blob_unpin(vx_store *s, const char *id)
{
    pthread_mutex_lock(&s->lock);
    blob_entry *e = blob_find_locked(s, id);
    if (e && e->pins > 0 && --e->pins == 0) {
        char path[2300];
        blob_path(s, id, path, sizeof path);
        unlink(path);
        *e = s->blobs[--s->nblobs];
    }
    pthread_mutex_unlock(&s->lock);
}

char *vx_store_blob_read(vx_store *s, const char *id, size_t *n, vx_err *err)
{
    char path[2300];
    if (!vx_store_valid_mesh_id(id)) {
        vx_err_set(err, VX_ENOTFOUND, "blob_not_found", "no blob %.80s", id);
        return NULL;
    }
    blob_path(s, id, path, sizeof path);
    vx_err e;
    vx_err_clear(&e);
    char *text = vx_read_file(path, SIZE_MAX / 4, n, &e);
    if (!text) {
        if (e.kind == VX_ENOTFOUND)
            vx_err_set(err, VX_ENOTFOUND, "blob_not_found",
                       "the job's inline data (blob %s) is gone", id);
        else
            vx_err_set(err, VX_EIO, "read_failed", "cannot read the job's inline data (blob %s)",
                       id);
    }
    return text;
}

size_t vx_store_blob_count(vx_store *s)
{
    pthread_mutex_lock(&s->lock);
    size_t n = s->nblobs;
    pthread_mutex_unlock(&s->lock);
    return n;
}

void vx_store_collect(vx_store *s)
{
    size_t meshes = 0, blobs = 0;
    pthread_mutex_lock(&s->lock);
    for (size_t i = s->nmeshes; i-- > 0;)
        if (s->meshes[i].deleted && s->meshes[i].pins == 0) {
            mesh_remove_locked(s, i);
            meshes++;
        }
    char dir[2100];
    snprintf(dir, sizeof dir, "%s/blobs", s->dir);
    DIR *d = opendir(dir);
    struct dirent *e;
    while (d && (e = readdir(d))) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0) continue;
        char id[65] = "";
        if (strlen(e->d_name) == 69 && strcmp(e->d_name + 64, ".json") == 0) {
            memcpy(id, e->d_name, 64);
            id[64] = 0;
        }
        const blob_entry *b = id[0] ? blob_find_locked(s, id) : NULL;
        if (b && b->pins > 0) continue;
        char path[2400];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        unlink(path);
        blobs++;
    }
    if (d) closedir(d);
    pthread_mutex_unlock(&s->lock);
    if (meshes) fsync_meshes_dir(s);
    if (meshes || blobs) VX_INFO("store.collected", "meshes=%zu blobs=%zu", meshes, blobs);
}

/* --- results ------------------------------------------------------------ */

int vx_store_result_dir(vx_store *s, const char *jid, char *buf, size_t n, vx_err *err)
{
    if (!valid_jid(jid)) return vx_err_set(err, VX_EINTERNAL, "bad_job_id", "bad job id");
    snprintf(buf, n, "%s/results/%s", s->dir, jid);
    vx_remove_tree(buf); /* left over from an interrupted earlier attempt */
    pthread_mutex_lock(&s->lock);
    for (size_t i = 0; i < s->nresults; i++)
        if (strcmp(s->results[i].jid, jid) == 0) {
            s->results_bytes -= s->results[i].bytes;
            s->results[i] = s->results[--s->nresults];
            break;
        }
    pthread_mutex_unlock(&s->lock);
    return vx_mkdirs(buf, err);
}

void vx_store_result_added(vx_store *s, const char *jid)
{
    char path[2200];
    snprintf(path, sizeof path, "%s/results/%s", s->dir, jid);
    uint64_t bytes = vx_tree_bytes(path);
    vx_fsync_dir(path, NULL);
    pthread_mutex_lock(&s->lock);
    result_add_locked(s, jid, bytes, vx_now());
    pthread_mutex_unlock(&s->lock);
}

int vx_store_result_file(vx_store *s, const char *jid, const char *file, char *buf, size_t n,
                         vx_err *err)
{
    char dir[2200];
    snprintf(dir, sizeof dir, "%s/results/%s", s->dir, jid);
    pthread_mutex_lock(&s->lock);
    int found = 0;
    for (size_t i = 0; i < s->nresults; i++)
        if (strcmp(s->results[i].jid, jid) == 0) {
            s->results[i].last_access = vx_now();
            found = 1;
            break;
        }
    pthread_mutex_unlock(&s->lock);
    if (!found || access(dir, F_OK) != 0)
        return vx_err_set(err, VX_EGONE, "result_evicted",
                          "the results of job %s were removed by the results budget", jid);
    /* The mtime of the dir carries the LRU order across restarts. */
    utimensat(AT_FDCWD, dir, NULL, 0);
    snprintf(buf, n, "%s/%s", dir, file);
    return 0;
}

void vx_store_result_remove(vx_store *s, const char *jid)
{
    char dir[2200];
    snprintf(dir, sizeof dir, "%s/results/%s", s->dir, jid);
    pthread_mutex_lock(&s->lock);
    for (size_t i = 0; i < s->nresults; i++)
        if (strcmp(s->results[i].jid, jid) == 0) {
            s->results_bytes -= s->results[i].bytes;
            s->results[i] = s->results[--s->nresults];
            break;
        }
    pthread_mutex_unlock(&s->lock);
    vx_remove_tree(dir);
}

int vx_store_results_evict(vx_store *s)
{
    int removed = 0;
    for (;;) {
        char victim[48] = {0};
        double now = vx_now();
        pthread_mutex_lock(&s->lock);
        size_t oldest = (size_t)-1;
        for (size_t i = 0; i < s->nresults; i++)
            if (oldest == (size_t)-1 || s->results[i].last_access < s->results[oldest].last_access)
                oldest = i;
        if (oldest != (size_t)-1) {
            int over_bytes =
                s->desc.results_max_bytes && s->results_bytes > s->desc.results_max_bytes;
            int too_old = s->desc.results_max_age_s > 0 &&
                          now - s->results[oldest].last_access > s->desc.results_max_age_s;
            if (over_bytes || too_old)
                snprintf(victim, sizeof victim, "%s", s->results[oldest].jid);
        }
        pthread_mutex_unlock(&s->lock);
        if (!victim[0]) break;
        VX_INFO("store.evict", "job=%s", victim);
        vx_store_result_remove(s, victim);
        removed++;
    }
    return removed;
}

uint64_t vx_store_results_bytes(vx_store *s)
{
    pthread_mutex_lock(&s->lock);
    uint64_t b = s->results_bytes;
    pthread_mutex_unlock(&s->lock);
    return b;
}
