/* Store: upload hashing, commit/dedup, metadata, listing, delete, restart,
 * incomplete commits, result budget and LRU eviction, a mesh catalog. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmocka.h>

#include "store/store.h"
#include "util/fsutil.h"

static char dir[256];

static int setup(void **state)
{
    snprintf(dir, sizeof dir, "/tmp/vx-store-XXXXXX");
    return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
    vx_remove_tree(dir);
    return 0;
}

/* Uploads text in small chunks and commits it; returns the id. */
static void put(vx_store *s, const char *text, char id[65], int *existed)
{
    vx_err err;
    vx_upload *u = vx_upload_begin(s, &err);
    assert_non_null(u);
    size_t n = strlen(text);
    for (size_t off = 0; off < n; off += 3)
        assert_int_equal(vx_upload_write(u, text + off, n - off < 3 ? n - off : 3, &err), 0);
    assert_int_equal(vx_upload_finish(u, id, &err), 0);
    cJSON *meta = cJSON_CreateObject();
    cJSON_AddStringToObject(meta, "id", id);
    cJSON_AddStringToObject(meta, "format", "obj");
    assert_int_equal(vx_store_mesh_commit(s, u, id, "obj", meta, existed, &err), 0);
    cJSON_Delete(meta);
}

static void test_hash_commit_dedup(void **state)
{
    vx_err err;
    vx_store *s = vx_store_open(dir, NULL, &err);
    assert_non_null(s);
    char id[65];
    int existed;
    put(s, "abc", id, &existed);
    /* SHA-256("abc"), FIPS 180-2 example */
    assert_string_equal(id, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    assert_int_equal(existed, 0);
    put(s, "abc", id, &existed);
    assert_int_equal(existed, 1);
    assert_int_equal(vx_store_mesh_count(s), 1);
    char path[512];
    assert_int_equal(vx_store_mesh_path(s, id, path, sizeof path, &err), 0);
    char *text = vx_read_file(path, 100, NULL, &err);
    assert_string_equal(text, "abc");
    free(text);
    cJSON *m = vx_store_mesh_meta(s, id, &err);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(m, "id")), id);
    cJSON_Delete(m);
    assert_null(vx_store_mesh_meta(s, "00", &err));
    assert_int_equal(err.kind, VX_ENOTFOUND);
    assert_string_equal(err.code, "mesh_not_found");
    vx_store_close(s);

    /* Reopen: the mesh is still there; an orphan mesh file (commit that
     * never wrote its metadata) and leftover temp uploads are cleaned. */
    char orphan[512], tmpf[512];
    snprintf(orphan, sizeof orphan, "%s/meshes/%064d.obj", dir, 0);
    FILE *f = fopen(orphan, "w");
    fputs("x", f);
    fclose(f);
    snprintf(tmpf, sizeof tmpf, "%s/tmp/upload-1-1", dir);
    f = fopen(tmpf, "w");
    fclose(f);
    s = vx_store_open(dir, NULL, &err);
    assert_int_equal(vx_store_mesh_count(s), 1);
    assert_int_not_equal(access(orphan, F_OK), 0);
    assert_int_not_equal(access(tmpf, F_OK), 0);
    assert_int_equal(vx_store_mesh_delete(s, id, &err), 0);
    assert_int_equal(vx_store_mesh_delete(s, id, &err), -1);
    assert_int_equal(vx_store_mesh_count(s), 0);
    vx_store_close(s);
}

static void test_list_pages(void **state)
{
    vx_err err;
    char sub[300];
    snprintf(sub, sizeof sub, "%s/list", dir);
    vx_store *s = vx_store_open(sub, NULL, &err);
    char id[65], text[32];
    int existed;
    for (int i = 0; i < 7; i++) {
        snprintf(text, sizeof text, "mesh %d", i);
        put(s, text, id, &existed);
    }
    char next[65], after[65] = "", prev[65] = "";
    int total = 0;
    for (int page = 0; page < 10; page++) {
        cJSON *arr = vx_store_mesh_list(s, after[0] ? after : NULL, 3, next, NULL);
        const cJSON *it;
        cJSON_ArrayForEach(it, arr)
        {
            const char *cur = cJSON_GetStringValue(cJSON_GetObjectItem(it, "id"));
            assert_true(strcmp(prev, cur) < 0); /* sorted, no repeats */
            snprintf(prev, sizeof prev, "%s", cur);
            total++;
        }
        cJSON_Delete(arr);
        if (!next[0]) break;
        snprintf(after, sizeof after, "%s", next);
    }
    assert_int_equal(total, 7);
    assert_true(vx_store_valid_mesh_id(prev));
    assert_false(vx_store_valid_mesh_id("ABC"));
    vx_store_close(s);
}

static void write_result(vx_store *s, const char *jid, size_t bytes)
{
    char d[512], p[600];
    vx_err err;
    assert_int_equal(vx_store_result_dir(s, jid, d, sizeof d, &err), 0);
    snprintf(p, sizeof p, "%s/out.bin", d);
    char *buf = calloc(1, bytes);
    assert_int_equal(vx_write_atomic(p, buf, bytes, &err), 0);
    free(buf);
    assert_int_equal(vx_store_result_commit(s, jid, NULL), 0);
}

static void test_results_budget(void **state)
{
    vx_err err;
    char sub[300];
    snprintf(sub, sizeof sub, "%s/res", dir);
    vx_store_desc d = {.results_max_bytes = 2500};
    vx_store *s = vx_store_open(sub, &d, &err);
    write_result(s, "aaaa", 1000);
    usleep(20000);
    write_result(s, "bbbb", 1000);
    usleep(20000);
    char p[600];
    /* Reading aaaa makes bbbb the least recently used. */
    assert_int_equal(vx_store_result_file(s, "aaaa", "out.bin", p, sizeof p, &err), 0);
    usleep(20000);
    write_result(s, "cccc", 1000);
    assert_int_equal(vx_store_results_bytes(s), 3000);
    assert_int_equal(vx_store_results_evict(s), 1);
    assert_int_equal(vx_store_results_bytes(s), 2000);
    assert_int_equal(vx_store_result_file(s, "bbbb", "out.bin", p, sizeof p, &err), -1);
    assert_string_equal(err.code, "result_evicted");
    assert_int_equal(err.kind, VX_EGONE); /* 410, not 404 */
    assert_int_equal(vx_store_result_file(s, "aaaa", "out.bin", p, sizeof p, &err), 0);
    assert_int_equal(vx_store_result_file(s, "cccc", "out.bin", p, sizeof p, &err), 0);
    /* A result over the whole budget is refused and removed, nothing else
     * evicted (it had evicted every other result, then itself). */
    char d2[512];
    assert_int_equal(vx_store_result_dir(s, "dddd", d2, sizeof d2, &err), 0);
    snprintf(p, sizeof p, "%s/out.bin", d2);
    char *big = calloc(1, 3000);
    assert_int_equal(vx_write_atomic(p, big, 3000, &err), 0);
    free(big);
    assert_int_equal(vx_store_result_commit(s, "dddd", &err), -1);
    assert_string_equal(err.code, "result_too_large");
    assert_non_null(strstr(err.message, "3000 bytes"));
    assert_int_not_equal(access(d2, F_OK), 0);
    assert_int_equal(vx_store_results_bytes(s), 2000);
    assert_int_equal(vx_store_results_evict(s), 0);
    vx_store_close(s);
    /* Sizes are found again on open. */
    s = vx_store_open(sub, &d, &err);
    assert_int_equal(vx_store_results_bytes(s), 2000);
    vx_store_close(s);
    /* An age budget of ~0 s evicts everything unused. */
    vx_store_desc aged = {.results_max_age_s = 0.001};
    s = vx_store_open(sub, &aged, &err);
    usleep(5000);
    assert_int_equal(vx_store_results_evict(s), 2);
    assert_int_equal(vx_store_results_bytes(s), 0);
    vx_store_close(s);
}

static void test_upload_abort(void **state)
{
    vx_err err;
    vx_store *s = vx_store_open(dir, NULL, &err);
    vx_upload *u = vx_upload_begin(s, &err);
    char path[2400];
    snprintf(path, sizeof path, "%s", vx_upload_path(u));
    vx_upload_write(u, "DRACO....", 9, &err);
    size_t n;
    const unsigned char *head = vx_upload_head(u, &n);
    assert_int_equal(n, 9);
    assert_memory_equal(head, "DRACO", 5);
    assert_int_equal(vx_upload_bytes(u), 9);
    vx_upload_abort(u);
    assert_int_not_equal(access(path, F_OK), 0);
    assert_true(vx_store_writable(s));
    vx_store_close(s);
}

/* A data dir of its own under dir, for tests that count what is in it. */
static char sub[300];

static int exists(const char *fmt, const char *id)
{
    char p[512];
    snprintf(p, sizeof p, fmt, sub, id);
    return access(p, F_OK) == 0;
}

/* A deleted mesh that jobs pin: gone from the API at once, its file kept
 * (also across a reopen, as a tombstone) until the last unpin or, with no
 * pin left at start, vx_store_collect. The same bytes revive it. */
static void test_pins(void **state)
{
    vx_err err;
    snprintf(sub, sizeof sub, "%s/pins", dir);
    vx_store *s = vx_store_open(sub, NULL, &err);
    assert_non_null(s);
    char a[65], b[65];
    int existed;
    put(s, "v 0 0 0\n", a, &existed);
    put(s, "v 1 1 1\n", b, &existed);
    assert_int_equal(vx_store_mesh_pin(s, a, 0, &err), 0);
    assert_int_equal(vx_store_mesh_pin(s, a, 0, &err), 0);
    assert_int_equal(vx_store_mesh_delete(s, a, &err), 0);
    assert_null(vx_store_mesh_meta(s, a, &err));
    assert_string_equal(err.code, "mesh_not_found");
    assert_int_equal(vx_store_mesh_count(s), 1);
    char next[65];
    cJSON *l = vx_store_mesh_list(s, NULL, 10, next, NULL);
    assert_int_equal(cJSON_GetArraySize(l), 1);
    cJSON_Delete(l);
    assert_int_equal(vx_store_mesh_pin(s, a, 0, &err), -1); /* new jobs: 404 */
    assert_int_equal(vx_store_mesh_delete(s, a, &err), -1);
    char path[2400];
    assert_int_equal(vx_store_mesh_path(s, a, path, sizeof path, &err),
                     0); /* runners still read it */
    assert_true(exists("%s/meshes/%s.obj", a));
    assert_true(exists("%s/meshes/%s.deleted", a));
    assert_false(exists("%s/meshes/%s.json", a));
    vx_store_mesh_unpin(s, a);
    assert_true(exists("%s/meshes/%s.obj", a));
    vx_store_close(s);

    /* Reopen: still deleted, a replay pin (deleted_ok) keeps it; the last
     * unpin removes it. */
    s = vx_store_open(sub, NULL, &err);
    assert_null(vx_store_mesh_meta(s, a, &err));
    assert_int_equal(vx_store_mesh_count(s), 1);
    assert_int_equal(vx_store_mesh_pin(s, a, 0, &err), -1);
    assert_int_equal(vx_store_mesh_pin(s, a, 1, &err), 0);
    vx_store_collect(s);
    assert_true(exists("%s/meshes/%s.obj", a));
    vx_store_mesh_unpin(s, a);
    assert_false(exists("%s/meshes/%s.obj", a));
    assert_false(exists("%s/meshes/%s.deleted", a));
    assert_int_equal(vx_store_mesh_path(s, a, path, sizeof path, &err), -1);

    /* Deleted while pinned, then uploaded again: a mesh again, kept after
     * the unpin. */
    put(s, "v 0 0 0\n", a, &existed);
    assert_int_equal(existed, 0);
    assert_int_equal(vx_store_mesh_pin(s, a, 0, &err), 0);
    assert_int_equal(vx_store_mesh_delete(s, a, &err), 0);
    put(s, "v 0 0 0\n", a, &existed);
    assert_int_equal(existed, 0); /* 201 */
    cJSON *m = vx_store_mesh_meta(s, a, &err);
    assert_non_null(m);
    cJSON_Delete(m);
    assert_false(exists("%s/meshes/%s.deleted", a));
    vx_store_mesh_unpin(s, a);
    assert_true(exists("%s/meshes/%s.obj", a));
    assert_int_equal(vx_store_mesh_count(s), 2);

    /* Deleted while pinned, no pin after a reopen: collect removes it. */
    assert_int_equal(vx_store_mesh_pin(s, b, 0, &err), 0);
    assert_int_equal(vx_store_mesh_delete(s, b, &err), 0);
    vx_store_close(s);
    s = vx_store_open(sub, NULL, &err);
    assert_true(exists("%s/meshes/%s.obj", b));
    vx_store_collect(s);
    assert_false(exists("%s/meshes/%s.obj", b));
    assert_false(exists("%s/meshes/%s.deleted", b));
    /* A delete without pins removes the files at once. */
    assert_int_equal(vx_store_mesh_delete(s, a, &err), 0);
    assert_false(exists("%s/meshes/%s.obj", a));
    assert_false(exists("%s/meshes/%s.json", a));
    assert_int_equal(vx_store_mesh_count(s), 0);
    vx_store_close(s);
}

/* Blobs: content-addressed, durable, one pin per put, removed with the
 * last unpin; after a reopen only what is pinned again survives collect. */
static void test_blobs(void **state)
{
    vx_err err;
    snprintf(sub, sizeof sub, "%s/blobs", dir);
    vx_store *s = vx_store_open(sub, NULL, &err);
    char id[65], id2[65], id3[65];
    assert_int_equal(vx_store_blob_put(s, "abc", 3, id, &err), 0);
    assert_string_equal(id, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    assert_int_equal(vx_store_blob_put(s, "abc", 3, id2, &err), 0);
    assert_string_equal(id, id2);
    assert_int_equal(vx_store_blob_count(s), 1);
    assert_true(exists("%s/blobs/%s.json", id));
    size_t n;
    char *t = vx_store_blob_read(s, id, &n, &err);
    assert_non_null(t);
    assert_int_equal(n, 3);
    assert_string_equal(t, "abc");
    free(t);
    vx_store_blob_unpin(s, id);
    assert_true(exists("%s/blobs/%s.json", id));
    vx_store_blob_unpin(s, id);
    assert_false(exists("%s/blobs/%s.json", id));
    assert_int_equal(vx_store_blob_count(s), 0);
    assert_null(vx_store_blob_read(s, id, &n, &err));
    assert_string_equal(err.code, "blob_not_found");
    assert_null(strstr(err.message, sub)); /* no server path */
    assert_int_equal(vx_store_blob_pin(s, id, &err), -1);

    assert_int_equal(vx_store_blob_put(s, "kept", 4, id, &err), 0);
    assert_int_equal(vx_store_blob_put(s, "dropped", 7, id3, &err), 0);
    vx_store_close(s); /* pins are memory only */
    s = vx_store_open(sub, NULL, &err);
    assert_int_equal(vx_store_blob_pin(s, id, &err), 0);
    vx_store_collect(s);
    assert_true(exists("%s/blobs/%s.json", id));
    assert_false(exists("%s/blobs/%s.json", id3));
    vx_store_blob_unpin(s, id);
    assert_false(exists("%s/blobs/%s.json", id));
    vx_store_close(s);
}

/* A catalog in memory (what cluster mode's vx_meshes is to the store). */
typedef struct fake_catalog {
    char ids[8][65];
    char *meta[8];
    int n, down;
    char calls[64]; /* L lock, P put, U unlock, G get, R remove */
} fake_catalog;

static void called(fake_catalog *f, char c)
{
    size_t n = strlen(f->calls);
    if (n + 1 < sizeof f->calls) f->calls[n] = c;
}

static int fake_find(fake_catalog *f, const char *id)
{
    for (int i = 0; i < f->n; i++)
        if (!strcmp(f->ids[i], id) && f->meta[i]) return i;
    return -1;
}

static int fake_down(fake_catalog *f, vx_err *err)
{
    return f->down ? vx_err_set(err, VX_EUNAVAIL, "database_unavailable", "down") : 0;
}

static int fake_lock(void *ud, const char *id, vx_err *err)
{
    (void)id;
    called(ud, 'L');
    return fake_down(ud, err);
}

static void fake_unlock(void *ud, const char *id)
{
    (void)id;
    called(ud, 'U');
}

static int fake_put(void *ud, const char *id, const cJSON *meta, int *existed, vx_err *err)
{
    fake_catalog *f = ud;
    called(f, 'P');
    if (fake_down(f, err)) return -1;
    *existed = fake_find(f, id) >= 0;
    if (!*existed) {
        snprintf(f->ids[f->n], 65, "%s", id);
        f->meta[f->n++] = cJSON_PrintUnformatted(meta);
    }
    return 0;
}

static int fake_get(void *ud, const char *id, cJSON **meta, vx_err *err)
{
    fake_catalog *f = ud;
    called(f, 'G');
    if (fake_down(f, err)) return -1;
    int i = fake_find(f, id);
    *meta = i >= 0 ? cJSON_Parse(f->meta[i]) : NULL;
    return i >= 0;
}

static int fake_remove(void *ud, const char *id, vx_err *err)
{
    fake_catalog *f = ud;
    called(f, 'R');
    int i = fake_find(f, id);
    if (i < 0) return vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh");
    free(f->meta[i]);
    f->meta[i] = NULL;
    return 0;
}

static cJSON *fake_list(void *ud, const char *after, int limit, char next[65], vx_err *err)
{
    fake_catalog *f = ud;
    (void)after, (void)limit;
    next[0] = 0;
    if (fake_down(f, err)) return NULL;
    cJSON *arr = cJSON_CreateArray();
    for (int i = 0; i < f->n; i++)
        if (f->meta[i]) cJSON_AddItemToArray(arr, cJSON_Parse(f->meta[i]));
    return arr;
}

static long fake_count(void *ud, vx_err *err)
{
    fake_catalog *f = ud;
    if (fake_down(f, err)) return -1;
    long n = 0;
    for (int i = 0; i < f->n; i++)
        n += f->meta[i] != NULL;
    return n;
}

/* A job reads the mesh through the fd the store checked, then asks
 * whether that file is still the version checked: a write in place
 * meanwhile (the same bytes written again included) makes it
 * mesh_damaged; the file checked again afterwards is intact. */
static void test_changed_while_read(void **state)
{
    (void)state;
    char sdir[300], path[512];
    snprintf(sdir, sizeof sdir, "%s/inplace", dir);
    vx_err err;
    vx_store *s = vx_store_open(sdir, NULL, &err);
    assert_non_null(s);
    char id[65];
    int existed;
    put(s, "v 1 2 3\n", id, &existed);
    usleep(30000); /* past the file system's timestamp granularity */
    int64_t ver[7];
    int fd = vx_store_mesh_open_path(s, id, path, sizeof path, ver, &err);
    assert_true(fd >= 0);
    assert_int_equal(vx_store_mesh_still_intact(id, fd, ver, &err), 0);
    int w = open(path, O_WRONLY);
    assert_true(w >= 0);
    assert_int_equal(pwrite(w, "v", 1, 0), 1); /* the same byte, written */
    close(w);
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_store_mesh_still_intact(id, fd, ver, &err), -1);
    assert_string_equal(err.code, "mesh_damaged");
    close(fd);
    fd = vx_store_mesh_open_path(s, id, path, sizeof path, ver, &err);
    assert_true(fd >= 0);
    assert_int_equal(vx_store_mesh_still_intact(id, fd, ver, &err), 0);
    close(fd);
    vx_store_close(s);
}

static void test_catalog(void **state)
{
    (void)state;
    char cdir[300], path[400];
    snprintf(cdir, sizeof cdir, "%s/catalog", dir);
    vx_err err;
    /* A mesh stored before there was a catalog: vx_store_mesh_local has it. */
    vx_store *s = vx_store_open(cdir, NULL, &err);
    assert_non_null(s);
    char old[65], id[65];
    int existed;
    put(s, "v 0 0 0\n", old, &existed);
    fake_catalog f = {0};
    vx_mesh_catalog c = {.ud = &f,
                         .lock = fake_lock,
                         .unlock = fake_unlock,
                         .put = fake_put,
                         .get = fake_get,
                         .remove = fake_remove,
                         .list = fake_list,
                         .count = fake_count};
    cJSON *local = vx_store_mesh_local(s);
    assert_int_equal(cJSON_GetArraySize(local), 1);
    cJSON_Delete(local);
    vx_store_set_catalog(s, &c);
    /* What the API sees is the catalog's: the old mesh is not in it. */
    assert_null(vx_store_mesh_meta(s, old, &err));
    assert_string_equal(err.code, "mesh_not_found");
    assert_int_equal(vx_store_mesh_count(s), 0);
    /* An upload: lock, bytes, put, unlock; new for the catalog. */
    f.calls[0] = 0;
    put(s, "v 1 1 1\n", id, &existed);
    assert_string_equal(f.calls, "LPU");
    assert_int_equal(existed, 0);
    assert_int_equal(vx_store_mesh_count(s), 1);
    cJSON *m = vx_store_mesh_meta(s, id, &err);
    assert_non_null(m);
    cJSON_Delete(m);
    char next[65];
    cJSON *l = vx_store_mesh_list(s, NULL, 10, next, &err);
    assert_int_equal(cJSON_GetArraySize(l), 1);
    cJSON_Delete(l);
    /* The old mesh uploaded again: its bytes were here, the catalog says new. */
    put(s, "v 0 0 0\n", old, &existed);
    assert_int_equal(existed, 0);
    put(s, "v 0 0 0\n", old, &existed);
    assert_int_equal(existed, 1);
    /* A delete tells the catalog only: the bytes stay for jobs. */
    assert_int_equal(vx_store_mesh_delete(s, id, &err), 0);
    assert_null(vx_store_mesh_meta(s, id, &err));
    assert_int_equal(vx_store_mesh_path(s, id, path, sizeof path, &err), 0);
    assert_int_equal(access(path, F_OK), 0);
    assert_int_equal(vx_store_mesh_delete(s, id, &err), -1);
    assert_string_equal(err.code, "mesh_not_found");
    /* The purge: not while a job here pins it; then bytes and entry go. */
    assert_int_equal(vx_store_mesh_pin(s, id, 1, &err), 0);
    assert_int_equal(vx_store_mesh_purge(s, id, "obj"), -1);
    assert_int_equal(access(path, F_OK), 0);
    vx_store_mesh_unpin(s, id);
    assert_int_equal(vx_store_mesh_purge(s, id, "obj"), 0);
    assert_int_equal(access(path, F_OK), -1);
    assert_int_equal(vx_store_mesh_path(s, id, path, sizeof path, &err), -1);
    /* Bytes another daemon purged (the entry here still names them): an
     * upload stores them again. */
    assert_int_equal(vx_store_mesh_path(s, old, path, sizeof path, &err), 0);
    assert_int_equal(vx_store_mesh_stored(s, old), 1);
    assert_int_equal(unlink(path), 0);
    assert_int_equal(vx_store_mesh_stored(s, old), 0); /* the catalog still names it */
    fake_remove(&f, old, &err);
    put(s, "v 0 0 0\n", old, &existed);
    assert_int_equal(existed, 0);
    assert_int_equal(vx_store_mesh_path(s, old, path, sizeof path, &err), 0);
    assert_int_equal(access(path, F_OK), 0);
    /* The catalog down: an upload is not acknowledged, lists fail, the
     * count falls back to this store's own. */
    f.down = 1;
    vx_upload *u = vx_upload_begin(s, &err);
    assert_int_equal(vx_upload_write(u, "v 2 2 2\n", 8, &err), 0);
    assert_int_equal(vx_upload_finish(u, id, &err), 0);
    cJSON *meta = cJSON_CreateObject();
    assert_int_equal(vx_store_mesh_commit(s, u, id, "obj", meta, &existed, &err), -1);
    cJSON_Delete(meta);
    assert_string_equal(err.code, "database_unavailable");
    assert_null(vx_store_mesh_list(s, NULL, 10, next, &err));
    assert_null(vx_store_mesh_meta(s, old, &err));
    assert_string_equal(err.code, "database_unavailable");
    assert_int_equal(vx_store_mesh_count(s), 1);
    vx_store_set_catalog(s, NULL);
    for (int i = 0; i < f.n; i++)
        free(f.meta[i]);
    vx_store_close(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hash_commit_dedup),
        cmocka_unit_test(test_list_pages),
        cmocka_unit_test(test_results_budget),
        cmocka_unit_test(test_upload_abort),
        cmocka_unit_test(test_pins),
        cmocka_unit_test(test_blobs),
        cmocka_unit_test(test_catalog),
        cmocka_unit_test(test_changed_while_read),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
