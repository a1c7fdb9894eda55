/* Blobs: content-addressed large job inputs, kept while pinned (store.h). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "store/store_int.h"
#include "util/log.h"

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

static void blob_key(const char *id, char *buf, size_t n)
{
    snprintf(buf, n, "blobs/%s.json", id);
}

/* Stages the bytes durably in the blobs namespace; messages name no path. */
static int blob_write_tmp(vx_store *s, const void *data, size_t n, char *tmp, size_t tmpn,
                          vx_err *err)
{
    if (s->ops->make_prefix(s->blob, "blobs", NULL))
        return vx_err_set(err, VX_EIO, "store_failed", "cannot make the blob store: %s",
                          strerror(errno));
    if (s->ops->stage(s->blob, "blobs", data, n, tmp, tmpn))
        return vx_err_set(err, vx_err_io_kind(errno), "store_failed",
                          "cannot store the job's inline data: %s", strerror(errno));
    return 0;
}

int vx_store_blob_put(vx_store *s, const void *data, size_t n, char id[65], vx_err *err)
{
    struct sha256_ctx sha;
    uint8_t digest[SHA256_DIGEST_SIZE];
    sha256_init(&sha);
    sha256_update(&sha, n, data);
    sha256_digest(&sha, sizeof digest, digest);
    vx_store_hex(digest, id);
    pthread_mutex_lock(&s->lock);
    blob_entry *e = blob_find_locked(s, id);
    if (e) e->pins++;
    pthread_mutex_unlock(&s->lock);
    if (e) return 0;
    /* Written outside the lock; put into place (or dropped, when a
     * concurrent put of the same bytes won) under it, so that a blob is
     * never removed between its put and its pin. */
    char tmp[VX_PATH_MAX], key[128];
    if (blob_write_tmp(s, data, n, tmp, sizeof tmp, err)) return -1;
    blob_key(id, key, sizeof key);
    int rc = 0;
    pthread_mutex_lock(&s->lock);
    e = blob_find_locked(s, id);
    if (e) {
        e->pins++;
        s->ops->discard(s->blob, tmp);
    } else if (!(e = blob_add_locked(s, id))) {
        s->ops->discard(s->blob, tmp);
        rc = vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    } else if (s->ops->put_file(s->blob, tmp, key) != 0 ||
               s->ops->sync(s->blob, "blobs", NULL) != 0) {
        int e2 = errno;
        s->ops->discard(s->blob, tmp);
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
    char key[128];
    if (!vx_store_valid_mesh_id(id))
        return vx_err_set(err, VX_ENOTFOUND, "blob_not_found", "no blob %.80s", id);
    blob_key(id, key, sizeof key);
    pthread_mutex_lock(&s->lock);
    blob_entry *e = blob_find_locked(s, id);
    if (!e && s->ops->stat(s->blob, key, NULL, NULL) >= 0) e = blob_add_locked(s, id);
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
        char key[128];
        blob_key(id, key, sizeof key);
        /* Content-addressed: on a shared store another daemon's job may
         * hold the same bytes, so they stay. */
        if (!s->ops->shared) s->ops->remove(s->blob, key);
        *e = s->blobs[--s->nblobs];
    }
    pthread_mutex_unlock(&s->lock);
}

char *vx_store_blob_read(vx_store *s, const char *id, size_t *n, vx_err *err)
{
    char key[128];
    if (!vx_store_valid_mesh_id(id)) {
        vx_err_set(err, VX_ENOTFOUND, "blob_not_found", "no blob %.80s", id);
        return NULL;
    }
    blob_key(id, key, sizeof key);
    vx_err e;
    vx_err_clear(&e);
    char *text = s->ops->read(s->blob, key, SIZE_MAX / 4, n, &e);
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

typedef struct collect_ctx {
    vx_store *s;
    size_t blobs;
} collect_ctx;

/* One name under blobs/: removed unless it is a pinned blob. */
static int collect_blob(const char *name, void *ud)
{
    collect_ctx *c = ud;
    char id[65] = "";
    if (strlen(name) == 69 && strcmp(name + 64, ".json") == 0) {
        memcpy(id, name, 64);
        id[64] = 0;
    }
    const blob_entry *b = id[0] ? blob_find_locked(c->s, id) : NULL;
    if (b && b->pins > 0) return 0;
    if (c->s->ops->shared) return 0; /* other daemons' jobs may hold it */
    char key[VX_PATH_MAX];
    snprintf(key, sizeof key, "blobs/%s", name);
    c->s->ops->remove(c->s->blob, key);
    c->blobs++;
    return 0;
}

void vx_store_collect(vx_store *s)
{
    collect_ctx c = {s, 0};
    pthread_mutex_lock(&s->lock);
    size_t meshes = vx_store_collect_meshes_locked(s);
    s->ops->list(s->blob, "blobs", collect_blob, &c);
    pthread_mutex_unlock(&s->lock);
    if (meshes) s->ops->sync(s->blob, "meshes", NULL);
    if (meshes || c.blobs) VX_INFO("store.collected", "meshes=%zu blobs=%zu", meshes, c.blobs);
}

/* The key of the store's id (cluster mode): under blobs/, whose names a
 * shared store never collects. */
#define STORE_ID_KEY "blobs/voxeld-store.id"

int vx_store_id_read(vx_store *s, char out[65], vx_err *err)
{
    vx_err e;
    vx_err_clear(&e);
    size_t n = 0;
    char *text = s->ops->read(s->blob, STORE_ID_KEY, 4096, &n, &e);
    if (!text) {
        if (e.kind == VX_ENOTFOUND) return 0;
        *err = e;
        return -1;
    }
    while (n && (text[n - 1] == '\n' || text[n - 1] == ' '))
        text[--n] = 0;
    snprintf(out, 65, "%s", text);
    free(text);
    return 1;
}

int vx_store_id_write(vx_store *s, const char *id, vx_err *err)
{
    char line[80];
    int n = snprintf(line, sizeof line, "%s\n", id);
    if (s->ops->make_prefix(s->blob, "blobs", err)) return -1;
    return s->ops->put_bytes(s->blob, STORE_ID_KEY, line, (size_t)n, err);
}
