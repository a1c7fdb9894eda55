/* The crossing-count voxelizer (method scan, src/voxel/scan.c) on a real GL
 * context: analytic answers, the CPU reference (ref_voxel.h) and peel voxel
 * for voxel. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cmocka.h>

#include "gl_fixture.h"

#include "ref_voxel.h"
#include "shapes.h"
#include "voxel/voxel.h"



static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

static void run_scan(const vx_mesh *m, vx_voxelize_desc *d, vx_bitgrid *out, vx_voxelize_stats *st)
{
    vx_err err = {0};
    int rc = vx_voxelize_scan(vx_test_gl, m, d, out, st, &err);
    if (rc) fprintf(stderr, "vx_voxelize_scan: %s: %s\n", err.code, err.message);
    assert_int_equal(rc, 0);
    assert_string_equal(st->method, "scan");
    assert_int_equal(st->layers, 0);
}

/* Compares with the reference; prints and returns the mismatch count. */
static size_t compare_ref(const char *what, const vx_mesh *m, const vx_grid *g, vx_inside rule,
                          const vx_bitgrid *b, double *iou)
{
    size_t n = (size_t)g->dims[0] * g->dims[1] * g->dims[2];
    uint8_t *ref = malloc(n);
    assert_non_null(ref);
    assert_int_equal(ref_voxelize(m, g, rule, ref), 0);
    size_t mis = 0, in = 0;
    for (int k = 0; k < g->dims[2]; k++)
        for (int j = 0; j < g->dims[1]; j++)
            for (int i = 0; i < g->dims[0]; i++) {
                size_t q = ((size_t)k * g->dims[1] + j) * g->dims[0] + i;
                mis += ref[q] != vx_bitgrid_get(b, i, j, k);
                in += ref[q];
            }
    *iou = ref_iou(ref, b);
    printf("%-28s %dx%dx%d ref=%zu scan=%llu mismatches=%zu IoU=%.6f\n", what, g->dims[0],
           g->dims[1], g->dims[2], in, (unsigned long long)vx_bitgrid_count(b), mis, *iou);
    free(ref);
    return mis;
}

/* scan against peel on the same request: voxel for voxel. */
static void same_as_peel(const char *what, const vx_mesh *m, vx_voxelize_desc *d,
                         const vx_bitgrid *b)
{
    vx_bitgrid p;
    vx_voxelize_stats st;
    vx_err err = {0};
    int rc = vx_voxelize_peel(vx_test_gl, m, d, &p, &st, &err);
    if (rc) fprintf(stderr, "vx_voxelize_peel: %s: %s\n", err.code, err.message);
    assert_int_equal(rc, 0);
    size_t words = b->wx * (size_t)d->grid.dims[1] * d->grid.dims[2], diff = 0;
    for (size_t w = 0; w < words; w++)
        diff += (size_t)__builtin_popcount(b->bits[w] ^ p.bits[w]);
    printf("%-28s scan vs peel: %zu voxels differ\n", what, diff);
    assert_int_equal(diff, 0);
    vx_bitgrid_free(&p);
}

static void grid_res(const vx_mesh *m, int res, int pad, vx_grid *g)
{
    assert_int_equal(vx_grid_from_resolution(m, res, pad, g, NULL), 0);
}

/* ---- tests ------------------------------------------------------------- */

static void test_cube_exact(void **state)
{
    vx_mesh *m = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    for (int pad = 0; pad <= 2; pad += 2)
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
            vx_voxelize_desc d = {.inside = (vx_inside)rule};
            grid_res(m, 8, pad, &d.grid);
            vx_bitgrid b;
            vx_voxelize_stats st;
            run_scan(m, &d, &b, &st);
            assert_int_equal(vx_bitgrid_count(&b), 512);
            assert_int_equal(st.voxels_inside, 512);
            assert_int_equal(st.chunks, 1);
            vx_bitgrid_free(&b);
        }
    /* flipped (inward) cube: nonzero still solid (winding -1), parity too */
    shape_flip(m);
    vx_voxelize_desc d = {0};
    grid_res(m, 8, 1, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_scan(m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 512);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

static void test_box_on_boundaries(void **state)
{
    vx_mesh *m = shape_box((double[]){0.5, 0.25, 0}, (double[]){10.25, 1.75, 1.5});
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 0.25, {45, 11, 9}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_scan(m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 39 * 6 * 6);
    for (int k = 0; k < 9; k++)
        for (int j = 0; j < 11; j++)
            for (int i = 0; i < 45; i++)
                assert_int_equal(vx_bitgrid_get(&b, i, j, k),
                                 i >= 2 && i < 41 && j >= 1 && j < 7 && k < 6);
    vx_bitgrid_free(&b);
    /* faces through voxel centres: the half-open [entry, exit) rule */
    vx_mesh_free(m);
    m = shape_box((double[]){0.125, 0.375, 0.625}, (double[]){1.125, 1.375, 1.625});
    double iou;
    run_scan(m, &d, &b, &st);
    assert_int_equal(compare_ref("box through centres", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou),
                     0);
    same_as_peel("box through centres", m, &d, &b);
    vx_bitgrid_free(&b);
    /* odd nx (the last 16-bit slot of a row half used), one voxel wide */
    for (int nx = 1; nx <= 3; nx++) {
        vx_voxelize_desc d1 = {.grid = {{0, 0, 0}, 0.25, {nx, 11, 9}}};
        run_scan(m, &d1, &b, &st);
        compare_ref("narrow grid", m, &d1.grid, VX_INSIDE_NONZERO, &b, &iou);
        assert_true(iou == 1.0 || vx_bitgrid_count(&b) == 0);
        same_as_peel("narrow grid", m, &d1, &b);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
}

static void test_sphere_torus(void **state)
{
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        vx_voxelize_desc d = {.inside = (vx_inside)rule};
        grid_res(m, 64, 1, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        run_scan(m, &d, &b, &st);
        double vol = (double)vx_bitgrid_count(&b) * pow(d.grid.h, 3), exact = 4.0 / 3 * M_PI;
        assert_true(fabs(vol / exact - 1) < 0.01);
        double iou;
        compare_ref(rule ? "sphere parity" : "sphere nonzero", m, &d.grid, (vx_inside)rule, &b,
                    &iou);
        assert_true(iou >= 0.999);
        same_as_peel("sphere", m, &d, &b);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
    m = shape_param_mesh(96, 48, 0, 0, 0.1, 0.2, 0.3, 1.0, 0.35);
    vx_voxelize_desc d = {0};
    grid_res(m, 80, 2, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_scan(m, &d, &b, &st);
    double iou;
    compare_ref("torus", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
    assert_true(iou >= 0.999);
    same_as_peel("torus", m, &d, &b);
    double vol = (double)vx_bitgrid_count(&b) * pow(d.grid.h, 3),
           exact = 2 * M_PI * M_PI * 1.0 * 0.35 * 0.35;
    assert_true(fabs(vol / exact - 1) < 0.02);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

static void test_hollow_and_nested(void **state)
{
    vx_mesh *parts[3] = {shape_sphere(0, 0, 0, 1, 0), shape_sphere(0, 0, 0, 0.6, 1),
                         shape_sphere(0, 0, 0, 0.3, 0)};
    vx_mesh *hollow = shape_merge(parts, 2), *nested = shape_merge(parts, 3);
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        vx_voxelize_desc d = {.inside = (vx_inside)rule};
        grid_res(hollow, 64, 1, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        run_scan(hollow, &d, &b, &st);
        size_t in_void = 0;
        for (int k = 0; k < d.grid.dims[2]; k++)
            for (int j = 0; j < d.grid.dims[1]; j++)
                for (int i = 0; i < d.grid.dims[0]; i++) {
                    double x = d.grid.origin[0] + (i + .5) * d.grid.h,
                           y = d.grid.origin[1] + (j + .5) * d.grid.h,
                           z = d.grid.origin[2] + (k + .5) * d.grid.h;
                    if (sqrt(x * x + y * y + z * z) < 0.58) in_void += vx_bitgrid_get(&b, i, j, k);
                }
        assert_int_equal(in_void, 0);
        double iou;
        compare_ref(rule ? "hollow parity" : "hollow nonzero", hollow, &d.grid, (vx_inside)rule,
                    &b, &iou);
        assert_true(iou >= 0.999);
        same_as_peel("hollow", hollow, &d, &b);
        vx_bitgrid_free(&b);

        run_scan(nested, &d, &b, &st);
        compare_ref(rule ? "ball in hollow parity" : "ball in hollow nonzero", nested, &d.grid,
                    (vx_inside)rule, &b, &iou);
        assert_true(iou >= 0.999);
        same_as_peel("ball in hollow", nested, &d, &b);
        double vol = (double)vx_bitgrid_count(&b) * pow(d.grid.h, 3),
               exact = 4.0 / 3 * M_PI * (1 - 0.216 + 0.027);
        assert_true(fabs(vol / exact - 1) < 0.02);
        vx_bitgrid_free(&b);
    }
    for (int i = 0; i < 3; i++)
        vx_mesh_free(parts[i]);
    vx_mesh_free(hollow);
    vx_mesh_free(nested);
}

static void test_overlapping_spheres(void **state)
{
    vx_mesh *parts[2] = {shape_sphere(0, 0, 0, 1, 0), shape_sphere(0.7, 0.3, 0.1, 0.8, 0)};
    vx_mesh *m = shape_merge(parts, 2);
    vx_voxelize_desc d = {0};
    grid_res(m, 64, 1, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    double iou;
    run_scan(m, &d, &b, &st);
    compare_ref("two spheres nonzero (union)", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
    assert_true(iou >= 0.999);
    same_as_peel("two spheres nonzero", m, &d, &b);
    uint64_t uni = vx_bitgrid_count(&b);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_PARITY;
    run_scan(m, &d, &b, &st);
    compare_ref("two spheres parity (xor)", m, &d.grid, VX_INSIDE_PARITY, &b, &iou);
    assert_true(iou >= 0.999);
    same_as_peel("two spheres parity", m, &d, &b);
    assert_true(vx_bitgrid_count(&b) < uni);
    vx_bitgrid_free(&b);
    for (int i = 0; i < 2; i++)
        vx_mesh_free(parts[i]);
    vx_mesh_free(m);
}

static void test_coincident_faces(void **state)
{
    /* Two boxes touching face to face, and the same box twice (winding 2:
     * nonzero solid, parity empty). */
    vx_mesh *parts[2] = {shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1}),
                         shape_box((double[]){1, 0, 0}, (double[]){2, 1, 1})};
    vx_mesh *m = shape_merge(parts, 2);
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 0.125, {16, 8, 8}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        d.inside = (vx_inside)rule;
        run_scan(m, &d, &b, &st);
        assert_int_equal(vx_bitgrid_count(&b), 1024);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
    vx_mesh_free(parts[1]);
    parts[1] = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    m = shape_merge(parts, 2);
    d.grid.dims[0] = 8;
    d.inside = VX_INSIDE_NONZERO;
    run_scan(m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 512);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_PARITY;
    run_scan(m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 0);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
    for (int i = 0; i < 2; i++)
        vx_mesh_free(parts[i]);
}

static void test_grid_cuts_mesh(void **state)
{
    /* A grid over part of a sphere: crossings before the grid start are
     * dropped, those beyond its end go to the row tails; counting from each
     * centre towards +x keeps the answer right. */
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {.grid = {{-0.3, -0.75, -1.1}, 1.0 / 32, {40, 30, 50}}};
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        d.inside = (vx_inside)rule;
        vx_bitgrid b;
        vx_voxelize_stats st;
        run_scan(m, &d, &b, &st);
        double iou;
        compare_ref(rule ? "cut sphere parity" : "cut sphere nonzero", m, &d.grid, (vx_inside)rule,
                    &b, &iou);
        assert_true(iou >= 0.999);
        same_as_peel("cut sphere", m, &d, &b);
        vx_bitgrid_free(&b);
    }
    for (int a = 0; a < 3; a++) {
        vx_voxelize_desc d1 = {.grid = {{-0.9, -0.9, -0.9}, 1.0 / 16, {29, 29, 29}}};
        d1.grid.dims[a] = 1;
        d1.grid.origin[a] = -0.03;
        vx_bitgrid b;
        vx_voxelize_stats st;
        run_scan(m, &d1, &b, &st);
        double iou;
        compare_ref("one voxel thick", m, &d1.grid, VX_INSIDE_NONZERO, &b, &iou);
        assert_true(iou >= 0.99);
        same_as_peel("one voxel thick", m, &d1, &b);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
    vx_mesh *e = vx_mesh_new();
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_scan(e, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 0);
    vx_bitgrid_free(&b);
    vx_mesh_free(e);
}

static void test_real_meshes_256(void **state)
{
    const char *names[] = {"spot_triangulated.obj", "fandisk.obj", "rocker-arm.obj"};
    for (int n = 0; n < 3; n++) {
        char path[512];
        snprintf(path, sizeof path, "%s/%s", VX_MESH_DIR, names[n]);
        vx_mesh *m = vx_obj_read_path(path, NULL, NULL);
        assert_non_null(m);
        vx_voxelize_desc d = {0};
        grid_res(m, 256, 1, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        double t0 = now_s();
        run_scan(m, &d, &b, &st);
        double t1 = now_s();
        printf("%s: %.0f ms wall, draw %.1f ms, sums %.1f ms, upload %.1f ms, readback %.1f ms\n",
               names[n], 1e3 * (t1 - t0), st.gpu_peel_ms, st.gpu_fill_ms, st.upload_ms,
               st.readback_ms);
        double iou;
        compare_ref(names[n], m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
        assert_true(iou >= 0.999);
        vx_bitgrid_free(&b);
        /* Voxel for voxel with peel on the same slabs: a slab's window
         * transform depends on its rows, so near-ties at voxel centres may
         * fall either way with other slab heights (scan.c). */
        d.max_slab_rows = 16;
        run_scan(m, &d, &b, &st);
        same_as_peel(names[n], m, &d, &b);
        vx_bitgrid_free(&b);
        vx_mesh_free(m);
    }
}

static void test_slabs(void **state)
{
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_triangulated.obj", NULL, NULL);
    assert_non_null(m);
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        vx_voxelize_desc d = {.inside = (vx_inside)rule};
        grid_res(m, 70, 1, &d.grid);
        vx_bitgrid one, many;
        vx_voxelize_stats st;
        run_scan(m, &d, &one, &st);
        assert_int_equal(st.chunks, 1);
        for (int rows = 1; rows <= 7; rows += 6) {
            d.max_slab_rows = rows;
            run_scan(m, &d, &many, &st);
            assert_int_equal(st.chunks, (d.grid.dims[2] + rows - 1) / rows);
            size_t words = one.wx * d.grid.dims[1] * d.grid.dims[2];
            assert_memory_equal(one.bits, many.bits, words * 4);
            printf("slabs rule %d: %d chunks, %llu voxels, identical\n", rule, st.chunks,
                   (unsigned long long)vx_bitgrid_count(&one));
            vx_bitgrid_free(&many);
        }
        d.max_slab_rows = 0;
        same_as_peel("spot 70", m, &d, &one);
        assert_true(vx_bitgrid_count(&one) > 1000);
        vx_bitgrid_free(&one);
    }
    vx_mesh_free(m);
}

static int stop_at(void *ud, double f, vx_err *err)
{
    int *calls = ud;
    assert_true(f >= 0 && f <= 1);
    if (++*calls == 3) return vx_err_set(err, VX_ECANCELED, "stopped_by_test", "stop");
    return 0;
}

static int count_calls(void *ud, double f, vx_err *err)
{
    (*(int *)ud)++;
    return 0;
}

static void test_limits_and_progress(void **state)
{
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {0};
    grid_res(m, 64, 1, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    d.max_memory = 40000; /* less than the 66^3 bits themselves */
    assert_int_equal(vx_voxelize_scan(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_string_equal(err.code, "job_memory_limit");
    assert_null(b.bits);
    /* enough for the grid but not for one slab of counters: slabs shrink */
    d.max_memory = 400000;
    run_scan(m, &d, &b, &st);
    printf("max_memory 400000: %d chunks\n", st.chunks);
    assert_true(st.chunks > 1);
    vx_bitgrid full;
    d.max_memory = 0;
    run_scan(m, &d, &full, &st);
    assert_memory_equal(b.bits, full.bits, b.wx * d.grid.dims[1] * d.grid.dims[2] * 4);
    vx_bitgrid_free(&b);
    vx_bitgrid_free(&full);

    int calls = 0;
    d.progress = count_calls;
    d.ud = &calls;
    d.max_slab_rows = 20;
    run_scan(m, &d, &b, &st);
    printf("progress calls: %d for %d chunks\n", calls, st.chunks);
    assert_true(calls >= st.chunks);
    vx_bitgrid_free(&b);
    calls = 0;
    d.progress = stop_at;
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize_scan(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "stopped_by_test");
    assert_int_equal(calls, 3);
    assert_null(b.bits);
    /* the same through the dispatcher (auto runs scan) */
    calls = 0;
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "stopped_by_test");
    assert_null(b.bits);
    vx_mesh_free(m);
}

static void test_overflow(void **state)
{
    /* 33000 copies of one box: every ray enters 33000 times inside one
     * voxel (x = 1 in a padded grid), beyond the 16-bit counters. scan
     * fails with too_many_crossings; auto falls back to peel. */
    enum { COPIES = 33000 };
    vx_mesh *one = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    size_t nt = 12 * (size_t)COPIES;
    uint32_t *idx = malloc(nt * 3 * sizeof *idx);
    assert_non_null(idx);
    for (size_t c = 0; c < COPIES; c++)
        memcpy(idx + 36 * c, one->tri, 36 * sizeof *idx);
    vx_mesh *m = shape_mesh_from(one->nverts, one->pos, nt, idx);
    free(idx);
    vx_voxelize_desc d = {.grid = {{-0.25, -0.25, -0.25}, 0.25, {6, 6, 6}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    assert_int_equal(vx_voxelize_scan(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "too_many_crossings");
    assert_null(b.bits);
    memset(&err, 0, sizeof err);
    d.max_layers = 4;
    int rc = vx_voxelize(vx_test_gl, m, &d, &b, &st, &err);
    if (rc) fprintf(stderr, "auto: %s: %s\n", err.code, err.message);
    assert_int_equal(rc, 0);
    assert_string_equal(st.method, "peel");
    assert_int_equal(st.voxels_inside, 64);
    vx_bitgrid_free(&b);
    /* below the limit: 3 copies counted exactly (winding 3, parity odd) */
    vx_mesh *parts[3] = {one, one, one};
    vx_mesh *three = shape_merge(parts, 3);
    d.max_layers = 0;
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        d.inside = (vx_inside)rule;
        run_scan(three, &d, &b, &st);
        assert_int_equal(st.voxels_inside, 64);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(three);
    vx_mesh_free(m);
    vx_mesh_free(one);
}

static void test_dispatcher(void **state)
{
    vx_mesh *m = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    vx_voxelize_desc d = {0};
    grid_res(m, 8, 1, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    const struct {
        vx_method method;
        vx_inside inside;
        vx_fill fill;
        const char *ran;
    } cases[] = {
        {VX_METHOD_AUTO, VX_INSIDE_NONZERO, VX_FILL_SOLID, "scan"},
        {VX_METHOD_AUTO, VX_INSIDE_PARITY, VX_FILL_SOLID, "scan"},
        {VX_METHOD_AUTO, VX_INSIDE_ROBUST, VX_FILL_SOLID, "peel"},
        {VX_METHOD_AUTO, VX_INSIDE_NONZERO, VX_FILL_SURFACE, "peel"},
        {VX_METHOD_SCAN, VX_INSIDE_NONZERO, VX_FILL_SOLID, "scan"},
        {VX_METHOD_SCAN, VX_INSIDE_ROBUST, VX_FILL_SOLID, "peel"},
        {VX_METHOD_SCAN, VX_INSIDE_NONZERO, VX_FILL_SURFACE, "peel"},
        {VX_METHOD_PEEL, VX_INSIDE_NONZERO, VX_FILL_SOLID, "peel"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        d.method = cases[i].method;
        d.inside = cases[i].inside;
        d.fill = cases[i].fill;
        memset(&err, 0, sizeof err);
        int rc = vx_voxelize(vx_test_gl, m, &d, &b, &st, &err);
        if (rc) fprintf(stderr, "case %zu: %s: %s\n", i, err.code, err.message);
        assert_int_equal(rc, 0);
        assert_string_equal(st.method, cases[i].ran);
        if (d.fill == VX_FILL_SOLID) assert_int_equal(st.voxels_inside, 512);
        else assert_true(st.voxels_inside > 0);
        vx_bitgrid_free(&b);
    }
    /* no supersampling with scan */
    d.method = VX_METHOD_SCAN;
    d.inside = VX_INSIDE_NONZERO;
    d.fill = VX_FILL_SOLID;
    d.supersample = 2;
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "invalid_params");
    vx_mesh_free(m);
}

/* Diagnostics (VX_SCAN_DIAG=mesh.obj:res): scan vs peel on a big grid;
 * every differing voxel is checked against the reference on its row. */
static void test_diag(void **state)
{
    const char *spec = getenv("VX_SCAN_DIAG");
    if (!spec) skip();
    char path[512];
    int res = 1024;
    snprintf(path, sizeof path, "%s", spec);
    char *colon = strrchr(path, ':');
    if (colon) *colon = 0, res = atoi(colon + 1);
    vx_mesh *m = vx_obj_read_path(path, NULL, NULL);
    assert_non_null(m);
    vx_voxelize_desc d = {0};
    grid_res(m, res, 0, &d.grid);
    if (getenv("VX_SCAN_DIAG_ROWS")) d.max_slab_rows = atoi(getenv("VX_SCAN_DIAG_ROWS"));
    vx_bitgrid b, p;
    vx_voxelize_stats st, pst;
    double t0 = now_s();
    run_scan(m, &d, &b, &st);
    double t1 = now_s();
    vx_err err = {0};
    assert_int_equal(vx_voxelize_peel(vx_test_gl, m, &d, &p, &pst, &err), 0);
    double t2 = now_s();
    printf("scan %.0f ms (draw %.1f sums %.1f upload %.1f readback %.1f, %d chunks); peel %.0f ms "
           "(peel %.1f fill %.1f, %d layers)\n",
           1e3 * (t1 - t0), st.gpu_peel_ms, st.gpu_fill_ms, st.upload_ms, st.readback_ms, st.chunks,
           1e3 * (t2 - t1), pst.gpu_peel_ms, pst.gpu_fill_ms, pst.layers);
    int shown = 0;
    for (int k = 0; k < d.grid.dims[2]; k++)
        for (int j = 0; j < d.grid.dims[1]; j++) {
            size_t w0 = ((size_t)k * d.grid.dims[1] + j) * b.wx;
            int differ = 0;
            for (size_t w = 0; w < b.wx; w++)
                differ |= b.bits[w0 + w] != p.bits[w0 + w];
            if (!differ || shown >= 20) continue;
            vx_grid row = d.grid;
            row.origin[1] += j * d.grid.h;
            row.origin[2] += k * d.grid.h;
            row.dims[1] = row.dims[2] = 1;
            uint8_t *ref = malloc((size_t)row.dims[0]);
            assert_int_equal(ref_voxelize(m, &row, VX_INSIDE_NONZERO, ref), 0);
            for (int i = 0; i < d.grid.dims[0]; i++)
                if (vx_bitgrid_get(&b, i, j, k) != vx_bitgrid_get(&p, i, j, k)) {
                    printf("  (%d,%d,%d): scan %d peel %d ref %d\n", i, j, k,
                           vx_bitgrid_get(&b, i, j, k), vx_bitgrid_get(&p, i, j, k), ref[i]);
                    shown++;
                }
            free(ref);
        }
    vx_bitgrid_free(&b);
    vx_bitgrid_free(&p);
    vx_mesh_free(m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cube_exact),
        cmocka_unit_test(test_box_on_boundaries),
        cmocka_unit_test(test_sphere_torus),
        cmocka_unit_test(test_hollow_and_nested),
        cmocka_unit_test(test_overlapping_spheres),
        cmocka_unit_test(test_coincident_faces),
        cmocka_unit_test(test_grid_cuts_mesh),
        cmocka_unit_test(test_real_meshes_256),
        cmocka_unit_test(test_slabs),
        cmocka_unit_test(test_limits_and_progress),
        cmocka_unit_test(test_overflow),
        cmocka_unit_test(test_dispatcher),
        cmocka_unit_test(test_diag),
    };
    return cmocka_run_group_tests(tests, vx_test_gl_setup, vx_test_gl_teardown);
}
