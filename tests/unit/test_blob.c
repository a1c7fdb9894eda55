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
#include <fcntl.h>
#include <sys/stat.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
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

/* The contract on backend o opened as conf says (remote: an object store,
 * where an empty namespace lists as empty and the store is reachable
 * before any namespace exists). */
static void contract(const vx_blob_ops *o, const vx_blob_conf *conf, int remote)
{
    vx_err err;
    vx_blob *b = o->open(dir, conf, &err);
    assert_non_null(b);
    /* reachable before any namespace exists: a local store makes its
     * meshes dir (one removed behind the daemon comes back) */
    assert_int_equal(o->ping(b), 1);
    if (!remote) {
        char meshes[4096];
        struct stat st;
        assert_int_equal(o->path(b, "meshes", meshes, sizeof meshes), 0);
        assert_int_equal(stat(meshes, &st), 0);
        assert_true(S_ISDIR(st.st_mode));
    }
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
    assert_int_equal(o->list(b, "missing", add_name, &ns), remote ? 0 : -1);
    assert_int_equal(ns.n, 1);
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
    assert_int_equal(o->make_prefix(b, "meshes", &err), 0);
    assert_int_equal(o->ping(b), 1);
    o->close(b);
}

static void test_local_contract(void **state)
{
    contract(&vx_blob_local, NULL, 0);
    assert_true(exists("%s", "ns"));
}

/* file:///DIR: the same contract rooted at DIR, the data dir untouched; a
 * file from another dir is copied in when rename cannot (EXDEV). */
static void test_file_contract(void **state)
{
    char url[600];
    snprintf(url, sizeof url, "file://%s/shared", dir);
    vx_blob_conf conf = {.url = url};
    contract(&vx_blob_file, &conf, 0);
    assert_true(exists("%s", "shared/ns"));
    assert_false(exists("%s", "ns"));
    assert_int_equal(vx_blob_file.shared, 1);
    assert_int_equal(vx_blob_local.shared, 0);
    vx_err err;
    /* An upload on another file system (tmpfs here, where it is another
     * one): copied in and fsync'd, the source gone. */
    char src[] = "/dev/shm/vx-blob-src-XXXXXX";
    int fd = mkstemp(src);
    if (fd >= 0) {
        assert_int_equal(write(fd, "xyz", 3), 3);
        close(fd);
        vx_blob *b = vx_blob_file.open(dir, &conf, &err);
        assert_non_null(b);
        assert_int_equal(vx_blob_file.make_prefix(b, "meshes", &err), 0);
        assert_int_equal(vx_blob_file.put_file(b, src, "meshes/m"), 0);
        assert_int_equal(access(src, F_OK), -1);
        size_t n = 0;
        char *t = vx_blob_file.read(b, "meshes/m", 100, &n, &err);
        assert_non_null(t);
        assert_string_equal(t, "xyz");
        free(t);
        vx_blob_file.close(b);
    }
    vx_blob_conf rel = {.url = "file://relative"};
    assert_null(vx_blob_file.open(dir, &rel, &err));
    assert_string_equal(err.code, "bad_blob_store");
}

static void test_backend_of_url(void **state)
{
    vx_err err;
    assert_ptr_equal(vx_blob_backend(NULL, &err), &vx_blob_local);
    assert_ptr_equal(vx_blob_backend("", &err), &vx_blob_local);
    assert_ptr_equal(vx_blob_backend("file:///x", &err), &vx_blob_file);
    assert_ptr_equal(vx_blob_backend("s3://b/p", &err), &vx_blob_s3);
    assert_null(vx_blob_backend("ftp://x", &err));
    assert_string_equal(err.code, "bad_blob_store");
    /* s3 refuses bad URLs and missing credentials before any request. */
    unsetenv("AWS_ACCESS_KEY_ID");
    unsetenv("AWS_SECRET_ACCESS_KEY");
    vx_blob_conf c = {.url = "s3://bucket/p?endpoint=http://127.0.0.1:9"};
    assert_null(vx_blob_s3.open(dir, &c, &err));
    assert_string_equal(err.code, "bad_blob_credentials");
    setenv("AWS_ACCESS_KEY_ID", "AK", 1);
    setenv("AWS_SECRET_ACCESS_KEY", "SK", 1);
    vx_blob_conf bad = {.url = "s3://b?endpoint=http://127.0.0.1:9"};
    assert_null(vx_blob_s3.open(dir, &bad, &err)); /* a bucket name of 1 letter */
    assert_string_equal(err.code, "bad_blob_store");
    assert_string_equal(err.message,
                        "s3:// needs a bucket name of 3 to 63 letters, digits, - and _");
    vx_blob_conf ftp = {.url = "s3://bucket?endpoint=ftp://x"};
    assert_null(vx_blob_s3.open(dir, &ftp, &err));
    vx_blob_conf small = {.url = "s3://bucket?endpoint=http://127.0.0.1:9", .part_size = 1 << 20};
    assert_null(vx_blob_s3.open(dir, &small, &err));
    /* Nothing listens on port 9: opening works (no request yet), the ping
     * fails at once, and an op fails with ECONNREFUSED (unreachable: 503), not a hang. */
    vx_blob_conf ok = {.url = "s3://bucket/p?endpoint=http://127.0.0.1:9", .retries = -1};
    vx_blob *b = vx_blob_s3.open(dir, &ok, &err);
    assert_non_null(b);
    assert_int_equal(vx_blob_s3.ping(b), 0);
    assert_int_equal(vx_blob_s3.stat(b, "meshes/x", NULL, NULL), -1);
    assert_int_equal(errno, ECONNREFUSED);
    vx_blob_s3.close(b);
    unsetenv("AWS_ACCESS_KEY_ID");
    unsetenv("AWS_SECRET_ACCESS_KEY");
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
    assert_int_equal(vx_store_result_commit(s, "ab12", NULL), 0);
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

/* The same contract on s3:// against s3rver (tools/s3rver), started here on
 * a free port; skipped when it is not installed. */
static void test_s3_contract(void **state)
{
    char s3rver[1024];
    snprintf(s3rver, sizeof s3rver, "%s/tools/s3rver/node_modules/.bin/s3rver", VX_SOURCE_DIR);
    if (access(s3rver, X_OK) != 0) {
        fprintf(stderr, "s3rver not installed (npm ci --prefix tools/s3rver): skipped\n");
        skip();
    }
    int s = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    socklen_t len = sizeof a;
    assert_int_equal(bind(s, (struct sockaddr *)&a, sizeof a), 0);
    assert_int_equal(getsockname(s, (struct sockaddr *)&a, &len), 0);
    int port = ntohs(a.sin_port);
    close(s);
    char sdir[600], portstr[16];
    snprintf(sdir, sizeof sdir, "%s/s3", dir);
    snprintf(portstr, sizeof portstr, "%d", port);
    assert_int_equal(mkdir(sdir, 0700), 0);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        int null = open("/dev/null", O_WRONLY);
        dup2(null, 1);
        dup2(null, 2);
        execl(s3rver, s3rver, "-d", sdir, "-a", "127.0.0.1", "-p", portstr, "--configure-bucket",
              "vx-test", (char *)NULL);
        _exit(127);
    }
    char url[256];
    snprintf(url, sizeof url, "s3://vx-test/unit?endpoint=http://127.0.0.1:%d", port);
    setenv("AWS_ACCESS_KEY_ID", "S3RVER", 1);
    setenv("AWS_SECRET_ACCESS_KEY", "S3RVER", 1);
    vx_blob_conf conf = {.url = url, .retries = -1, .timeout_s = 5};
    vx_err err;
    int up = 0;
    for (int i = 0; i < 200 && !up; i++) { /* node takes a moment */
        vx_blob *b = vx_blob_s3.open(dir, &conf, &err);
        if (b) up = vx_blob_s3.ping(b);
        if (b) vx_blob_s3.close(b);
        if (!up) usleep(50000);
    }
    if (up) contract(&vx_blob_s3, &conf, 1);
    kill(pid, SIGTERM);
    waitpid(pid, NULL, 0);
    unsetenv("AWS_ACCESS_KEY_ID");
    unsetenv("AWS_SECRET_ACCESS_KEY");
    assert_true(up);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_local_contract, setup, teardown),
        cmocka_unit_test_setup_teardown(test_file_contract, setup, teardown),
        cmocka_unit_test_setup_teardown(test_backend_of_url, setup, teardown),
        cmocka_unit_test_setup_teardown(test_s3_contract, setup, teardown),
        cmocka_unit_test_setup_teardown(test_store_uses_backend, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
