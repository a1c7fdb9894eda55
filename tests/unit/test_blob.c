/* store/blob: the local byte store's contract, and the store using only its
 * backend for the bytes (a backend rooted elsewhere gets every mesh, blob
 * and result; the data dir keeps only the lock and the uploads in flight). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <errno.h>
#include <cmocka.h>

#include "store/blob.h"
#include "store/store.h"
#include "util/fsutil.h"

static char dir[256];

static int setup(void **state)
{
    snprintf(dir, sizeof dir, "/tmp/vx-blob-XXXXXX");
    return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
    vx_remove_tree(dir);
    return 0;
}

static int exists(const char *fmt, const char *a)
{
    char p[1024], f[1024];
    snprintf(f, sizeof f, "%%s/%s", fmt);
    snprintf(p, sizeof p, f, dir, a);
    return access(p, F_OK) == 0;
}

typedef struct names {
    char seen[8][80];
    int n;
} names;

static int add_name(const char *name, void *ud)
{
    names *ns = ud;
    if (ns->n < 8) snprintf(ns->seen[ns->n++], sizeof ns->seen[0], "%s", name);
    return 0;
}

static void test_local_contract(void **state)
{
    vx_err err;
    const vx_blob_ops *o = &vx_blob_local;
    vx_blob *b = o->open(dir, NULL, &err);
    assert_non_null(b);
    assert_int_equal(o->make_prefix(b, "ns", &err), 0);
    /* stage: durable but under no key; put_file names it */
    char tmp[4096];
    assert_int_equal(o->stage(b, "ns", "hello", 5, tmp, sizeof tmp), 0);
    assert_int_equal(o->stat(b, "ns/a", NULL, NULL), -1);
    assert_int_equal(o->put_file(b, tmp, "ns/a"), 0);
    assert_int_equal(o->sync(b, "ns", &err), 0);
    uint64_t bytes = 0;
    double mtime = 0;
    assert_int_equal(o->stat(b, "ns/a", &bytes, &mtime), 0);
    assert_int_equal(bytes, 5);
    assert_true(mtime > 1.6e9);
    size_t n = 0;
    char *text = o->read(b, "ns/a", 1 << 20, &n, &err);
    assert_non_null(text);
    assert_int_equal(n, 5);
    assert_string_equal(text, "hello");
    free(text);
    /* put_bytes replaces; move renames; remove of a missing key is fine */
    assert_int_equal(o->put_bytes(b, "ns/a", "hi", 2, &err), 0);
    assert_int_equal(o->move(b, "ns/a", "ns/b"), 0);
    assert_int_equal(o->stat(b, "ns/a", NULL, NULL), -1);
    assert_int_equal(errno, ENOENT);
    assert_int_equal(o->stat(b, "ns/b", &bytes, NULL), 0);
    assert_int_equal(bytes, 2);
    vx_err_clear(&err);
    assert_null(o->read(b, "ns/a", 1 << 20, NULL, &err));
    assert_int_equal(err.kind, VX_ENOTFOUND);
    assert_int_equal(o->remove(b, "ns/a"), 0);
    /* a discarded stage leaves nothing */
    assert_int_equal(o->stage(b, "ns", "x", 1, tmp, sizeof tmp), 0);
    o->discard(b, tmp);
    names ns = {0};
    assert_int_equal(o->list(b, "ns", add_name, &ns), 0);
    assert_int_equal(ns.n, 1);
    assert_string_equal(ns.seen[0], "b");
    assert_int_equal(o->list(b, "missing", add_name, &ns), -1);
    /* prefixes: stat answers 1 with the bytes under them */
    assert_int_equal(o->make_prefix(b, "ns/p", &err), 0);
    assert_int_equal(o->put_bytes(b, "ns/p/x", "abc", 3, &err), 0);
    assert_int_equal(o->stat(b, "ns/p", &bytes, NULL), 1);
    assert_int_equal(bytes, 3);
    assert_int_equal(o->touch(b, "ns/p"), 0);
    char path[4096];
    assert_int_equal(o->path(b, "ns/p/x", path, sizeof path), 0);
    assert_int_equal(access(path, R_OK), 0);
    assert_int_equal(o->remove_prefix(b, "ns/p"), 0);
    assert_int_equal(o->stat(b, "ns/p", NULL, NULL), -1);
    o->close(b);
}

/* The local backend rooted at <where>/alt: a stand-in for a remote one. */
static vx_blob *alt_open(const char *where, const vx_blob_conf *conf, vx_err *err)
{
    char p[4096];
    snprintf(p, sizeof p, "%s/alt", where);
    if (vx_mkdirs(p, err)) return NULL;
    return vx_blob_local.open(p, conf, err);
}

static void test_store_uses_backend(void **state)
{
    vx_blob_ops alt = vx_blob_local;
    alt.name = "alt";
    alt.open = alt_open;
    vx_store_desc d = {.blob_ops = &alt};
    vx_err err;
    vx_store *s = vx_store_open(dir, &d, &err);
    assert_non_null(s);
    vx_upload *u = vx_upload_begin(s, &err);
    assert_non_null(u);
    assert_int_equal(vx_upload_write(u, "v 0 0 0\n", 8, &err), 0);
    char id[65];
    assert_int_equal(vx_upload_finish(u, id, &err), 0);
    cJSON *meta = cJSON_CreateObject();
    cJSON_AddStringToObject(meta, "id", id);
    cJSON_AddStringToObject(meta, "format", "obj");
    int existed;
    assert_int_equal(vx_store_mesh_commit(s, u, id, "obj", meta, &existed, &err), 0);
    cJSON_Delete(meta);
    assert_true(exists("alt/meshes/%s.obj", id));
    assert_true(exists("alt/meshes/%s.json", id));
    assert_false(exists("meshes/%s.obj", id));
    char path[4096];
    assert_int_equal(vx_store_mesh_path(s, id, path, sizeof path, &err), 0);
    assert_non_null(strstr(path, "/alt/meshes/"));
    char bid[65];
    assert_int_equal(vx_store_blob_put(s, "{}", 2, bid, &err), 0);
    assert_true(exists("alt/blobs/%s.json", bid));
    assert_int_equal(vx_store_result_dir(s, "ab12", path, sizeof path, &err), 0);
    assert_true(exists("alt/results/%s", "ab12"));
    char f[4200];
    snprintf(f, sizeof f, "%s/out.txt", path);
    assert_int_equal(vx_write_atomic(f, "12345", 5, &err), 0);
    vx_store_result_added(s, "ab12");
    assert_int_equal(vx_store_results_bytes(s), 5);
    assert_int_equal(vx_store_result_file(s, "ab12", "out.txt", path, sizeof path, &err), 0);
    assert_int_equal(access(path, R_OK), 0);
    vx_store_close(s);
    /* A restart loads the index from the backend. */
    s = vx_store_open(dir, &d, &err);
    assert_non_null(s);
    assert_int_equal(vx_store_mesh_count(s), 1);
    cJSON *m = vx_store_mesh_meta(s, id, &err);
    assert_non_null(m);
    cJSON_Delete(m);
    assert_int_equal(vx_store_results_bytes(s), 5);
    assert_int_equal(vx_store_blob_pin(s, bid, &err), 0);
    vx_store_blob_unpin(s, bid);
    assert_false(exists("alt/blobs/%s.json", bid));
    assert_int_equal(vx_store_mesh_delete(s, id, &err), 0);
    assert_false(exists("alt/meshes/%s.obj", id));
    vx_store_close(s);
    /* The same data dir opened with the local backend has none of it. */
    s = vx_store_open(dir, NULL, &err);
    assert_non_null(s);
    assert_int_equal(vx_store_results_bytes(s), 0);
    vx_store_close(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_local_contract, setup, teardown),
        cmocka_unit_test_setup_teardown(test_store_uses_backend, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
