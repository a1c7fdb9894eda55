/* voxelize's writers (voxel/io.h) read back independently: raw8 and raw1
 * byte for byte / bit for bit, binvox through a small reader written here
 * (header + run-length body), .vdb through OpenVDB itself (the vdbinfo
 * tool); and the kind's parameter parsing. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cjson/cJSON.h>
#include <cmocka.h>

#include "voxel/io.h"
#include "voxel/job.h"
#include "voxel/voxel.h"

static char dir[] = "/tmp/vx-voxel-io-XXXXXX";

/* A pattern with no symmetry between axes, on a grid whose nx is neither a
 * multiple of 8 nor of 32 (row padding would show). */
static int pattern(int i, int j, int k)
{
    return ((i * 7 + j * 3 + k * 5) % 4 == 0) || (i == 12 && k == 2);
}

static void make_grid(vx_bitgrid *g, int nx, int ny, int nz, int counts)
{
    vx_grid gr = {{-1.5, 2.0, 0.25}, 0.5, {nx, ny, nz}, {0, 0, 0}};
    assert_int_equal(vx_bitgrid_alloc(g, &gr, counts, NULL), 0);
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++) {
                if (pattern(i, j, k))
                    g->bits[((size_t)k * ny + j) * g->wx + (size_t)(i >> 5)] |= 1u << (i & 31);
                if (counts)
                    g->counts[((size_t)k * ny + j) * nx + i] = (uint8_t)((i + 2 * j + 3 * k) % 9);
            }
}

static uint8_t *slurp(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    fseek(f, 0, SEEK_END);
    long len = ftell(f);
    fseek(f, 0, SEEK_SET);
    uint8_t *b = malloc((size_t)len + 1);
    assert_int_equal(fread(b, 1, (size_t)len, f), (size_t)len);
    fclose(f);
    *n = (size_t)len;
    return b;
}

static void path_of(char *out, size_t n, const char *name)
{
    snprintf(out, n, "%s/%s", dir, name);
}

static void test_raw8(void **st)
{
    vx_bitgrid g;
    make_grid(&g, 13, 5, 3, 0);
    char p[256];
    path_of(p, sizeof p, "a.raw8");
    vx_err err;
    assert_int_equal(vx_voxel_write_raw8(&g, p, NULL, &err), 0);
    size_t n;
    uint8_t *b = slurp(p, &n);
    assert_int_equal(n, 13 * 5 * 3);
    for (int k = 0; k < 3; k++)
        for (int j = 0; j < 5; j++)
            for (int i = 0; i < 13; i++)
                assert_int_equal(b[i + 13 * (j + 5 * k)], pattern(i, j, k));
    free(b);
    vx_bitgrid_free(&g);
}

static void test_raw1(void **st)
{
    vx_bitgrid g;
    make_grid(&g, 13, 5, 3, 0);
    char p[256];
    path_of(p, sizeof p, "a.raw1");
    vx_err err;
    assert_int_equal(vx_voxel_write_raw1(&g, p, NULL, &err), 0);
    size_t n;
    uint8_t *b = slurp(p, &n);
    const size_t nv = 13 * 5 * 3;
    assert_int_equal(n, (nv + 7) / 8);
    for (int k = 0; k < 3; k++)
        for (int j = 0; j < 5; j++)
            for (int i = 0; i < 13; i++) {
                size_t L = (size_t)i + 13 * ((size_t)j + 5 * (size_t)k);
                assert_int_equal((b[L / 8] >> (L % 8)) & 1, pattern(i, j, k));
            }
    /* the unused high bits of the last byte are 0 */
    for (size_t L = nv; L < n * 8; L++)
        assert_int_equal((b[L / 8] >> (L % 8)) & 1, 0);
    /* spot check of the order: voxel (0,0,0) is bit 0 of byte 0, (8,0,0) bit 0 of byte 1 */
    assert_int_equal(b[0] & 1, pattern(0, 0, 0));
    assert_int_equal(b[1] & 1, pattern(8, 0, 0));
    free(b);
    vx_bitgrid_free(&g);
}

/* Minimal binvox reader: returns the d^3 voxels in binvox order. */
static uint8_t *read_binvox(const char *path, int *d, double t[3], double *scale)
{
    size_t n;
    uint8_t *b = slurp(path, &n);
    b[n] = 0;
    int dx, dy, dz, off = 0;
    assert_int_equal(sscanf((char *)b,
                            "#binvox 1\ndim %d %d %d\ntranslate %lf %lf %lf\nscale %lf\ndata\n%n",
                            &dx, &dy, &dz, &t[0], &t[1], &t[2], scale, &off),
                     7);
    assert_true(off > 0);
    assert_int_equal(dx, dy);
    assert_int_equal(dx, dz);
    *d = dx;
    size_t nv = (size_t)dx * dx * dx, at = 0;
    uint8_t *v = calloc(nv, 1);
    for (size_t p = (size_t)off; p + 1 < n; p += 2) {
        assert_true(b[p] <= 1);
        assert_true(b[p + 1] >= 1);
        for (int c = 0; c < b[p + 1]; c++) {
            assert_true(at < nv);
            v[at++] = b[p];
        }
    }
    assert_int_equal(at, nv);
    free(b);
    return v;
}

static void test_binvox(void **st)
{
    vx_bitgrid g;
    make_grid(&g, 13, 5, 3, 0);
    char p[256];
    path_of(p, sizeof p, "a.binvox");
    vx_err err;
    assert_int_equal(vx_voxel_write_binvox(&g, p, NULL, &err), 0);
    int d;
    double t[3], scale;
    uint8_t *v = read_binvox(p, &d, t, &scale);
    assert_int_equal(d, 13); /* padded to a cube of the largest axis */
    assert_true(t[0] == -1.5 && t[1] == 2.0 && t[2] == 0.25);
    assert_true(fabs(scale - 13 * 0.5) < 1e-12);
    for (int i = 0; i < d; i++)
        for (int k = 0; k < d; k++)
            for (int j = 0; j < d; j++) {
                int want = i < 13 && j < 5 && k < 3 ? pattern(i, j, k) : 0;
                assert_int_equal(v[(size_t)i * d * d + (size_t)k * d + (size_t)j], want);
            }
    free(v);
    vx_bitgrid_free(&g);
}

/* Runs vdbinfo on path and returns grids[0]. */
static cJSON *vdbinfo(const char *path, cJSON **root)
{
    char cmd[512];
    snprintf(cmd, sizeof cmd, "%s/vdbinfo %s", VX_TOOLS_DIR, path);
    FILE *f = popen(cmd, "r");
    assert_non_null(f);
    static char buf[1 << 16];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    buf[n] = 0;
    assert_int_equal(pclose(f), 0);
    *root = cJSON_Parse(buf);
    assert_non_null(*root);
    cJSON *grids = cJSON_GetObjectItem(*root, "grids");
    assert_int_equal(cJSON_GetArraySize(grids), 1);
    return cJSON_GetArrayItem(grids, 0);
}

static double num_at(const cJSON *o, const char *a, int i)
{
    const cJSON *x = cJSON_GetObjectItem(o, a);
    return i < 0 ? x->valuedouble : cJSON_GetArrayItem(x, i)->valuedouble;
}

static void test_vdb_bool(void **st)
{
    vx_bitgrid g;
    make_grid(&g, 13, 5, 3, 0);
    char p[256];
    path_of(p, sizeof p, "a.vdb");
    vx_err err;
    vx_vdb_meta m = {"peel", "nonzero", "solid", "abc", 1, 4, NULL};
    assert_int_equal(vx_voxel_write_vdb(&g, VX_VDB_BOOL, &m, p, NULL, &err), 0);
    cJSON *root, *gr = vdbinfo(p, &root);
    assert_string_equal(cJSON_GetObjectItem(gr, "name")->valuestring, "voxels");
    assert_string_equal(cJSON_GetObjectItem(gr, "type")->valuestring, "bool");
    assert_int_equal((uint64_t)num_at(gr, "active_voxels", -1), vx_bitgrid_count(&g));
    const cJSON *xf = cJSON_GetObjectItem(gr, "transform");
    assert_true(cJSON_IsTrue(cJSON_GetObjectItem(xf, "linear")));
    for (int a = 0; a < 3; a++) {
        assert_true(fabs(num_at(xf, "voxel_size", a) - 0.5) < 1e-12);
        /* index (0,0,0) is the centre of voxel (0,0,0) */
        assert_true(fabs(num_at(xf, "translation", a) - (g.grid.origin[a] + 0.25)) < 1e-12);
    }
    const cJSON *md = cJSON_GetObjectItem(gr, "metadata");
    assert_string_equal(cJSON_GetObjectItem(md, "method")->valuestring, "peel");
    assert_string_equal(cJSON_GetObjectItem(md, "mesh")->valuestring, "abc");
    assert_int_equal((int)num_at(md, "dims", 0), 13);
    assert_int_equal((int)num_at(md, "threshold", -1), 4);
    assert_true(num_at(md, "voxel_size", -1) == 0.5);
    cJSON_Delete(root);
    vx_bitgrid_free(&g);
}

static void test_vdb_coverage(void **st)
{
    /* samples inside / samples per voxel: 8 (cube) or 7 (faces) */
    for (int n = 8; n >= 7; n--) {
        vx_bitgrid g;
        make_grid(&g, 13, 5, 3, 1);
        g.nsamples = n;
        char p[256];
        path_of(p, sizeof p, "c.vdb");
        vx_err err;
        vx_vdb_meta m = {"slice", "parity", "solid", NULL, 2, 3, n == 8 ? "cube" : "faces"};
        assert_int_equal(vx_voxel_write_vdb(&g, VX_VDB_FOG, &m, p, NULL, &err), 0);
        uint64_t active = 0, sum = 0;
        for (size_t i = 0; i < 13 * 5 * 3; i++) {
            active += g.counts[i] > 0;
            sum += g.counts[i];
        }
        cJSON *root, *gr = vdbinfo(p, &root);
        assert_string_equal(cJSON_GetObjectItem(gr, "name")->valuestring, "coverage");
        assert_string_equal(cJSON_GetObjectItem(gr, "type")->valuestring, "float");
        assert_int_equal((uint64_t)num_at(gr, "active_voxels", -1), active);
        assert_true(fabs(num_at(gr, "value_sum", -1) - (double)sum / n) < 1e-4);
        const cJSON *md = cJSON_GetObjectItem(gr, "metadata");
        assert_string_equal(cJSON_GetObjectItem(md, "samples")->valuestring, m.samples);
        cJSON_Delete(root);
        vx_bitgrid_free(&g);
    }
}

static void test_write_error(void **st)
{
    vx_bitgrid g;
    make_grid(&g, 4, 4, 4, 0);
    vx_err err;
    assert_int_equal(vx_voxel_write_raw8(&g, "/nonexistent-dir/x.raw", NULL, &err), -1);
    assert_int_equal(err.kind, VX_EIO);
    assert_int_equal(
        vx_voxel_write_vdb(&g, VX_VDB_BOOL, NULL, "/nonexistent-dir/x.vdb", NULL, &err), -1);
    assert_int_equal(err.kind, VX_EIO);
    vx_bitgrid_free(&g);
}

static int stop_at_half(void *ud, double f, vx_err *err)
{
    return f >= 0.5 ? vx_err_set(err, VX_ECANCELED, "canceled", "stop") : 0;
}

static void test_write_canceled(void **st)
{
    vx_bitgrid g;
    make_grid(&g, 4, 4, 32, 0);
    char p[256];
    path_of(p, sizeof p, "x.raw");
    vx_voxel_io io = {.progress = stop_at_half};
    vx_err err;
    assert_int_equal(vx_voxel_write_raw1(&g, p, &io, &err), -1);
    assert_int_equal(err.kind, VX_ECANCELED);
    assert_int_not_equal(access(p, F_OK), 0); /* nothing left behind */
    vx_bitgrid_free(&g);
}

/* ---- params ---- */

static cJSON *parse(const char *json, const vx_limits *lim, vx_err *err)
{
    cJSON *in = cJSON_Parse(json);
    assert_non_null(in);
    cJSON *out = vx_kind_parse(&vx_kind_voxelize, in, lim, err);
    cJSON_Delete(in);
    return out;
}

static void expect_invalid(const char *json, const char *needle)
{
    vx_limits lim = {.max_job_memory = 1ull << 30};
    vx_err err;
    cJSON *o = parse(json, &lim, &err);
    if (o) fail_msg("%s was accepted", json);
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "invalid_params");
    if (!strstr(err.message, needle))
        fail_msg("%s: message '%s' lacks '%s'", json, err.message, needle);
}

/* The kind's check at submission of json's params for a mesh whose box
 * is (0, 0, 0)..max: 0, or -1 with err. */
static int check_with_box(const char *json, const double max[3], const vx_limits *lim, vx_err *err)
{
    cJSON *o = parse(json, lim, err);
    assert_non_null(o);
    void *typed = vx_kind_read(&vx_kind_voxelize, o, lim, err);
    assert_non_null(typed);
    char text[256];
    snprintf(text, sizeof text,
             "{\"bbox\":{\"min\":[0,0,0],\"max\":[%.17g,%.17g,%.17g]},\"boundary_edges\":0}",
             max[0], max[1], max[2]);
    cJSON *meta = cJSON_Parse(text);
    assert_non_null(meta);
    int rc = vx_kind_voxelize.check_mesh(typed, meta, lim, err);
    cJSON_Delete(meta);
    vx_kind_params_free(&vx_kind_voxelize, typed);
    cJSON_Delete(o);
    return rc;
}

static void test_params(void **st)
{
    vx_err err;
    cJSON *o = parse("{}", NULL, &err);
    assert_non_null(o);
    char *s = cJSON_PrintUnformatted(o);
    assert_string_equal(
        s,
        "{\"resolution\":256,\"voxel_size\":null,\"grid\":null,\"padding\":0,\"method\":\"auto\","
        "\"inside\":null,\"fill\":\"solid\",\"supersample\":1,\"samples\":\"cube\","
        "\"threshold\":4,"
        "\"format\":\"vdb\",\"vdb_grid\":\"fog\",\"bricks\":null,\"merge\":true,"
        "\"vdb_index_base\":null}");
    /* normalised params parse to themselves */
    cJSON *again = vx_kind_parse(&vx_kind_voxelize, o, NULL, &err);
    char *s2 = cJSON_PrintUnformatted(again);
    assert_string_equal(s, s2);
    free(s);
    free(s2);
    cJSON_Delete(o);
    cJSON_Delete(again);

    o = parse(
        "{\"grid\":{\"origin\":[0,1,2],\"voxel_size\":0.5,\"dims\":[4,5,6]},\"format\":\"raw1\"}",
        NULL, &err);
    assert_non_null(o);
    assert_true(cJSON_IsNull(cJSON_GetObjectItem(o, "resolution")));
    assert_int_equal(
        cJSON_GetArrayItem(cJSON_GetObjectItem(cJSON_GetObjectItem(o, "grid"), "dims"), 2)
            ->valueint,
        6);
    cJSON_Delete(o);

    expect_invalid("{\"resolution\":0}", "params.resolution");
    expect_invalid("{\"resolution\":8,\"voxel_size\":0.1}", "params.voxel_size");
    expect_invalid("{\"voxel_size\":0}", "params.voxel_size");
    expect_invalid(
        "{\"grid\":{\"origin\":[0,0,0],\"voxel_size\":1,\"dims\":[2,2,2]},\"padding\":1}",
        "params.padding");
    expect_invalid("{\"grid\":{\"origin\":[0,0,0],\"voxel_size\":1,\"dims\":[0,2,2]}}",
                   "params.grid.dims[0]");
    expect_invalid("{\"grid\":{\"origin\":[0,0,0],\"voxel_size\":1,\"dims\":[4096,4096,4096]},"
                   "\"format\":\"raw8\"}",
                   "2048^3");
    expect_invalid("{\"grid\":{\"origin\":[0,0],\"voxel_size\":1,\"dims\":[2,2,2]}}",
                   "params.grid.origin");
    expect_invalid("{\"grid\":{\"origin\":[0,0,0],\"voxel_size\":1,\"dims\":[2,2,2],\"x\":1}}",
                   "params.grid.x");
    expect_invalid("{\"method\":\"magic\"}", "params.method");
    expect_invalid("{\"inside\":\"odd\"}", "params.inside");
    expect_invalid("{\"threshold\":9}", "params.threshold");
    expect_invalid("{\"supersample\":3}", "params.supersample");
    expect_invalid("{\"supersample\":2,\"method\":\"peel\"}", "params.supersample");
    expect_invalid("{\"format\":\"stl\"}", "params.format");
    expect_invalid("{\"vdb_grid\":\"points\"}", "params.vdb_grid");
    expect_invalid("{\"colour\":1}", "params.colour");
    /* A resolution's grid depends on the mesh's box: checked with it at
     * submission (check_mesh). 2048^3 bits is 1 GiB: twice that (CPU +
     * GPU) is over a 1 GiB limit for a cube; a flat plate's 2048 x 2048 x
     * 3 is not (the params alone had been checked as a cube). */
    vx_limits lim = {.max_job_memory = 1ull << 30};
    const double cube[3] = {1, 1, 1}, plate[3] = {1, 1, 1e-3};
    assert_int_equal(
        check_with_box("{\"resolution\":2048,\"bricks\":{\"size\":0}}", cube, &lim, &err), -1);
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_non_null(strstr(err.message, "job memory limit"));
    assert_int_equal(
        check_with_box("{\"resolution\":2048,\"bricks\":{\"size\":0}}", plate, &lim, &err), 0);
    /* as bricks (a .vdb past the 1024^3 default threshold) only one
     * brick's job counts: accepted under the same 1 GiB */
    assert_int_equal(check_with_box("{\"resolution\":2048}", cube, &lim, &err), 0);
    expect_invalid("{\"bricks\":{\"size\":20}}", "multiple of 8");
    expect_invalid("{\"bricks\":{\"size\":64},\"format\":\"binvox\"}", "params.bricks");
    expect_invalid("{\"merge\":false}", "params.merge");
}

static int setup(void **st)
{
    return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **st)
{
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    return system(cmd) == 0 ? 0 : -1;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_raw8),           cmocka_unit_test(test_raw1),
        cmocka_unit_test(test_binvox),         cmocka_unit_test(test_vdb_bool),
        cmocka_unit_test(test_vdb_coverage),   cmocka_unit_test(test_write_error),
        cmocka_unit_test(test_write_canceled), cmocka_unit_test(test_params),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
