/* The two crossing-counting solid engines, peel (seed 000, src/voxel/peel.c)
 * and scan (src/voxel/scan.c), on one table of cases run with each: exact
 * counts for boxes, analytic volumes, the CPU reference (ref_voxel.h), and
 * scan voxel for voxel against peel. Engine-only features live in
 * test_peel.c (robust, surface, big grids) and the scan-only ones (16-bit
 * counter overflow, the dispatcher's fallbacks) at the end of this file. */
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
#include "voxel/faces_int.h"
#include "voxel/voxel.h"
#include "voxel/xing.h"

typedef int (*engine_fn)(vx_gl *, const vx_mesh *, const vx_voxelize_desc *, vx_bitgrid *,
                         vx_voxelize_stats *, vx_err *);

typedef struct engine {
    const char *name;
    engine_fn run;
    vx_inside last_rule; /* the inside rules it takes: NONZERO..last_rule */
    int peels;           /* reports depth layers */
} engine;

static const engine peel = {"peel", vx_voxelize_peel, VX_INSIDE_ROBUST, 1};
static const engine scan = {"scan", vx_voxelize_scan, VX_INSIDE_PARITY, 0};

static int cpu_run(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                   vx_voxelize_stats *st, vx_err *err)
{
    (void)gl;
    return vx_voxelize_cpu(m, d, out, st, err);
}
static const engine cpu = {"cpu", cpu_run, VX_INSIDE_PARITY, 0};

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

static void run(const engine *e, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                vx_voxelize_stats *st)
{
    vx_err err = {0};
    int rc = e->run(vx_test_gl, m, d, out, st, &err);
    if (rc) fprintf(stderr, "%s: %s: %s\n", e->name, err.code, err.message);
    assert_int_equal(rc, 0);
    assert_string_equal(st->method, e->name);
    if (!e->peels) assert_int_equal(st->layers, 0);
}

/* ref_compare with the engine's name in the printed line. */
static size_t compare_ref(const engine *e, const char *what, const vx_mesh *m, const vx_grid *g,
                          vx_inside rule, const vx_bitgrid *b, double *iou)
{
    char label[96];
    snprintf(label, sizeof label, "%s %s", e->name, what);
    size_t mis = ref_compare(label, m, g, rule, b, iou);
    assert_true(mis != (size_t)-1);
    return mis;
}

/* Any engine but peel against peel on the same request: voxel for voxel. */
static void same_as_peel(const engine *e, const char *what, const vx_mesh *m,
                         const vx_voxelize_desc *d, const vx_bitgrid *b)
{
    if (e == &peel) return;
    vx_bitgrid p;
    vx_voxelize_stats st;
    run(&peel, m, d, &p, &st);
    size_t words = b->wx * (size_t)d->grid.dims[1] * d->grid.dims[2], diff = 0;
    for (size_t w = 0; w < words; w++)
        diff += (size_t)__builtin_popcount(b->bits[w] ^ p.bits[w]);
    printf("%-28s %s vs peel: %zu voxels differ\n", what, e->name, diff);
    assert_int_equal(diff, 0);
    vx_bitgrid_free(&p);
}

/* The reference and peel agree with a result (IoU at least min_iou). */
static void check(const engine *e, const char *what, const vx_mesh *m, const vx_voxelize_desc *d,
                  const vx_bitgrid *b, double min_iou)
{
    double iou;
    compare_ref(e, what, m, &d->grid, d->inside, b, &iou);
    assert_true(iou >= min_iou);
    same_as_peel(e, what, m, d, b);
}

static void grid_res(const vx_mesh *m, int res, int pad, vx_grid *g)
{
    assert_int_equal(vx_grid_from_resolution(m, res, pad, g, NULL), 0);
}

static double volume(const vx_bitgrid *b, const vx_grid *g)
{
    return (double)vx_bitgrid_count(b) * pow(g->h, 3);
}

/* ---- the shared table ------------------------------------------------- */

static void test_cube_exact(void **state)
{
    const engine *e = *state;
    vx_mesh *m = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    for (int flipped = 0; flipped <= 1; flipped++) {
        for (int pad = 0; pad <= 2; pad += 2)
            for (int rule = VX_INSIDE_NONZERO; rule <= (int)e->last_rule; rule++) {
                vx_voxelize_desc d = {.inside = (vx_inside)rule};
                grid_res(m, 8, pad, &d.grid);
                vx_bitgrid b;
                vx_voxelize_stats st;
                run(e, m, &d, &b, &st);
                assert_int_equal(vx_bitgrid_count(&b), 512);
                assert_int_equal(st.voxels_inside, 512);
                /* cpu's chunks are its bands of rows, one task each */
                if (e != &cpu) assert_int_equal(st.chunks, 1);
                if (e->peels) assert_int_equal(st.layers, 2);
                vx_bitgrid_free(&b);
            }
        /* inward faces: winding -1, still solid for nonzero and parity */
        shape_flip(m);
    }
    vx_mesh_free(m);
}

static void test_box_on_boundaries(void **state)
{
    const engine *e = *state;
    /* faces on cell boundaries (h = 0.25), odd grid sizes, a grid wider
     * than 32 voxels along x (several words per row) */
    vx_mesh *m = shape_box((double[]){0.5, 0.25, 0}, (double[]){10.25, 1.75, 1.5});
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 0.25, {45, 11, 9}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    run(e, m, &d, &b, &st);
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
    run(e, m, &d, &b, &st);
    assert_int_equal(compare_ref(e, "box through centres", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou),
                     0);
    same_as_peel(e, "box through centres", m, &d, &b);
    vx_bitgrid_free(&b);
    /* narrow grids: one to three voxels along x (scan: a half-used last
     * 16-bit slot of the row) */
    for (int nx = 1; nx <= 3; nx++) {
        vx_voxelize_desc d1 = {.grid = {{0, 0, 0}, 0.25, {nx, 11, 9}}};
        run(e, m, &d1, &b, &st);
        compare_ref(e, "narrow grid", m, &d1.grid, VX_INSIDE_NONZERO, &b, &iou);
        assert_true(iou == 1.0 || vx_bitgrid_count(&b) == 0);
        same_as_peel(e, "narrow grid", m, &d1, &b);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
}

static void test_sphere_torus(void **state)
{
    const engine *e = *state;
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        vx_voxelize_desc d = {.inside = (vx_inside)rule};
        grid_res(m, 64, 1, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        run(e, m, &d, &b, &st);
        double vol = volume(&b, &d.grid), exact = 4.0 / 3 * M_PI;
        printf("sphere 64^3: volume %.5f analytic %.5f (%.3f%%), polyhedron %.5f\n", vol, exact,
               100 * (vol / exact - 1), shape_signed_volume(m));
        assert_true(fabs(vol / exact - 1) < 0.01);
        check(e, rule ? "sphere parity" : "sphere nonzero", m, &d, &b, 0.999);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
    m = shape_param_mesh(96, 48, 0, 0, 0.1, 0.2, 0.3, 1.0, 0.35);
    vx_voxelize_desc d = {0};
    grid_res(m, 80, 2, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    run(e, m, &d, &b, &st);
    check(e, "torus", m, &d, &b, 0.999);
    if (e->peels) assert_int_equal(st.layers, 4);
    double vol = volume(&b, &d.grid), exact = 2 * M_PI * M_PI * 1.0 * 0.35 * 0.35;
    assert_true(fabs(vol / exact - 1) < 0.02);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

static void test_hollow_and_nested(void **state)
{
    const engine *e = *state;
    vx_mesh *parts[3] = {shape_sphere(0, 0, 0, 1, 0), shape_sphere(0, 0, 0, 0.6, 1),
                         shape_sphere(0, 0, 0, 0.3, 0)};
    vx_mesh *hollow = shape_merge(parts, 2), *nested = shape_merge(parts, 3);
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        vx_voxelize_desc d = {.inside = (vx_inside)rule};
        grid_res(hollow, 64, 1, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        run(e, hollow, &d, &b, &st);
        /* the void is empty: no centre within 0.58 of the centre is set */
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
        check(e, rule ? "hollow parity" : "hollow nonzero", hollow, &d, &b, 0.999);
        if (e->peels) assert_int_equal(st.layers, 4);
        vx_bitgrid_free(&b);

        /* a ball in the void: three solid layers along a ray */
        run(e, nested, &d, &b, &st);
        if (e->peels) assert_int_equal(st.layers, 6);
        check(e, rule ? "ball in hollow parity" : "ball in hollow nonzero", nested, &d, &b, 0.999);
        double vol = volume(&b, &d.grid), exact = 4.0 / 3 * M_PI * (1 - 0.216 + 0.027);
        assert_true(fabs(vol / exact - 1) < 0.02);
        vx_bitgrid_free(&b);
        if (e->peels) { /* max_layers below what the mesh needs fails clearly */
            d.max_layers = 5;
            vx_err err = {0};
            assert_int_equal(e->run(vx_test_gl, nested, &d, &b, &st, &err), -1);
            assert_string_equal(err.code, "too_many_layers");
            assert_null(b.bits);
        }
    }
    for (int i = 0; i < 3; i++)
        vx_mesh_free(parts[i]);
    vx_mesh_free(hollow);
    vx_mesh_free(nested);
}

static void test_overlapping_spheres(void **state)
{
    const engine *e = *state;
    vx_mesh *parts[2] = {shape_sphere(0, 0, 0, 1, 0), shape_sphere(0.7, 0.3, 0.1, 0.8, 0)};
    vx_mesh *m = shape_merge(parts, 2);
    vx_voxelize_desc d = {0};
    grid_res(m, 64, 1, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    run(e, m, &d, &b, &st);
    check(e, "two spheres nonzero (union)", m, &d, &b, 0.999);
    uint64_t uni = vx_bitgrid_count(&b);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_PARITY;
    run(e, m, &d, &b, &st);
    check(e, "two spheres parity (xor)", m, &d, &b, 0.999);
    assert_true(vx_bitgrid_count(&b) < uni);
    vx_bitgrid_free(&b);
    for (int i = 0; i < 2; i++)
        vx_mesh_free(parts[i]);
    vx_mesh_free(m);
}

static void test_coincident_faces(void **state)
{
    const engine *e = *state;
    /* Two boxes touching face to face: at x = 1 two crossings share one
     * depth (peel keeps one fragment per depth; its per-layer counts must
     * still see both, or the second box would come out empty). */
    vx_mesh *parts[2] = {shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1}),
                         shape_box((double[]){1, 0, 0}, (double[]){2, 1, 1})};
    vx_mesh *m = shape_merge(parts, 2);
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 0.125, {16, 8, 8}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    for (int rule = VX_INSIDE_NONZERO; rule <= (int)e->last_rule; rule++) {
        d.inside = (vx_inside)rule;
        run(e, m, &d, &b, &st);
        assert_int_equal(vx_bitgrid_count(&b), 1024);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
    /* The same box twice: winding 2 inside (nonzero: solid), four crossings
     * per ray (parity: empty), as the reference says. */
    vx_mesh_free(parts[1]);
    parts[1] = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    m = shape_merge(parts, 2);
    d.grid.dims[0] = 8;
    d.inside = VX_INSIDE_NONZERO;
    run(e, m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 512);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_PARITY;
    run(e, m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 0);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
    for (int i = 0; i < 2; i++)
        vx_mesh_free(parts[i]);
}

static int count_calls(void *ud, double f, vx_err *err);

/* Twelve boxes in a row along x: 24 layers per ray, more than peel's first
 * pass keeps (16), so it takes a second pass; exact counts, the layer
 * bound to the layer, progress between passes, and the same boxes twice
 * (coincident crossings in both passes). */
static void test_many_layers(void **state)
{
    const engine *e = *state;
    vx_mesh *parts[24];
    for (int i = 0; i < 12; i++)
        parts[i] = parts[12 + i] =
            shape_box((double[]){2.0 * i, 0, 0}, (double[]){2.0 * i + 1, 1, 1});
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 0.25, {96, 4, 4}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    for (int copies = 1; copies <= 2; copies++) {
        vx_mesh *m = shape_merge(parts, 12 * copies);
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
            d.inside = (vx_inside)rule;
            int calls = 0;
            d.progress = count_calls;
            d.ud = &calls;
            run(e, m, &d, &b, &st);
            d.progress = NULL;
            printf("%s %d copies %s: %llu voxels, %d layers, %d passes, %d progress calls\n",
                   e->name, copies, rule ? "parity" : "nonzero",
                   (unsigned long long)st.voxels_inside, st.layers, st.passes, calls);
            int empty = copies == 2 && rule == VX_INSIDE_PARITY;
            assert_int_equal(vx_bitgrid_count(&b), empty ? 0 : 12 * 64);
            if (e->peels) {
                assert_int_equal(st.layers, 24);
                /* 16 + 16 slots; the copies add a pass that counts them */
                assert_int_equal(st.passes, 2 + (copies == 2));
                assert_true(calls >= 2);
            }
            check(e, copies == 1 ? "12 boxes" : "12 boxes twice", m, &d, &b, 1.0);
            vx_bitgrid_free(&b);
        }
        if (e->peels) { /* max_layers bounds the layers exactly */
            vx_err err = {0};
            d.max_layers = 23;
            assert_int_equal(e->run(vx_test_gl, m, &d, &b, &st, &err), -1);
            assert_string_equal(err.code, "too_many_layers");
            assert_null(b.bits);
            d.max_layers = 24;
            run(e, m, &d, &b, &st);
            assert_int_equal(st.passes, 2 + (copies == 2)); /* 16 + 8 slots */
            vx_bitgrid_free(&b);
            d.max_layers = 0;
        }
        vx_mesh_free(m);
    }
    for (int i = 0; i < 12; i++)
        vx_mesh_free(parts[i]);
}

static void test_grid_cuts_mesh(void **state)
{
    const engine *e = *state;
    /* A grid over part of a sphere (the mesh reaches outside it along every
     * axis, also before the grid along the rays): crossings outside the
     * grid still count. */
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {.grid = {{-0.3, -0.75, -1.1}, 1.0 / 32, {40, 30, 50}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        d.inside = (vx_inside)rule;
        run(e, m, &d, &b, &st);
        check(e, rule ? "cut sphere parity" : "cut sphere nonzero", m, &d, &b, 0.999);
        vx_bitgrid_free(&b);
    }
    /* degenerate grids: one voxel thick along each axis in turn */
    for (int a = 0; a < 3; a++) {
        vx_voxelize_desc d1 = {.grid = {{-0.9, -0.9, -0.9}, 1.0 / 16, {29, 29, 29}}};
        d1.grid.dims[a] = 1;
        d1.grid.origin[a] = -0.03;
        for (int rule = VX_INSIDE_NONZERO; rule <= (int)e->last_rule; rule++) {
            d1.inside = (vx_inside)rule;
            run(e, m, &d1, &b, &st);
            double iou;
            compare_ref(e, "one voxel thick", m, &d1.grid, VX_INSIDE_NONZERO, &b, &iou);
            assert_true(iou >= 0.99);
            if (rule == VX_INSIDE_NONZERO) same_as_peel(e, "one voxel thick", m, &d1, &b);
            vx_bitgrid_free(&b);
        }
    }
    vx_mesh_free(m);
    /* no triangles at all: an empty grid */
    vx_mesh *empty = vx_mesh_new();
    run(e, empty, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 0);
    assert_int_equal(st.layers, 0);
    vx_bitgrid_free(&b);
    vx_mesh_free(empty);
}

static void test_real_meshes_256(void **state)
{
    const engine *e = *state;
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
        run(e, m, &d, &b, &st);
        printf("%s %s: %.0f ms wall, draw/peel %.1f ms, sums/fill %.1f ms, layers %d, upload %.1f "
               "ms, readback %.1f ms\n",
               e->name, names[n], 1e3 * (now_s() - t0), st.gpu_peel_ms, st.gpu_fill_ms, st.layers,
               st.upload_ms, st.readback_ms);
        double iou;
        compare_ref(e, names[n], m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
        assert_true(iou >= 0.999);
        /* Voxel for voxel with peel, and on slabs (cpu: bands) of 16 rows
         * the same voxels: no method's crossings depend on how the grid is
         * cut. (Scan and peel on 16-row slabs differed from their default
         * slabs by 10 voxels on fandisk on llvmpipe while the viewport
         * ended at the slab and clipped the triangles crossing it;
         * src/voxel/xing.h, rule 2.) */
        same_as_peel(e, names[n], m, &d, &b);
        vx_bitgrid b16;
        d.max_slab_rows = 16;
        run(e, m, &d, &b16, &st);
        assert_memory_equal(b.bits, b16.bits, b.wx * d.grid.dims[1] * d.grid.dims[2] * 4);
        vx_bitgrid_free(&b16);
        vx_bitgrid_free(&b);
        vx_mesh_free(m);
    }
}

static void test_slabs(void **state)
{
    const engine *e = *state;
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_triangulated.obj", NULL, NULL);
    assert_non_null(m);
    /* every inside rule, and peel's surface fill */
    int modes = (int)e->last_rule + 1 + (e->peels ? 1 : 0);
    for (int mode = 0; mode < modes; mode++) {
        vx_voxelize_desc d = {0};
        if (mode <= (int)e->last_rule)
            d.inside = (vx_inside)mode;
        else
            d.fill = VX_FILL_SURFACE;
        grid_res(m, 70, 1, &d.grid);
        vx_bitgrid one, many;
        vx_voxelize_stats st;
        run(e, m, &d, &one, &st);
        if (e != &cpu) assert_int_equal(st.chunks, 1);
        for (int rows = 1; rows <= 7; rows += 6) {
            d.max_slab_rows = rows;
            run(e, m, &d, &many, &st);
            assert_int_equal(st.chunks, (d.grid.dims[2] + rows - 1) / rows);
            size_t words = one.wx * d.grid.dims[1] * d.grid.dims[2];
            assert_memory_equal(one.bits, many.bits, words * 4);
            printf("%s slabs mode %d: %d chunks, %llu voxels, identical\n", e->name, mode,
                   st.chunks, (unsigned long long)vx_bitgrid_count(&one));
            vx_bitgrid_free(&many);
        }
        assert_true(vx_bitgrid_count(&one) > 1000);
        d.max_slab_rows = 0;
        if (d.fill == VX_FILL_SOLID && mode <= VX_INSIDE_PARITY)
            same_as_peel(e, "spot 70", m, &d, &one);
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
    const engine *e = *state;
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {0};
    grid_res(m, 64, 1, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    d.max_memory = 40000; /* less than the 66^3 bits themselves */
    assert_int_equal(e->run(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_string_equal(err.code, "job_memory_limit");
    assert_null(b.bits);
    /* enough for the grid but not for one slab: slabs shrink to fit, and
     * the answer stays the same (cpu: its bands are small anyway; the
     * grid, 40 bytes a vertex and 24 a triangle for its setup and bins,
     * the crossings of the bands in flight) */
    d.max_memory = 400000 + vx_xing_bytes(m); /* + the positions the shaders read */
    if (e == &cpu) d.max_memory = 60000 + 40 * m->nverts + 24 * m->ntris + (128 << 10);
    run(e, m, &d, &b, &st);
    printf("%s max_memory %llu: %d chunks\n", e->name, (unsigned long long)d.max_memory, st.chunks);
    assert_true(st.chunks > 1);
    vx_bitgrid full;
    d.max_memory = 0;
    run(e, m, &d, &full, &st);
    assert_memory_equal(b.bits, full.bits, b.wx * d.grid.dims[1] * d.grid.dims[2] * 4);
    vx_bitgrid_free(&b);
    vx_bitgrid_free(&full);

    int calls = 0;
    d.progress = count_calls;
    d.ud = &calls;
    d.max_slab_rows = 20;
    run(e, m, &d, &b, &st);
    printf("%s progress calls: %d for %d chunks and %d passes\n", e->name, calls, st.chunks,
           st.passes);
    /* peel: once between passes and once per slab; scan: once per slab;
     * cpu: before and after its setup, before each band the calling
     * thread runs and at the end */
    assert_true(calls >= (e->peels ? st.passes : e == &cpu ? 3 : st.chunks));
    vx_bitgrid_free(&b);
    calls = 0;
    d.progress = stop_at;
    memset(&err, 0, sizeof err);
    assert_int_equal(e->run(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "stopped_by_test");
    assert_int_equal(calls, 3);
    assert_null(b.bits);
    /* the same through the dispatcher (auto runs cpu or scan) */
    calls = 0;
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "stopped_by_test");
    assert_null(b.bits);
    vx_mesh_free(m);
}

/* ---- scan's limits and the dispatcher ---------------------------------- */

static void test_overflow(void **state)
{
    /* 33000 copies of one box: every ray enters 33000 times inside one
     * voxel (x = 1 in a padded grid), beyond the 16-bit counters. scan
     * fails with too_many_crossings; auto runs cpu, which counts in 32
     * bits. */
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
    assert_string_equal(st.method, "cpu");
    assert_int_equal(st.voxels_inside, 64);
    vx_bitgrid_free(&b);
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        d.inside = (vx_inside)rule;
        run(&cpu, m, &d, &b, &st);
        /* winding 33000 inside: nonzero, but an even count */
        assert_int_equal(st.voxels_inside, rule == VX_INSIDE_NONZERO ? 64 : 0);
        vx_bitgrid_free(&b);
    }
    d.inside = VX_INSIDE_NONZERO;
    /* below the limit: 3 copies counted exactly (winding 3, parity odd) */
    vx_mesh *parts[3] = {one, one, one};
    vx_mesh *three = shape_merge(parts, 3);
    d.max_layers = 0;
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        d.inside = (vx_inside)rule;
        run(&scan, three, &d, &b, &st);
        assert_int_equal(st.voxels_inside, 64);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(three);
    vx_mesh_free(m);
    vx_mesh_free(one);
}

/* supersample 2 with the faces pattern (src/voxel/faces.c): every voxel's
 * count is the centre and its six face centres inside, whatever method
 * samples the four grids. A box with faces off every sample plane gives
 * exact counts; on a sphere the counts match the CPU winding number at
 * each sample point. */
static int box_has(const double lo[3], const double hi[3], const double p[3])
{
    for (int a = 0; a < 3; a++)
        if (p[a] < lo[a] || p[a] >= hi[a]) return 0;
    return 1;
}

static void test_faces_pattern(void **state)
{
    (void)state;
    static const int off[7][3] = {{0, 0, 0}, {-1, 0, 0}, {1, 0, 0}, {0, -1, 0},
                                  {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
    const double in = 0.5 - 1.0 / VX_GRID_SNAP; /* the samples just inside the faces */
    const double lo[3] = {1.3, 2.2, 0.7}, hi[3] = {5.8, 6.4, 3.1};
    vx_mesh *box = shape_box(lo, hi), *ball = shape_sphere(0.1, -0.05, 0.03, 1, 0);
    vx_voxelize_desc d = {
        .grid = {{0, 0, 0}, 1, {8, 8, 5}}, .supersample = 2, .samples = VX_SAMPLES_FACES};
    const vx_method methods[3] = {VX_METHOD_AUTO, VX_METHOD_PEEL, VX_METHOD_SLICE};
    const char *expect[3] = {"cpu", "peel", "slice"};
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    for (int mi = 0; mi < 3; mi++)
        for (int thr = 1; thr <= 7; thr += 3) {
            d.method = methods[mi];
            d.threshold = thr;
            int rc = vx_voxelize(vx_test_gl, box, &d, &b, &st, &err);
            if (rc) fprintf(stderr, "faces: %s: %s\n", err.code, err.message);
            assert_int_equal(rc, 0);
            assert_string_equal(st.method, expect[mi]);
            assert_non_null(b.counts);
            assert_int_equal(b.nsamples, 7);
            size_t bad = 0, set = 0;
            for (int k = 0; k < 5; k++)
                for (int j = 0; j < 8; j++)
                    for (int i = 0; i < 8; i++) {
                        int want = 0;
                        for (int q = 0; q < 7; q++) {
                            double p[3] = {i + 0.5 + in * off[q][0], j + 0.5 + in * off[q][1],
                                           k + 0.5 + in * off[q][2]};
                            want += box_has(lo, hi, p);
                        }
                        bad += b.counts[(k * 8 + j) * 8 + i] != want;
                        bad += vx_bitgrid_get(&b, i, j, k) != (want >= thr);
                        set += want >= thr;
                    }
            printf("faces box %s threshold %d: %zu set, %zu wrong\n", st.method, thr, set, bad);
            assert_int_equal(bad, 0);
            assert_int_equal(st.voxels_inside, set);
            vx_bitgrid_free(&b);
        }

    /* A box on voxel faces fills voxels 1..3 exactly: every sample of
     * those voxels is inside and none of the others', at every threshold
     * and by every method (samples on the faces counted the box's faces
     * for the voxel below them only: 8 voxels at threshold 7, a layer on
     * the low sides at 1). */
    vx_mesh *aligned = shape_box((double[]){1, 1, 1}, (double[]){4, 4, 4});
    const vx_method all[4] = {VX_METHOD_CPU, VX_METHOD_SCAN, VX_METHOD_PEEL, VX_METHOD_SLICE};
    vx_voxelize_desc da = {
        .grid = {{0, 0, 0}, 1, {6, 6, 6}}, .supersample = 2, .samples = VX_SAMPLES_FACES};
    for (int mi = 0; mi < 4; mi++)
        for (int thr = 1; thr <= 7; thr++) {
            da.method = all[mi];
            da.threshold = thr;
            assert_int_equal(vx_voxelize(vx_test_gl, aligned, &da, &b, &st, &err), 0);
            size_t bad = 0;
            for (int k = 0; k < 6; k++)
                for (int j = 0; j < 6; j++)
                    for (int i = 0; i < 6; i++) {
                        int in_box = i >= 1 && i <= 3 && j >= 1 && j <= 3 && k >= 1 && k <= 3;
                        bad += b.counts[(k * 6 + j) * 6 + i] != (in_box ? 7 : 0);
                        bad += vx_bitgrid_get(&b, i, j, k) != in_box;
                    }
            if (bad)
                fprintf(stderr, "aligned box %s threshold %d: %zu wrong\n", st.method, thr, bad);
            assert_int_equal(bad, 0);
            assert_int_equal(st.voxels_inside, 27);
            vx_bitgrid_free(&b);
        }
    vx_mesh_free(aligned);

    /* a sphere against the winding number at every sample */
    d.method = VX_METHOD_AUTO;
    d.threshold = 1;
    grid_res(ball, 20, 1, &d.grid);
    assert_int_equal(vx_voxelize(vx_test_gl, ball, &d, &b, &st, &err), 0);
    const vx_grid *g = &d.grid;
    size_t bad = 0, n = 0;
    for (int k = 0; k < g->dims[2]; k++)
        for (int j = 0; j < g->dims[1]; j++)
            for (int i = 0; i < g->dims[0]; i++, n++) {
                int want = 0;
                for (int q = 0; q < 7; q++) {
                    double p[3] = {g->origin[0] + (i + 0.5 + in * off[q][0]) * g->h,
                                   g->origin[1] + (j + 0.5 + in * off[q][1]) * g->h,
                                   g->origin[2] + (k + 0.5 + in * off[q][2]) * g->h};
                    want += ref_winding_number(ball, p) > 0.5;
                }
                bad += b.counts[n] != want;
            }
    printf("faces sphere: %zu of %zu counts differ from the winding number\n", bad, n);
    assert_true(bad <= n / 1000);
    vx_bitgrid_free(&b);

    /* what the pattern refuses */
    const struct {
        int threshold;
        vx_fill fill;
        uint64_t max_memory;
        const char *code;
    } no[] = {{8, VX_FILL_SOLID, 0, "invalid_params"},
              {1, VX_FILL_SURFACE, 0, "invalid_params"},
              {1, VX_FILL_SOLID, 20000, "job_memory_limit"}};
    for (size_t q = 0; q < sizeof no / sizeof *no; q++) {
        d.threshold = no[q].threshold;
        d.fill = no[q].fill;
        d.max_memory = no[q].max_memory;
        memset(&err, 0, sizeof err);
        assert_int_equal(vx_voxelize(vx_test_gl, ball, &d, &b, &st, &err), -1);
        assert_string_equal(err.code, no[q].code);
        assert_null(b.bits);
    }
    vx_mesh_free(box);
    vx_mesh_free(ball);
}

/* The seven sample grids of a voxel grid (zeroed) and the result with counts. */
static void alloc_samples(const vx_grid *grid, vx_bitgrid g[VX_FACES_SAMPLES], vx_bitgrid *out)
{
    vx_err err = {0};
    for (int s = 0; s < VX_FACES_SAMPLES; s++)
        assert_int_equal(vx_bitgrid_alloc(&g[s], grid, 0, &err), 0);
    assert_int_equal(vx_bitgrid_alloc(out, grid, 1, &err), 0);
}

static void free_samples(vx_bitgrid g[VX_FACES_SAMPLES], vx_bitgrid *out)
{
    for (int s = 0; s < VX_FACES_SAMPLES; s++)
        vx_bitgrid_free(&g[s]);
    vx_bitgrid_free(out);
}

static int stop_second(void *ud, double fraction, vx_err *err)
{
    (void)fraction;
    int *calls = ud;
    if (++*calls < 2) return 0;
    return vx_err_set(err, VX_ECANCELED, "canceled", "stopped");
}

/* The faces count on the GPU (vx_faces_count) on random sample grids:
 * widths on and off word and uint boundaries, one z row per slab up to the
 * whole grid, every threshold, against a voxel-by-voxel count here. */
static void test_faces_count_random(void **state)
{
    (void)state;
    srand(20261202);
    vx_err err = {0};
    size_t checked = 0;
    for (int it = 0; it < 60; it++) {
        vx_grid grid = {.h = 1, .dims = {1 + rand() % 100, 1 + rand() % 13, 1 + rand() % 9}};
        if (it == 0) grid.dims[0] = 200, grid.dims[1] = 37, grid.dims[2] = 11;
        const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
        const int density = rand() % 101; /* percent of sample bits set */
        vx_bitgrid g[VX_FACES_SAMPLES], out;
        alloc_samples(&grid, g, &out);
        for (int s = 0; s < VX_FACES_SAMPLES; s++) {
            const int *gd = g[s].grid.dims;
            for (int k = 0; k < gd[2]; k++)
                for (int j = 0; j < gd[1]; j++)
                    for (int i = 0; i < gd[0]; i++)
                        if (rand() % 100 < density)
                            g[s].bits[((size_t)k * gd[1] + j) * g[s].wx + i / 32] |= 1u << (i % 32);
        }
        memset(out.counts, 0xee, (size_t)nx * ny * nz);
        const int thr = 1 + it % 7;
        vx_faces_count_desc fd = {.max_rows = it % 3 == 0 ? 0 : 1 + rand() % nz};
        vx_voxelize_stats st = {0};
        int rc = vx_faces_count(vx_test_gl, g, thr, &out, &fd, &st, &err);
        if (rc) fprintf(stderr, "faces count: %s: %s\n", err.code, err.message);
        assert_int_equal(rc, 0);
        size_t bad = 0;
        for (int k = 0; k < nz; k++)
            for (int j = 0; j < ny; j++)
                for (int i = 0; i < nx; i++) {
                    int want = 0;
                    for (int q = 0; q < VX_FACES_SAMPLES; q++)
                        want += vx_bitgrid_get(&g[q], i, j, k);
                    bad += out.counts[((size_t)k * ny + j) * nx + i] != want;
                    bad += vx_bitgrid_get(&out, i, j, k) != (want >= thr);
                    checked++;
                }
        /* no bits beyond nx in any row */
        for (size_t r = 0; r < (size_t)ny * nz; r++)
            if (nx % 32) bad += (out.bits[r * out.wx + out.wx - 1] >> (nx % 32)) != 0;
        if (bad)
            fprintf(stderr, "faces count %dx%dx%d threshold %d rows %d: %zu wrong\n", nx, ny, nz,
                    thr, fd.max_rows, bad);
        assert_int_equal(bad, 0);
        free_samples(g, &out);
    }
    printf("faces count: %zu voxels of 60 random grids right\n", checked);

    /* a stop asked for between slabs ends the count with its error */
    {
        vx_grid grid = {.h = 1, .dims = {40, 9, 12}};
        vx_bitgrid g[VX_FACES_SAMPLES], out;
        alloc_samples(&grid, g, &out);
        int calls = 0;
        vx_faces_count_desc stop = {.max_rows = 2, .progress = stop_second, .ud = &calls};
        vx_voxelize_stats st = {0};
        assert_int_equal(vx_faces_count(vx_test_gl, g, 1, &out, &stop, &st, &err), -1);
        assert_string_equal(err.code, "canceled");
        assert_int_equal(calls, 2);
        free_samples(g, &out);
    }

    /* a budget too small for one z row */
    vx_grid grid = {.h = 1, .dims = {40, 40, 4}};
    vx_bitgrid g[VX_FACES_SAMPLES], out;
    alloc_samples(&grid, g, &out);
    vx_faces_count_desc small = {.max_bytes = 1000};
    vx_voxelize_stats st = {0};
    assert_int_equal(vx_faces_count(vx_test_gl, g, 1, &out, &small, &st, &err), -1);
    assert_string_equal(err.code, "job_memory_limit");
    free_samples(g, &out);
}

static void test_dispatcher_routes(void **state)
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
        {VX_METHOD_AUTO, VX_INSIDE_NONZERO, VX_FILL_SOLID, "cpu"},
        {VX_METHOD_AUTO, VX_INSIDE_PARITY, VX_FILL_SOLID, "cpu"},
        {VX_METHOD_CPU, VX_INSIDE_NONZERO, VX_FILL_SOLID, "cpu"},
        {VX_METHOD_CPU, VX_INSIDE_PARITY, VX_FILL_SOLID, "cpu"},
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
        if (d.fill == VX_FILL_SOLID)
            assert_int_equal(st.voxels_inside, 512);
        else
            assert_true(st.voxels_inside > 0);
        vx_bitgrid_free(&b);
    }
    /* no supersampling with scan or cpu; cpu fills solids by nonzero or
     * parity only */
    const struct {
        vx_method method;
        vx_inside inside;
        vx_fill fill;
        int ss;
    } refused[] = {
        {VX_METHOD_SCAN, VX_INSIDE_NONZERO, VX_FILL_SOLID, 2},
        {VX_METHOD_CPU, VX_INSIDE_NONZERO, VX_FILL_SOLID, 2},
        {VX_METHOD_CPU, VX_INSIDE_ROBUST, VX_FILL_SOLID, 1},
        {VX_METHOD_CPU, VX_INSIDE_NONZERO, VX_FILL_SURFACE, 1},
    };
    for (size_t i = 0; i < sizeof refused / sizeof refused[0]; i++) {
        d.method = refused[i].method;
        d.inside = refused[i].inside;
        d.fill = refused[i].fill;
        d.supersample = refused[i].ss;
        memset(&err, 0, sizeof err);
        assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), -1);
        assert_string_equal(err.code, "invalid_params");
    }
    vx_mesh_free(m);
}

static void test_dispatcher_params(void **state)
{
    vx_mesh *m = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    vx_voxelize_desc d = {0};
    grid_res(m, 8, 0, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    /* auto: cpu for nonzero/parity solid fills, peel for robust */
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), 0);
    assert_string_equal(st.method, "cpu");
    assert_int_equal(st.voxels_inside, 512);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_ROBUST;
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), 0);
    assert_string_equal(st.method, "peel");
    assert_int_equal(st.voxels_inside, 512);
    d.inside = VX_INSIDE_NONZERO;
    vx_bitgrid_free(&b);
    struct {
        vx_voxelize_desc d;
    } bad[6];
    for (int i = 0; i < 6; i++)
        bad[i].d = d;
    bad[0].d.grid.dims[1] = 0;
    bad[1].d.supersample = 3;
    bad[2].d.threshold = 9;
    bad[3].d.method = (vx_method)7;
    bad[4].d.inside = (vx_inside)-1;
    bad[5].d.fill = (vx_fill)2;
    for (int i = 0; i < 6; i++) {
        memset(&err, 0, sizeof err);
        assert_int_equal(vx_voxelize(vx_test_gl, m, &bad[i].d, &b, &st, &err), -1);
        assert_int_equal(err.kind, VX_EUNPROC);
        assert_string_equal(err.code, "invalid_params");
    }
    /* peel has no supersampling; auto sends supersample 2 to slice */
    d.method = VX_METHOD_PEEL;
    d.supersample = 2;
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), -1);
    d.method = VX_METHOD_AUTO;
    memset(&err, 0, sizeof err);
    if (vx_voxelize(vx_test_gl, m, &d, &b, &st, &err) == 0) {
        assert_string_equal(st.method, "slice");
        vx_bitgrid_free(&b);
    } else {
        assert_string_equal(err.code, "method_unavailable");
    }
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
    run(&scan, m, &d, &b, &st);
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

#define BOTH(f)                                                                                    \
    cmocka_unit_test_prestate(f, (void *)&peel), cmocka_unit_test_prestate(f, (void *)&scan),      \
        cmocka_unit_test_prestate(f, (void *)&cpu)

int main(void)
{
    const struct CMUnitTest tests[] = {
        BOTH(test_cube_exact),
        BOTH(test_box_on_boundaries),
        BOTH(test_sphere_torus),
        BOTH(test_hollow_and_nested),
        BOTH(test_overlapping_spheres),
        BOTH(test_coincident_faces),
        BOTH(test_many_layers),
        BOTH(test_grid_cuts_mesh),
        BOTH(test_real_meshes_256),
        BOTH(test_slabs),
        BOTH(test_limits_and_progress),
        cmocka_unit_test(test_overflow),
        cmocka_unit_test(test_faces_pattern),
        cmocka_unit_test(test_faces_count_random),
        cmocka_unit_test(test_dispatcher_routes),
        cmocka_unit_test(test_dispatcher_params),
        cmocka_unit_test(test_diag),
    };
    return cmocka_run_group_tests(tests, vx_test_gl_setup, vx_test_gl_teardown);
}
