/* Content-addressed mesh index (store.h); the bytes go through s->ops. */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "mesh/intake.h"
#include "store/store_int.h"
#include "util/fsutil.h"
#include "util/sorted.h"
#include "util/log.h"
#include "util/json.h"

int vx_store_valid_mesh_id(const char *id)
{
    if (!id || strlen(id) != 64) return 0;
    for (int i = 0; i < 64; i++)
        if (!((id[i] >= '0' && id[i] <= '9') || (id[i] >= 'a' && id[i] <= 'f'))) return 0;
    return 1;
}

/* The key of mesh id's file with suffix (".json", ".deleted", ".obj"...). */
static void mesh_key(char *key, size_t n, const char *id, const char *suffix)
{
    snprintf(key, n, "meshes/%s%s", id, suffix);
}

/* The key of mesh id's data file, extension ext. */
static void mesh_data_key(char *key, size_t n, const char *id, const char *ext)
{
    snprintf(key, n, "meshes/%s.%s", id, ext);
}
/* The index's entry i. */
static mesh_entry *mesh_at(vx_store *s, size_t i)
{
    return s->meshes.items[i];
}

/* Index of id in the sorted index, or its insertion point (*found = 0). */
static size_t mesh_find(vx_store *s, const char *id, int *found)
{
    return vx_sorted_find(&s->meshes, id, found);
}

/* Takes meta on success (0), not on failure (-1). The index keeps each
 * mesh's metadata as printed JSON, parsed again for each GET: about 0.6 KB
 * a mesh instead of 3 KB of cJSON nodes. */
static int mesh_insert(vx_store *s, const char *id, const char *ext, cJSON *meta, int deleted)
{
    char *text = NULL;
    if (!deleted && !(text = vx_json_print(meta, 0))) return -1;
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found) {
        free(mesh_at(s, at)->meta);
        mesh_at(s, at)->meta = text;
        cJSON_Delete(meta);
        return 0;
    }
    mesh_entry *e = calloc(1, sizeof *e);
    if (!e) {
        free(text);
        return -1;
    }
    snprintf(e->id, sizeof e->id, "%s", id);
    snprintf(e->ext, sizeof e->ext, "%s", ext);
    e->meta = text;
    e->deleted = deleted;
    if (vx_sorted_insert(&s->meshes, e)) {
        free(text);
        free(e);
        return -1;
    }
    cJSON_Delete(meta);
    if (deleted) s->ndeleted++;
    return 0;
}

/* Removes entry `at` and its files (data, metadata or tombstone). Caller
 * holds the lock and syncs the meshes namespace. With checked, a metadata
 * removal the store did not take (an S3 outage) returns -1 (errno set) and
 * leaves everything; else returns 0. */
static int mesh_remove_locked(vx_store *s, size_t at, int checked)
{
    mesh_entry *e = mesh_at(s, at);
    char key[128];
    /* Metadata first: without it the mesh no longer exists, even if the
     * process dies before the data file is gone (load_meshes cleans up). */
    mesh_key(key, sizeof key, e->id, ".json");
    if (s->ops->remove(s->blob, key) != 0 && checked) return -1;
    mesh_key(key, sizeof key, e->id, ".deleted");
    s->ops->remove(s->blob, key);
    mesh_data_key(key, sizeof key, e->id, e->ext);
    s->ops->remove(s->blob, key);
    VX_INFO("store.mesh_removed", "mesh=%s", e->id);
    free(e->meta);
    if (e->deleted) s->ndeleted--;
    free(vx_sorted_remove_at(&s->meshes, at));
    return 0;
}

static void fsync_meshes_dir(vx_store *s)
{
    s->ops->sync(s->blob, "meshes", NULL);
}

static int hash_fd(int fd, char hex[65]);

/* Mesh id's metadata made anew from its data file (key: the metadata's),
 * read as fmt: 1 when written and indexed (store.metadata_rebuilt), 0
 * when there is no such data file, -1 when it does not read as a mesh
 * (*code: why) or the metadata cannot be written. */
static int rebuild_meta_as(vx_store *s, const char *id, vx_mesh_format fmt, const char *key,
                           const char **code)
{
    const char *ext = vx_intake_format_ext(fmt);
    char mkey[128], mpath[VX_PATH_MAX];
    uint64_t bytes = 0;
    mesh_data_key(mkey, sizeof mkey, id, ext);
    if (s->ops->stat(s->blob, mkey, &bytes, NULL) < 0) return 0;
    vx_err err = {0};
    vx_mesh *m = NULL;
    if (s->ops->path(s->blob, mkey, mpath, sizeof mpath) == 0)
        m = vx_mesh_read_as(mpath, fmt, NULL, &err);
    cJSON *meta = m && vx_intake_check(m, &err) == 0 ? vx_intake_meta(id, fmt, bytes, m) : NULL;
    vx_mesh_free(m);
    char *text = meta ? vx_json_print(meta, 0) : NULL;
    if (!text || s->ops->put_bytes(s->blob, key, text, strlen(text), NULL)) {
        *code = err.code[0] ? err.code : "store_failed";
        free(text);
        cJSON_Delete(meta);
        return -1;
    }
    free(text);
    fsync_meshes_dir(s);
    VX_WARN("store.metadata_rebuilt", "mesh=%s format=%s", id, vx_intake_format_name(fmt));
    if (mesh_insert(s, id, ext, meta, 0)) cJSON_Delete(meta);
    return 1;
}

/* Mesh id's metadata made anew from its data file, whose metadata file
 * (key) does not parse: damaged after the upload was acknowledged (a disk
 * fault, a crash of the file system). The file is read again as the
 * format its extension names, the metadata written over the damaged one
 * (the upload's name is lost). 0, or -1 when no data file reads: then
 * both are kept (nothing acknowledged is deleted) and said at error
 * level. */
static int rebuild_meta(vx_store *s, const char *id, const char *key)
{
    for (vx_mesh_format fmt = VX_MESH_OBJ; fmt <= VX_MESH_OFF; fmt++) { /* every format */
        const char *code = NULL;
        int rc = rebuild_meta_as(s, id, fmt, key, &code);
        if (rc == 0) continue;
        if (rc < 0) {
            char mkey[128];
            mesh_data_key(mkey, sizeof mkey, id, vx_intake_format_ext(fmt));
            VX_ERROR("store.mesh_unrecovered", "mesh=%s data=%s code=%s", id, mkey, code);
            return -1;
        }
        return 0;
    }
    VX_ERROR("store.mesh_unrecovered", "mesh=%s data=none", id);
    return -1;
}

/* A data file DATA/meshes/<id>.<ext> (name) without metadata: a commit cut
 * short before its metadata was written (never acknowledged), or a mesh
 * whose metadata file was lost since (rm, a file system's crash). When the
 * file's SHA-256 is its id and it reads as its format, the metadata is made
 * anew (store.metadata_rebuilt; either way those are bytes an upload
 * checked); else it goes (store.mesh_file_removed). A file that cannot be
 * read stays, said at error level. */
static void adopt_data_file(vx_store *s, const char *id, const char *name)
{
    char key[128], mkey[128], path[VX_PATH_MAX];
    snprintf(key, sizeof key, "meshes/%s", name);
    mesh_key(mkey, sizeof mkey, id, ".json");
    vx_mesh_format fmt = vx_intake_format_of_path(name);
    const char *why = "not_a_mesh_file";
    if (fmt && s->ops->path(s->blob, key, path, sizeof path) == 0) {
        int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
        struct stat st;
        char hex[65] = "";
        int e = 0;
        if (fd < 0 || fstat(fd, &st) != 0 || (S_ISREG(st.st_mode) && hash_fd(fd, hex)))
            e = errno ? errno : EIO;
        if (fd >= 0) close(fd);
        if (e) {
            VX_ERROR("store.unreadable_mesh_file", "mesh=%s path=%s error=%d message=%s", id,
                     VX_Q(path), e, VX_Q(strerror(e)));
            return;
        }
        why = "other_bytes";
        const char *code = NULL;
        if (strcmp(hex, id) == 0) {
            if (rebuild_meta_as(s, id, fmt, mkey, &code) > 0) return;
            why = code ? code : "store_failed";
        }
    }
    VX_INFO("store.mesh_file_removed", "mesh=%s file=%s reason=%s", id, name, why);
    s->ops->remove(s->blob, key);
}

/* One metadata file, DATA/meshes/<id><suffix> (".json", or ".deleted" for a
 * deleted mesh that jobs still held): the entry, when its data file is
 * there. */
static void load_one(vx_store *s, const char *id, const char *suffix)
{
    char key[128], path[VX_PATH_MAX];
    mesh_key(key, sizeof key, id, suffix);
    s->ops->path(s->blob, key, path, sizeof path);
    int deleted = strcmp(suffix, ".deleted") == 0;
    int found;
    mesh_find(s, id, &found);
    if (found) { /* a re-upload of a deleted mesh that was cut short */
        if (deleted) s->ops->remove(s->blob, key);
        return;
    }
    char *text = s->ops->read(s->blob, key, 1 << 20, NULL, NULL);
    cJSON *meta = text ? cJSON_Parse(text) : NULL;
    free(text);
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(meta, "format");
    if (!cJSON_IsString(fmt)) {
        VX_WARN("store.bad_metadata", "path=%s", VX_Q(path));
        cJSON_Delete(meta);
        if (!deleted && !s->ops->shared) rebuild_meta(s, id, key);
        return;
    }
    const char *ext = vx_intake_ext_of_name(fmt->valuestring);
    char mkey[128], mpath[VX_PATH_MAX];
    mesh_data_key(mkey, sizeof mkey, id, ext);
    if (s->ops->stat(s->blob, mkey, NULL, NULL) < 0) {
        int e = errno;
        s->ops->path(s->blob, mkey, mpath, sizeof mpath);
        /* The metadata is written after the data file and removed before
         * it: metadata without its file is damage to an acknowledged mesh,
         * not a commit cut short. It stays indexed, as at run time: 410
         * mesh_damaged (or the read error) until its bytes are uploaded
         * again. A deleted one's tombstone goes (nothing to keep for its
         * jobs); on a shared store it is not indexed (fetched when seen). */
        if (e == ENOENT)
            VX_WARN("store.missing_mesh_file", "mesh=%s path=%s", id, VX_Q(mpath));
        else
            VX_ERROR("store.unreadable_mesh_file", "mesh=%s path=%s error=%d message=%s", id,
                     VX_Q(mpath), e, VX_Q(strerror(e)));
        if (deleted || s->ops->shared) {
            cJSON_Delete(meta);
            if (deleted) s->ops->remove(s->blob, key);
            return;
        }
    }
    if (mesh_insert(s, id, ext, meta, deleted)) cJSON_Delete(meta);
}

typedef struct load_pass {
    vx_store *s;
    int pass;
} load_pass;

static int load_name(const char *name, void *ud)
{
    load_pass *lp = ud;
    char id[65];
    vx_store *s = lp->s;
    /* A staged file (tmp-*) that a crash kept from its rename: no daemon
     * writes in the data dir but this one, which has not started yet. */
    if (lp->pass == 2 && !s->ops->shared && strncmp(name, "tmp-", 4) == 0) {
        char key[128];
        snprintf(key, sizeof key, "meshes/%.100s", name);
        VX_INFO("store.leftover_removed", "file=meshes/%s", name);
        s->ops->remove(s->blob, key);
        return 0;
    }
    const char *dot = strchr(name, '.');
    if (!dot || dot - name != 64) return 0;
    memcpy(id, name, 64);
    id[64] = 0;
    if (!vx_store_valid_mesh_id(id)) return 0;
    int meta = strcmp(dot, ".json") == 0, tomb = strcmp(dot, ".deleted") == 0;
    if (lp->pass == 0 && meta) load_one(lp->s, id, dot);
    if (lp->pass == 1 && tomb) load_one(lp->s, id, dot);
    /* On a shared store these may be another daemon's writes in flight. */
    if (lp->pass == 2 && !meta && !tomb && !s->ops->shared) {
        int found;
        mesh_find(s, id, &found);
        char key[128], mkey[128];
        snprintf(key, sizeof key, "meshes/%.100s", name);
        snprintf(mkey, sizeof mkey, "meshes/%s.json", id);
        if (!vx_intake_format_of_path(name)) {
            /* no data file: a metadata write's temp file (ID.json.tmp.N;
             * one a rebuild above renamed meanwhile is gone) */
            if (s->ops->stat(s->blob, key, NULL, NULL) == 0) {
                VX_INFO("store.leftover_removed", "file=meshes/%s", name);
                s->ops->remove(s->blob, key);
            }
        } else if (!found && s->ops->stat(s->blob, mkey, NULL, NULL) < 0) {
            /* A mesh file without metadata: adopted when its bytes are its
             * id's, else removed. One whose metadata is there but damaged
             * (rebuild_meta could not read it) stays. */
            adopt_data_file(s, id, name);
        }
    }
    return 0;
}

int vx_store_load_meshes(vx_store *s)
{
    /* Pass 0: metadata; 1: tombstones of deleted meshes (vx_store_collect
     * removes those no unfinished job pins); 2: data files without either. */
    for (int pass = 0; pass < 3; pass++) {
        load_pass lp = {s, pass};
        if (s->ops->list(s->blob, "meshes", load_name, &lp)) return -1;
    }
    return 0;
}

/* Upload u has the bytes of deleted mesh `at`, whose file jobs still hold:
 * it becomes a stored mesh again (metadata back, tombstone gone). Caller
 * holds the lock and frees u. */
static int mesh_revive_locked(vx_store *s, size_t at, vx_upload *u, const char *ext,
                              const cJSON *meta, vx_err *err)
{
    mesh_entry *e = mesh_at(s, at);
    char key[128], old[128];
    close(u->fd);
    u->fd = -1;
    if (strcmp(e->ext, ext) != 0) { /* read as another format this time */
        mesh_data_key(old, sizeof old, e->id, e->ext);
        mesh_data_key(key, sizeof key, e->id, ext);
        if (s->ops->put_file(s->blob, u->path, key) != 0)
            return vx_err_set(err, VX_EIO, "store_failed", "cannot store mesh %s: %s", e->id,
                              strerror(errno));
        s->ops->remove(s->blob, old);
        snprintf(e->ext, sizeof e->ext, "%s", ext);
    }
    char *text = vx_json_print(meta, 0);
    char *copy = text ? strdup(text) : NULL;
    mesh_key(key, sizeof key, e->id, ".json");
    int rc = -1;
    if (!text || !copy) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    } else if (s->ops->sync(s->blob, "meshes", NULL) ||
               s->ops->put_bytes(s->blob, key, text, strlen(text), NULL)) {
        vx_err_set(err, VX_EIO, "store_failed", "cannot store the metadata of mesh %s", e->id);
    } else {
        mesh_key(key, sizeof key, e->id, ".deleted");
        s->ops->remove(s->blob, key);
        fsync_meshes_dir(s);
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

/* Moves upload u in as new mesh id: data file (unless in_place: a repair
 * moved it in already), sync, metadata. Caller holds the lock; 0 or -1
 * (the keys are then removed by the caller). */
static int mesh_commit_new_locked(vx_store *s, vx_upload *u, const char *id, const char *ext,
                                  const cJSON *meta, const char *key, const char *mkey,
                                  int in_place, vx_err *err)
{
    close(u->fd);
    u->fd = -1;
    int rc = -1;
    char *text = vx_json_print(meta, 0);
    if (!text) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    } else if (!in_place && s->ops->put_file(s->blob, u->path, key) != 0) {
        int e = errno;
        char path[VX_PATH_MAX];
        s->ops->path(s->blob, key, path, sizeof path);
        /* (a rename in the data dir, an upload to S3: the backend's put) */
        VX_ERROR("store.put_failed", "path=%s errno=%d error=%s", VX_Q(path), e, VX_Q(strerror(e)));
        vx_err_set(err, vx_err_io_kind(e), "store_failed", "cannot store the mesh: %s",
                   strerror(e));
    } else if (s->ops->sync(s->blob, "meshes", err) == 0 &&
               s->ops->put_bytes(s->blob, mkey, text, strlen(text), err) == 0) {
        cJSON *copy = cJSON_Duplicate(meta, 1);
        if (copy && mesh_insert(s, id, ext, copy, 0) == 0)
            rc = 0;
        else {
            cJSON_Delete(copy);
            vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        }
    }
    free(text);
    return rc;
}

/* With a catalog: the bytes of an entry that the catalog's purge (another
 * daemon's) removed: the entry goes, and the upload stores them again. */
static void mesh_drop_purged(vx_store *s, const char *id)
{
    char key[128];
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found) mesh_data_key(key, sizeof key, id, mesh_at(s, at)->ext);
    pthread_mutex_unlock(&s->lock);
    /* (a remote store's stat is a request: not under the lock) */
    if (!found || s->ops->stat(s->blob, key, NULL, NULL) == 0 || errno != ENOENT) return;
    pthread_mutex_lock(&s->lock);
    at = mesh_find(s, id, &found);
    if (found && !mesh_at(s, at)->deleted && !mesh_at(s, at)->pins) {
        VX_INFO("store.mesh_purged_elsewhere", "mesh=%s", id);
        free(mesh_at(s, at)->meta);
        free(vx_sorted_remove_at(&s->meshes, at));
    }
    pthread_mutex_unlock(&s->lock);
}

/* The stat fields that change with a file's bytes, as mesh_entry.checked. */
static void file_version(const struct stat *st, int64_t v[7])
{
    v[0] = (int64_t)st->st_dev;
    v[1] = (int64_t)st->st_ino;
    v[2] = (int64_t)st->st_size;
    v[3] = (int64_t)st->st_mtim.tv_sec;
    v[4] = (int64_t)st->st_mtim.tv_nsec;
    v[5] = (int64_t)st->st_ctim.tv_sec;
    v[6] = (int64_t)st->st_ctim.tv_nsec;
}

/* The hex SHA-256 of open file fd from its start into hex: 0, or -1 (errno). */
static int hash_fd(int fd, char hex[65])
{
    enum { CHUNK = 1 << 20 };
    unsigned char *buf = malloc(CHUNK);
    if (!buf) {
        errno = ENOMEM;
        return -1;
    }
    struct sha256_ctx sha;
    sha256_init(&sha);
    ssize_t got;
    off_t at = 0;
    while ((got = pread(fd, buf, CHUNK, at)) != 0) {
        if (got < 0 && errno == EINTR) continue;
        if (got < 0) break;
        sha256_update(&sha, (size_t)got, buf);
        at += got;
    }
    int e = errno;
    free(buf);
    if (got < 0) {
        errno = e;
        return -1;
    }
    uint8_t digest[SHA256_DIGEST_SIZE];
    sha256_digest(&sha, sizeof digest, digest);
    vx_store_hex(digest, hex);
    return 0;
}

/* The "bytes" of a mesh's metadata text, or -1 (none, or deleted). */
static long long meta_bytes(const char *meta)
{
    cJSON *o = meta ? cJSON_Parse(meta) : NULL;
    const cJSON *b = cJSON_GetObjectItemCaseSensitive(o, "bytes");
    long long n = cJSON_IsNumber(b) && b->valuedouble >= 0 ? (long long)b->valuedouble : -1;
    cJSON_Delete(o);
    return n;
}

/* Records version v of mesh id's file as damaged. */
static void mark_bad(vx_store *s, const char *id, const int64_t v[7])
{
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found) memcpy(mesh_at(s, at)->bad, v, 7 * sizeof *v);
    pthread_mutex_unlock(&s->lock);
}

/* 1 when open file fd holds mesh id's bytes (a regular file whose SHA-256
 * is the id), hashed once per version of the file; 0 when it does not (a
 * size other than the metadata's "bytes" decides unhashed; a version found
 * so is not hashed again); -1 when it cannot be read (errno). v: the
 * version (stat) checked. Checking the open file, not a path, is what
 * makes the bytes served or parsed the ones checked. */
static int mesh_fd_intact(vx_store *s, const char *id, int fd, int64_t v[7])
{
    struct stat st;
    if (fstat(fd, &st) != 0) return -1;
    if (!S_ISREG(st.st_mode)) return 0; /* a directory, FIFO or device */
    file_version(&st, v);
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    int known = found && memcmp(mesh_at(s, at)->checked, v, 7 * sizeof *v) == 0;
    int known_bad = found && memcmp(mesh_at(s, at)->bad, v, 7 * sizeof *v) == 0;
    /* the upload's size, parsed only for a version not yet decided */
    long long bytes = found && !known && !known_bad ? meta_bytes(mesh_at(s, at)->meta) : -1;
    pthread_mutex_unlock(&s->lock);
    if (known) return 1;
    if (known_bad) return 0;
    char hex[65];
    if (bytes >= 0 && (long long)st.st_size != bytes) {
        mark_bad(s, id, v);
        return 0;
    }
    if (hash_fd(fd, hex)) return -1;
    if (strcmp(hex, id) != 0) {
        mark_bad(s, id, v);
        return 0;
    }
    /* the version fstat saw before the hash: one changed since differs */
    pthread_mutex_lock(&s->lock);
    at = mesh_find(s, id, &found);
    if (found) memcpy(mesh_at(s, at)->checked, v, 7 * sizeof *v);
    pthread_mutex_unlock(&s->lock);
    return 1;
}

/* The file at path opened for mesh id if it holds its bytes: the fd, or
 * -1 with *intact 0 (missing or other bytes: damaged) or -1 (errno). A
 * FIFO does not block the open, and is not read. */
static int mesh_open_intact(vx_store *s, const char *id, const char *path, int *intact,
                            int64_t v[7])
{
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        *intact = errno == ENOENT || errno == ENXIO || errno == ELOOP ? 0 : -1;
        return -1;
    }
    *intact = mesh_fd_intact(s, id, fd, v);
    if (*intact == 1) return fd;
    int e = errno;
    close(fd);
    errno = e;
    return -1;
}

/* 1 when the file at path holds mesh id's bytes, 0 when not, -1 (errno). */
static int mesh_file_intact(vx_store *s, const char *id, const char *path)
{
    int64_t v[7];
    int intact, fd = mesh_open_intact(s, id, path, &intact, v);
    if (fd >= 0) close(fd);
    return intact;
}

/* vx_store_mesh_repair; *moved = 1 when the upload's file was moved in. */
static int mesh_repair(vx_store *s, vx_upload *u, const char *id, const char *ext, int *moved,
                       vx_err *err)
{
    char key[128], path[VX_PATH_MAX];
    *moved = 0;
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    /* a deleted mesh read as another format is stored anew by its revival */
    if (found && mesh_at(s, at)->deleted && strcmp(mesh_at(s, at)->ext, ext) != 0) found = 0;
    if (found) mesh_data_key(key, sizeof key, id, mesh_at(s, at)->ext);
    pthread_mutex_unlock(&s->lock);
    /* a blob store out of reach: the bytes are checked on their next use */
    if (!found || s->ops->path(s->blob, key, path, sizeof path)) return 0;
    struct stat before, now;
    int had = stat(path, &before) == 0;
    if (mesh_file_intact(s, id, path) == 1) return 0;
    /* The file is checked outside the lock: a delete in between removed it
     * with its entry, and another upload may have stored it again since.
     * Neither is damage (the upload then commits as usual, its temp file
     * still the caller's): the move goes in under the lock, only while the
     * entry and the file are what was checked. */
    pthread_mutex_lock(&s->lock);
    at = mesh_find(s, id, &found);
    int has = stat(path, &now) == 0;
    if (!found || strcmp(mesh_at(s, at)->ext, ext) != 0 || has != had ||
        (has && (now.st_ino != before.st_ino || now.st_dev != before.st_dev ||
                 now.st_size != before.st_size || now.st_mtim.tv_sec != before.st_mtim.tv_sec ||
                 now.st_mtim.tv_nsec != before.st_mtim.tv_nsec))) {
        pthread_mutex_unlock(&s->lock);
        return 0;
    }
    close(u->fd);
    u->fd = -1;
    struct stat st;
    if (lstat(path, &st) == 0 && S_ISDIR(st.st_mode)) vx_remove_tree(path); /* not renamed over */
    int rc = s->ops->put_file(s->blob, u->path, key);
    int e = errno;
    *moved = rc == 0;
    /* its metadata too, when that went with it (DATA/meshes removed behind
     * the daemon): a restart would find the data file alone */
    char mkey[128], *meta = NULL;
    mesh_key(mkey, sizeof mkey, id, ".json");
    if (rc == 0 && mesh_at(s, at)->meta && s->ops->stat(s->blob, mkey, NULL, NULL) < 0)
        meta = strdup(mesh_at(s, at)->meta);
    pthread_mutex_unlock(&s->lock);
    if (meta && s->ops->put_bytes(s->blob, mkey, meta, strlen(meta), NULL) == 0)
        VX_WARN("store.mesh_metadata_rewritten", "mesh=%s", id);
    free(meta);
    if (rc != 0 || s->ops->sync(s->blob, "meshes", NULL)) {
        if (!rc) e = errno;
        VX_ERROR("store.mesh_repair_failed", "mesh=%s error=%d", id, e);
        return vx_err_set(err, vx_err_io_kind(e), "store_failed", "cannot store mesh %s: %s", id,
                          strerror(e));
    }
    VX_WARN("store.mesh_repaired", "mesh=%s", id);
    return 0;
}

int vx_store_mesh_repair(vx_store *s, vx_upload *u, const char *id, const char *ext, vx_err *err)
{
    int moved;
    return mesh_repair(s, u, id, ext, &moved, err);
}

static int mesh_commit_here(vx_store *s, vx_upload *u, const char *id, const char *ext,
                            const cJSON *meta, int *existed, vx_err *err)
{
    char key[128], mkey[128];
    mesh_data_key(key, sizeof key, id, ext);
    mesh_key(mkey, sizeof mkey, id, ".json");
    *existed = 0;
    if (s->catalog) mesh_drop_purged(s, id);
    int moved;
    if (mesh_repair(s, u, id, ext, &moved, err)) {
        vx_upload_abort(u);
        return -1;
    }
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found && !mesh_at(s, at)->deleted) {
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
    /* A delete between the repair and here: the bytes the repair moved in
     * are the mesh's (its id is their hash) unless the delete took them. */
    struct stat st;
    char path[VX_PATH_MAX];
    int rc = -1;
    if (moved && (s->ops->path(s->blob, key, path, sizeof path) || stat(path, &st) != 0))
        vx_err_set(err, VX_EUNAVAIL, "store_failed",
                   "the mesh was deleted while this upload stored it: send it again");
    else
        rc = mesh_commit_new_locked(s, u, id, ext, meta, key, mkey, moved, err);
    if (rc) { /* under the lock: an upload of the same bytes may commit next */
        s->ops->remove(s->blob, mkey);
        s->ops->remove(s->blob, key);
    }
    pthread_mutex_unlock(&s->lock);
    vx_upload_abort(u);
    return rc;
}

int vx_store_mesh_commit(vx_store *s, vx_upload *u, const char *id, const char *ext,
                         const cJSON *meta, int *existed, vx_err *err)
{
    const vx_mesh_catalog *c = s->catalog;
    if (!c) return mesh_commit_here(s, u, id, ext, meta, existed, err);
    /* The bytes first, then the catalog's row: a mesh the catalog names
     * has its bytes in the store. */
    if (c->lock(c->ud, id, err)) {
        vx_upload_abort(u);
        return -1;
    }
    int here, rc = mesh_commit_here(s, u, id, ext, meta, &here, err);
    if (!rc) rc = c->put(c->ud, id, meta, existed, err);
    c->unlock(c->ud, id);
    return rc;
}
/* On a shared store (file://, s3://) a mesh another daemon committed after
 * this one loaded its index: its metadata is read from the store (outside
 * the lock) and indexed when its data file is there. 1 when id is indexed
 * now (it may have been before), 0 when the store has no such mesh, -1
 * with err (VX_EUNAVAIL, VX_EIO store_failed) when the store cannot say. */
static int mesh_fetch_shared(vx_store *s, const char *id, vx_err *err)
{
    if (!s->ops->shared || !vx_store_valid_mesh_id(id)) return 0;
    pthread_mutex_lock(&s->lock);
    int found;
    mesh_find(s, id, &found);
    pthread_mutex_unlock(&s->lock);
    if (found) return 1;
    char key[128];
    mesh_key(key, sizeof key, id, ".json");
    vx_err rerr;
    vx_err_clear(&rerr);
    char *text = s->ops->read(s->blob, key, 1 << 20, NULL, &rerr);
    if (!text && rerr.kind != VX_ENOTFOUND)
        return vx_err_set(err, rerr.kind == VX_EUNAVAIL ? VX_EUNAVAIL : VX_EIO, "store_failed",
                          "cannot reach mesh %s in the blob store", id);
    cJSON *meta = text ? cJSON_Parse(text) : NULL;
    free(text);
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(meta, "format");
    const char *ext = cJSON_IsString(fmt) ? vx_intake_ext_of_name(fmt->valuestring) : NULL;
    if (!ext) {
        cJSON_Delete(meta);
        return 0;
    }
    /* Metadata without its data file (ENOENT) is a damaged mesh, not a
     * deleted one (a delete removes the metadata first, an upload writes
     * it last): known here, so that opening it says mesh_damaged, as on
     * the replica that stored it (this one said "deleted", 404, and ran a
     * job on it into mesh_not_found). */
    char mkey[128];
    mesh_data_key(mkey, sizeof mkey, id, ext);
    if (s->ops->stat(s->blob, mkey, NULL, NULL) < 0 && errno != ENOENT) {
        int e = errno;
        cJSON_Delete(meta);
        return vx_err_set(err, vx_err_io_kind(e), "store_failed",
                          "cannot reach mesh %s in the blob store: %s", id, strerror(e));
    }
    pthread_mutex_lock(&s->lock);
    mesh_find(s, id, &found);
    int ok = found || mesh_insert(s, id, ext, meta, 0) == 0;
    pthread_mutex_unlock(&s->lock);
    if (found || !ok) cJSON_Delete(meta);
    if (ok && !found) VX_INFO("store.mesh_fetched", "mesh=%s", id);
    return ok;
}

cJSON *vx_store_mesh_meta(vx_store *s, const char *id, vx_err *err)
{
    const vx_mesh_catalog *c = s->catalog;
    if (c) {
        cJSON *meta = NULL;
        int got = vx_store_valid_mesh_id(id) ? c->get(c->ud, id, &meta, err) : 0;
        if (!got) vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
        return got > 0 ? meta : NULL;
    }
    if (mesh_fetch_shared(s, id, err) < 0) return NULL;
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found && mesh_at(s, at)->deleted) found = 0;
    cJSON *copy = found && mesh_at(s, at)->meta ? cJSON_Parse(mesh_at(s, at)->meta) : NULL;
    pthread_mutex_unlock(&s->lock);
    if (!found) vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    return copy;
}

/* The path of mesh id's file into buf, opened and checked: the fd, or -1
 * with err (as vx_store_mesh_path says). */
static int mesh_open_checked(vx_store *s, const char *id, char *buf, size_t n, int64_t v[7],
                             vx_err *err)
{
    if (mesh_fetch_shared(s, id, err) < 0) return -1;
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    char key[128];
    if (found) mesh_data_key(key, sizeof key, id, mesh_at(s, at)->ext);
    pthread_mutex_unlock(&s->lock);
    if (!found) return vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    /* A remote backend fetches its copy here (outside the lock). */
    if (s->ops->path(s->blob, key, buf, n))
        return vx_err_set(err, vx_err_io_kind(errno), "store_failed",
                          "cannot read mesh %.80s from the blob store: %s", id, strerror(errno));
    int intact, fd = mesh_open_intact(s, id, buf, &intact, v);
    if (fd >= 0) return fd;
    if (intact < 0)
        return vx_err_set(err, vx_err_io_kind(errno), "store_failed", "cannot read mesh %.80s: %s",
                          id, strerror(errno));
    VX_ERROR("store.mesh_damaged", "mesh=%s path=%s", id, VX_Q(buf));
    return vx_err_set(err, VX_EGONE, "mesh_damaged",
                      "the stored file of mesh %.80s is missing or not the bytes uploaded; "
                      "upload the mesh again to repair it",
                      id);
}

int vx_store_mesh_path(vx_store *s, const char *id, char *buf, size_t n, vx_err *err)
{
    int64_t v[7];
    int fd = mesh_open_checked(s, id, buf, n, v, err);
    if (fd < 0) return -1;
    close(fd);
    return 0;
}

int vx_store_mesh_open_path(vx_store *s, const char *id, char *buf, size_t n, int64_t version[7],
                            vx_err *err)
{
    return mesh_open_checked(s, id, buf, n, version, err);
}

int vx_store_mesh_still_intact(const char *id, int fd, const int64_t version[7], vx_err *err)
{
    struct stat st;
    int64_t v[7];
    if (fstat(fd, &st) == 0) {
        file_version(&st, v);
        if (memcmp(v, version, sizeof v) == 0) return 0;
    }
    VX_ERROR("store.mesh_damaged", "mesh=%s changed=while_read", id);
    return vx_err_set(err, VX_EGONE, "mesh_damaged",
                      "the stored file of mesh %.80s changed while it was read; "
                      "upload the mesh again to repair it",
                      id);
}

int vx_store_mesh_open(vx_store *s, const char *id, vx_err *err)
{
    char path[VX_PATH_MAX];
    int64_t v[7];
    return mesh_open_checked(s, id, path, sizeof path, v, err);
}

int vx_store_mesh_delete(vx_store *s, const char *id, vx_err *err)
{
    const vx_mesh_catalog *c = s->catalog;
    if (c) return c->remove(c->ud, id, err); /* the bytes stay until the purge */
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (!found || mesh_at(s, at)->deleted) {
        pthread_mutex_unlock(&s->lock);
        return vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    }
    mesh_entry *e = mesh_at(s, at);
    if (e->pins == 0) {
        /* checked: a remove the store did not take (an S3 outage) must not
         * answer 204 for a mesh that comes back */
        if (mesh_remove_locked(s, at, 1) != 0) {
            int e2 = errno;
            pthread_mutex_unlock(&s->lock);
            return vx_err_set(err, vx_err_io_kind(e2), "store_failed",
                              "cannot delete mesh %.80s: %s", id, strerror(e2));
        }
    } else {
        /* Jobs still use it: the metadata becomes a tombstone (the mesh is
         * gone for the API, also after a restart) and the file stays until
         * the last of them finishes. */
        char from[128], to[128];
        mesh_key(from, sizeof from, id, ".json");
        mesh_key(to, sizeof to, id, ".deleted");
        if (s->ops->move(s->blob, from, to) != 0) {
            int e2 = errno;
            pthread_mutex_unlock(&s->lock);
            return vx_err_set(err, vx_err_io_kind(e2), "store_failed",
                              "cannot delete mesh %.80s: %s", id, strerror(e2));
        }
        VX_INFO("store.mesh_deleted", "mesh=%s kept_for_jobs=%d", id, e->pins);
        free(e->meta);
        e->meta = NULL;
        e->deleted = 1;
        s->ndeleted++;
    }
    pthread_mutex_unlock(&s->lock);
    return s->ops->sync(s->blob, "meshes", err);
}

int vx_store_mesh_pin(vx_store *s, const char *id, int deleted_ok, vx_err *err)
{
    if (mesh_fetch_shared(s, id, err) < 0) return -1;
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found && (deleted_ok || !mesh_at(s, at)->deleted))
        mesh_at(s, at)->pins++;
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
    if (found && mesh_at(s, at)->pins > 0 && --mesh_at(s, at)->pins == 0 &&
        mesh_at(s, at)->deleted) {
        mesh_remove_locked(s, at, 0);
        removed = 1;
    }
    pthread_mutex_unlock(&s->lock);
    if (removed) fsync_meshes_dir(s);
}

cJSON *vx_store_mesh_list(vx_store *s, const char *after, int limit, char next[65], vx_err *err)
{
    const vx_mesh_catalog *c = s->catalog;
    if (c) return c->list(c->ud, after, limit, next, err);
    cJSON *arr = cJSON_CreateArray();
    next[0] = 0;
    pthread_mutex_lock(&s->lock);
    size_t i = vx_sorted_after(&s->meshes, after);
    int n = 0;
    size_t last = 0;
    for (; i < s->meshes.n; i++) {
        if (mesh_at(s, i)->deleted) continue;
        if (n == limit) { /* another one after this page */
            if (n > 0) snprintf(next, 65, "%s", mesh_at(s, last)->id);
            break;
        }
        cJSON *m = cJSON_Parse(mesh_at(s, i)->meta);
        if (m) cJSON_AddItemToArray(arr, m);
        last = i;
        n++;
    }
    pthread_mutex_unlock(&s->lock);
    return arr;
}

size_t vx_store_mesh_count(vx_store *s)
{
    const vx_mesh_catalog *c = s->catalog;
    long cn = c ? c->count(c->ud, NULL) : -1;
    if (cn >= 0) return (size_t)cn;
    pthread_mutex_lock(&s->lock);
    size_t n = s->meshes.n - s->ndeleted;
    pthread_mutex_unlock(&s->lock);
    return n;
}

size_t vx_store_collect_meshes_locked(vx_store *s)
{
    size_t meshes = 0;
    for (size_t i = s->meshes.n; i-- > 0;)
        if (mesh_at(s, i)->deleted && mesh_at(s, i)->pins == 0) {
            mesh_remove_locked(s, i, 0);
            meshes++;
        }
    return meshes;
}

int vx_store_mesh_stored(vx_store *s, const char *id)
{
    if (s->catalog) mesh_drop_purged(s, id);
    if (mesh_fetch_shared(s, id, NULL) < 0) return 0;
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    found = found && !mesh_at(s, at)->deleted;
    pthread_mutex_unlock(&s->lock);
    return found;
}

void vx_store_set_catalog(vx_store *s, const vx_mesh_catalog *c)
{
    s->catalog = c;
}

int vx_store_mesh_purge(vx_store *s, const char *id, const char *format)
{
    pthread_mutex_lock(&s->lock);
    int found;
    size_t at = mesh_find(s, id, &found);
    if (found && mesh_at(s, at)->pins) {
        pthread_mutex_unlock(&s->lock);
        return -1;
    }
    char key[128];
    const char *ext = vx_intake_ext_of_name(format);
    /* A removal the store does not take (an s3 outage, a read-only dir)
     * fails the purge: the catalog row stays and the purge is tried again,
     * where the bytes left behind had been cataloged anew at the next start
     * (the deleted mesh back on every replica). */
    /* Metadata first, as mesh_remove_locked: without it no start catalogs
     * the mesh again. A missing object removes as 0. */
    mesh_key(key, sizeof key, id, ".json");
    int rc = s->ops->remove(s->blob, key);
    if (!rc && ext) { /* the catalog's format, whatever this store's entry says */
        mesh_data_key(key, sizeof key, id, ext);
        rc = s->ops->remove(s->blob, key);
    }
    if (!rc && found) mesh_remove_locked(s, at, 0);
    pthread_mutex_unlock(&s->lock);
    if (rc) {
        VX_WARN("store.mesh_purge_failed", "mesh=%s errno=%d", id, errno);
        return -1;
    }
    fsync_meshes_dir(s);
    return 0;
}

cJSON *vx_store_mesh_local(vx_store *s)
{
    cJSON *arr = cJSON_CreateArray();
    pthread_mutex_lock(&s->lock);
    for (size_t i = 0; arr && i < s->meshes.n; i++) {
        if (mesh_at(s, i)->deleted || !mesh_at(s, i)->meta) continue;
        cJSON *m = cJSON_Parse(mesh_at(s, i)->meta);
        if (m && !cJSON_AddItemToArray(arr, m)) cJSON_Delete(m);
    }
    pthread_mutex_unlock(&s->lock);
    return arr;
}
