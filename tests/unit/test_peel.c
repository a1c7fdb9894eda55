/* The depth-peeling voxelizer (seed 000) and the dispatcher, on a real GL
 * context, against analytic answers and the CPU reference (ref_voxel.h). */
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



/* Meshes: tests/support/shapes.h (shared with test_scan). */

/* ---- helpers ----------------------------------------------------------- */

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

static void run_peel(const vx_mesh *m, vx_voxelize_desc *d, vx_bitgrid *out, vx_voxelize_stats *st)
{
    vx_err err = {0};
    int rc = vx_voxelize_peel(vx_test_gl, m, d, out, st, &err);
    if (rc) fprintf(stderr, "vx_voxelize_peel: %s: %s\n", err.code, err.message);
    assert_int_equal(rc, 0);
    assert_string_equal(st->method, "peel");
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
    printf("%-28s %dx%dx%d ref=%zu gpu=%llu mismatches=%zu IoU=%.6f\n", what, g->dims[0],
           g->dims[1], g->dims[2], in, (unsigned long long)vx_bitgrid_count(b), mis, *iou);
    free(ref);
    return mis;
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
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_ROBUST; rule++) {
            vx_voxelize_desc d = {.inside = (vx_inside)rule};
            grid_res(m, 8, pad, &d.grid);
            vx_bitgrid b;
            vx_voxelize_stats st;
            run_peel(m, &d, &b, &st);
            assert_int_equal(vx_bitgrid_count(&b), 512);
            assert_int_equal(st.voxels_inside, 512);
            assert_int_equal(st.layers, 2);
            assert_int_equal(st.chunks, 1);
            vx_bitgrid_free(&b);
        }
    vx_mesh_free(m);
}

static void test_box_on_boundaries(void **state)
{
    /* faces on cell boundaries (h = 0.25), odd grid sizes, a grid wider
     * than 32 voxels along x (several words per row) */
    vx_mesh *m = shape_box((double[]){0.5, 0.25, 0}, (double[]){10.25, 1.75, 1.5});
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 0.25, {45, 11, 9}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_peel(m, &d, &b, &st);
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
    run_peel(m, &d, &b, &st);
    assert_int_equal(compare_ref("box through centres", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou),
                     0);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

static void test_sphere(void **state)
{
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {0};
    grid_res(m, 64, 1, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_peel(m, &d, &b, &st);
    double vol = (double)vx_bitgrid_count(&b) * pow(d.grid.h, 3), exact = 4.0 / 3 * M_PI;
    printf("sphere 64^3: volume %.5f analytic %.5f (%.3f%%), polyhedron %.5f\n", vol, exact,
           100 * (vol / exact - 1), shape_signed_volume(m));
    assert_true(fabs(vol / exact - 1) < 0.01);
    double iou;
    compare_ref("sphere nonzero", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
    assert_true(iou >= 0.999);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_PARITY;
    run_peel(m, &d, &b, &st);
    compare_ref("sphere parity", m, &d.grid, VX_INSIDE_PARITY, &b, &iou);
    assert_true(iou >= 0.999);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

static void test_torus(void **state)
{
    vx_mesh *m = shape_param_mesh(96, 48, 0, 0, 0.1, 0.2, 0.3, 1.0, 0.35);
    vx_voxelize_desc d = {0};
    grid_res(m, 80, 2, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_peel(m, &d, &b, &st);
    double iou;
    compare_ref("torus", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
    assert_true(iou >= 0.999);
    assert_int_equal(st.layers, 4);
    double vol = (double)vx_bitgrid_count(&b) * pow(d.grid.h, 3),
           exact = 2 * M_PI * M_PI * 1.0 * 0.35 * 0.35;
    printf("torus volume %.5f analytic %.5f\n", vol, exact);
    assert_true(fabs(vol / exact - 1) < 0.02);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

static void test_hollow_and_nested(void **state)
{
    vx_mesh *parts[3] = {shape_sphere(0, 0, 0, 1, 0), shape_sphere(0, 0, 0, 0.6, 1), shape_sphere(0, 0, 0, 0.3, 0)};
    vx_mesh *hollow = shape_merge(parts, 2), *nested = shape_merge(parts, 3);
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        vx_voxelize_desc d = {.inside = (vx_inside)rule};
        grid_res(hollow, 64, 1, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        run_peel(hollow, &d, &b, &st);
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
        double iou;
        compare_ref(rule ? "hollow parity" : "hollow nonzero", hollow, &d.grid, (vx_inside)rule, &b,
                    &iou);
        assert_true(iou >= 0.999);
        assert_int_equal(st.layers, 4);
        vx_bitgrid_free(&b);

        run_peel(nested, &d, &b, &st);
        assert_int_equal(st.layers, 6);
        compare_ref(rule ? "ball in hollow parity" : "ball in hollow nonzero", nested, &d.grid,
                    (vx_inside)rule, &b, &iou);
        assert_true(iou >= 0.999);
        double vol = (double)vx_bitgrid_count(&b) * pow(d.grid.h, 3),
               exact = 4.0 / 3 * M_PI * (1 - 0.216 + 0.027);
        printf("ball in hollow: volume %.5f analytic %.5f\n", vol, exact);
        assert_true(fabs(vol / exact - 1) < 0.02);
        vx_bitgrid_free(&b);
        /* max_layers below what the mesh needs fails clearly */
        d.max_layers = 5;
        vx_err err = {0};
        assert_int_equal(vx_voxelize_peel(vx_test_gl, nested, &d, &b, &st, &err), -1);
        assert_string_equal(err.code, "too_many_layers");
        assert_null(b.bits);
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
    run_peel(m, &d, &b, &st);
    compare_ref("two spheres nonzero (union)", m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
    assert_true(iou >= 0.999);
    uint64_t uni = vx_bitgrid_count(&b);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_PARITY;
    run_peel(m, &d, &b, &st);
    compare_ref("two spheres parity (xor)", m, &d.grid, VX_INSIDE_PARITY, &b, &iou);
    assert_true(iou >= 0.999);
    assert_true(vx_bitgrid_count(&b) < uni);
    vx_bitgrid_free(&b);
    for (int i = 0; i < 2; i++)
        vx_mesh_free(parts[i]);
    vx_mesh_free(m);
}

static void test_coincident_faces(void **state)
{
    /* Two boxes touching face to face: at x = 1 two crossings share one
     * depth. Peeling keeps one fragment per depth; the per-layer counts
     * must still see both, or the second box would come out empty. */
    vx_mesh *parts[2] = {shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1}),
                         shape_box((double[]){1, 0, 0}, (double[]){2, 1, 1})};
    vx_mesh *m = shape_merge(parts, 2);
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 0.125, {16, 8, 8}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_ROBUST; rule++) {
        d.inside = (vx_inside)rule;
        run_peel(m, &d, &b, &st);
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
    run_peel(m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 512);
    vx_bitgrid_free(&b);
    d.inside = VX_INSIDE_PARITY;
    run_peel(m, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 0);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
    for (int i = 0; i < 2; i++)
        vx_mesh_free(parts[i]);
}

static void test_grid_cuts_mesh(void **state)
{
    /* A grid over part of a sphere (the mesh reaches outside it along every
     * axis, also below the grid along the rays): crossings outside the grid
     * still count. */
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {.grid = {{-0.3, -0.75, -1.1}, 1.0 / 32, {40, 30, 50}}};
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        d.inside = (vx_inside)rule;
        vx_bitgrid b;
        vx_voxelize_stats st;
        run_peel(m, &d, &b, &st);
        double iou;
        compare_ref(rule ? "cut sphere parity" : "cut sphere nonzero", m, &d.grid, (vx_inside)rule,
                    &b, &iou);
        assert_true(iou >= 0.999);
        vx_bitgrid_free(&b);
    }
    /* degenerate grids: one voxel thick along each axis in turn */
    for (int a = 0; a < 3; a++) {
        vx_voxelize_desc d1 = {.grid = {{-0.9, -0.9, -0.9}, 1.0 / 16, {29, 29, 29}}};
        d1.grid.dims[a] = 1;
        d1.grid.origin[a] = -0.03;
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_ROBUST; rule++) {
            d1.inside = (vx_inside)rule;
            vx_bitgrid b;
            vx_voxelize_stats st;
            run_peel(m, &d1, &b, &st);
            double iou;
            compare_ref("one voxel thick", m, &d1.grid, VX_INSIDE_NONZERO, &b, &iou);
            assert_true(iou >= 0.99);
            vx_bitgrid_free(&b);
        }
    }
    vx_mesh_free(m);
    /* no triangles at all: an empty grid */
    vx_mesh *e = vx_mesh_new();
    vx_bitgrid b;
    vx_voxelize_stats st;
    run_peel(e, &d, &b, &st);
    assert_int_equal(vx_bitgrid_count(&b), 0);
    assert_int_equal(st.layers, 0);
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
        run_peel(m, &d, &b, &st);
        double t1 = now_s();
        printf("%s: %.0f ms wall, peel %.1f ms, fill %.3f ms, layers %d, upload %.1f ms, "
               "readback %.1f ms\n",
               names[n], 1e3 * (t1 - t0), st.gpu_peel_ms, st.gpu_fill_ms, st.layers, st.upload_ms,
               st.readback_ms);
        double iou;
        compare_ref(names[n], m, &d.grid, VX_INSIDE_NONZERO, &b, &iou);
        assert_true(iou >= 0.999);
        vx_bitgrid_free(&b);
        vx_mesh_free(m);
    }
}

/* Agreement of a bit grid with the winding number (> 0.5 inside) at the
 * sampled centres. */
static size_t winding_agree(const vx_mesh *m, const vx_bitgrid *b, const int (*pts)[3], int n)
{
    size_t agree = 0;
    const vx_grid *g = &b->grid;
    for (int q = 0; q < n; q++) {
        double c[3];
        for (int a = 0; a < 3; a++)
            c[a] = g->origin[a] + (pts[q][a] + .5) * g->h;
        agree +=
            (ref_winding_number(m, c) > 0.5) == vx_bitgrid_get(b, pts[q][0], pts[q][1], pts[q][2]);
    }
    return agree;
}

static void test_bunny_robust(void **state)
{
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/stanford-bunny.obj", NULL, NULL);
    assert_non_null(m);
    assert_true(m->boundary_edges > 0);
    vx_voxelize_desc d = {.inside = VX_INSIDE_ROBUST};
    grid_res(m, 64, 1, &d.grid);
    vx_bitgrid b, par;
    vx_voxelize_stats st;
    run_peel(m, &d, &b, &st);
    d.inside = VX_INSIDE_PARITY;
    run_peel(m, &d, &par, &st);
    /* 2000 uniform centres and 1000 where the robust grid changes along x
     * (the boundary, where mistakes would be) */
    enum { NU = 2000, NB = 1000 };
    static int pts[NU + NB][3];
    const int *dim = d.grid.dims;
    uint64_t s = 12345;
    int nb = 0;
    for (int q = 0; q < NU; q++) {
        s = s * 6364136223846793005ull + 1442695040888963407ull;
        size_t i = (size_t)(s >> 33) % ((size_t)dim[0] * dim[1] * dim[2]);
        pts[q][0] = (int)(i % dim[0]);
        pts[q][1] = (int)(i / dim[0] % dim[1]);
        pts[q][2] = (int)(i / dim[0] / dim[1]);
    }
    for (int k = 0; k < dim[2] && nb < NB; k += 3)
        for (int j = 0; j < dim[1] && nb < NB; j += 2)
            for (int i = 0; i + 1 < dim[0] && nb < NB; i++)
                if (vx_bitgrid_get(&b, i, j, k) != vx_bitgrid_get(&b, i + 1, j, k)) {
                    int in = vx_bitgrid_get(&b, i, j, k);
                    pts[NU + nb][0] = in ? i : i + 1;
                    pts[NU + nb][1] = j;
                    pts[NU + nb][2] = k;
                    nb++;
                }
    /* open mesh, single rules: the same crossings counted from each centre
     * towards +x as the reference does */
    for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
        vx_voxelize_desc d1 = {.grid = d.grid, .inside = (vx_inside)rule};
        vx_bitgrid b1;
        double iou;
        run_peel(m, &d1, &b1, &st);
        compare_ref(rule ? "bunny (open) parity" : "bunny (open) nonzero", m, &d.grid,
                    (vx_inside)rule, &b1, &iou);
        assert_true(iou >= 0.999);
        vx_bitgrid_free(&b1);
    }
    size_t ru = winding_agree(m, &b, pts, NU), rb = winding_agree(m, &b, pts + NU, nb);
    size_t pu = winding_agree(m, &par, pts, NU), pb = winding_agree(m, &par, pts + NU, nb);
    printf("bunny 64^3 vs winding number: robust %zu/%d uniform, %zu/%d boundary; parity only "
           "%zu/%d uniform, %zu/%d boundary; layers %d\n",
           ru, NU, rb, nb, pu, NU, pb, nb, st.layers);
    assert_true(ru >= (size_t)(0.995 * NU));
    assert_true(rb >= (size_t)(0.97 * nb));
    vx_bitgrid_free(&b);
    vx_bitgrid_free(&par);
    vx_mesh_free(m);
}

/* Midpoint subdivision 1 -> 4 of every `every`-th triangle (every = 1:
 * all, with shared edge midpoints so the mesh stays watertight; otherwise
 * T-junctions appear, which is fine for timing). */
static vx_mesh *subdivide(const vx_mesh *m, int every)
{
    size_t nt = m->ntris, nsplit = (nt + every - 1) / every;
    size_t nv = m->nverts + 3 * nsplit, nt2 = nt + 3 * nsplit;
    double *p = malloc(nv * 3 * sizeof *p);
    uint32_t *f = malloc(nt2 * 3 * sizeof *f);
    memcpy(p, m->pos, m->nverts * 3 * sizeof *p);
    size_t v = m->nverts, t2 = 0;
    for (size_t t = 0; t < nt; t++) {
        const uint32_t *a = m->tri + 3 * t;
        if (t % every) {
            memcpy(f + 3 * t2++, a, 3 * sizeof *f);
            continue;
        }
        uint32_t mid[3];
        for (int e = 0; e < 3; e++) {
            for (int k = 0; k < 3; k++)
                p[3 * v + k] = 0.5 * (m->pos[3 * a[e] + k] + m->pos[3 * a[(e + 1) % 3] + k]);
            mid[e] = (uint32_t)v++;
        }
        uint32_t q[12] = {a[0],   mid[0], mid[2], mid[0], a[1],   mid[1],
                          mid[2], mid[1], a[2],   mid[0], mid[1], mid[2]};
        memcpy(f + 3 * t2, q, sizeof q);
        t2 += 4;
    }
    vx_mesh *r = shape_mesh_from(v, p, t2, f);
    free(p);
    free(f);
    return r;
}

/* Where robust mode holds and where it fails (peel.c's header): a cube
 * missing its top is still right (only the z rays leak); missing its top
 * and its +x side, the z and x rays both leak inside and it comes out
 * empty. */
static void test_robust_limits(void **state)
{
    vx_mesh *cube = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    /* triangles 2, 3: top (z = 1); 10, 11: +x side */
    for (int open2 = 0; open2 < 2; open2++) {
        uint32_t f[36];
        size_t nt = 0;
        for (size_t t = 0; t < 12; t++) {
            if (t == 2 || t == 3 || (open2 && (t == 10 || t == 11))) continue;
            memcpy(f + 3 * nt++, cube->tri + 3 * t, 3 * sizeof *f);
        }
        vx_mesh *m = shape_mesh_from(8, cube->pos, nt, f);
        vx_voxelize_desc d = {.inside = VX_INSIDE_ROBUST};
        grid_res(m, 8, 1, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        run_peel(m, &d, &b, &st);
        uint64_t robust = vx_bitgrid_count(&b);
        vx_bitgrid_free(&b);
        d.inside = VX_INSIDE_PARITY;
        run_peel(m, &d, &b, &st);
        printf("cube missing %s: robust %llu voxels, parity along x %llu (solid: 512)\n",
               open2 ? "top and +x side" : "top", (unsigned long long)robust,
               (unsigned long long)vx_bitgrid_count(&b));
        vx_bitgrid_free(&b);
        if (open2)
            assert_int_equal(robust, 0);
        else
            assert_int_equal(robust, 512);
        vx_mesh_free(m);
    }
    vx_mesh_free(cube);
}

static void test_surface(void **state)
{
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {.fill = VX_FILL_SURFACE};
    grid_res(m, 48, 1, &d.grid);
    vx_bitgrid surf, solid;
    vx_voxelize_stats st;
    run_peel(m, &d, &surf, &st);
    const vx_grid *g = &d.grid;
    /* every voxel that holds a sampled surface point is set */
    uint64_t s = 99;
    for (size_t t = 0; t < m->ntris; t++)
        for (int q = 0; q < 8; q++) {
            s = s * 6364136223846793005ull + 1442695040888963407ull;
            double u = (double)(s >> 40) / (1 << 24);
            s = s * 6364136223846793005ull + 1442695040888963407ull;
            double v = (double)(s >> 40) / (1 << 24);
            if (u + v > 1) u = 1 - u, v = 1 - v;
            const double *a = m->pos + 3 * m->tri[3 * t], *b = m->pos + 3 * m->tri[3 * t + 1],
                         *c = m->pos + 3 * m->tri[3 * t + 2];
            int idx[3];
            for (int k = 0; k < 3; k++) {
                double p = a[k] + u * (b[k] - a[k]) + v * (c[k] - a[k]);
                idx[k] = (int)floor((p - g->origin[k]) / g->h);
            }
            assert_int_equal(vx_bitgrid_get(&surf, idx[0], idx[1], idx[2]), 1);
        }
    /* a solid boundary (a face-adjacent pair, one in, one out) always has
     * the surface crossing between the two centres, so one of the two
     * voxels is a surface voxel */
    d.fill = VX_FILL_SOLID;
    run_peel(m, &d, &solid, &st);
    size_t pairs = 0, solid_boundary_in_surface = 0, solid_boundary = 0;
    for (int k = 0; k < g->dims[2]; k++)
        for (int j = 0; j < g->dims[1]; j++)
            for (int i = 0; i + 1 < g->dims[0]; i++) {
                int a = vx_bitgrid_get(&solid, i, j, k), b = vx_bitgrid_get(&solid, i + 1, j, k);
                if (a == b) continue;
                pairs++;
                assert_true(vx_bitgrid_get(&surf, i, j, k) || vx_bitgrid_get(&surf, i + 1, j, k));
                solid_boundary++;
                solid_boundary_in_surface += vx_bitgrid_get(&surf, a ? i : i + 1, j, k);
            }
    printf("surface: %llu voxels, %zu in/out x pairs, solid boundary voxels in the surface set "
           "%zu/%zu\n",
           (unsigned long long)vx_bitgrid_count(&surf), pairs, solid_boundary_in_surface,
           solid_boundary);
    vx_bitgrid_free(&solid);
    vx_bitgrid_free(&surf);
    /* a plate thinner than a voxel vanishes in solid mode, not in surface */
    vx_mesh *plate = shape_box((double[]){0.15, 0.15, 0.42}, (double[]){0.85, 0.85, 0.44});
    vx_voxelize_desc dp = {.grid = {{0, 0, 0}, 0.1, {10, 10, 10}}};
    run_peel(plate, &dp, &solid, &st);
    assert_int_equal(vx_bitgrid_count(&solid), 0);
    dp.fill = VX_FILL_SURFACE;
    run_peel(plate, &dp, &surf, &st);
    assert_int_equal(vx_bitgrid_count(&surf), 8 * 8);
    vx_bitgrid_free(&solid);
    vx_bitgrid_free(&surf);
    /* a huge triangle (CPU path) gives the same voxels as when small */
    vx_mesh_free(plate);
    vx_mesh_free(m);
    /* spans most of a 128^3 grid: over SURF_GPU_WORK tests, so the CPU takes it */
    double tp[9] = {0.05, 0.1, 0.2, 100.0, 6.0, 80.0, 14.0, 110.0, 40.0};
    uint32_t ti[3] = {0, 1, 2};
    vx_mesh *big = shape_mesh_from(3, tp, 1, ti);
    vx_voxelize_desc db = {.grid = {{0, 0, 0}, 1.0, {128, 128, 128}}, .fill = VX_FILL_SURFACE};
    run_peel(big, &db, &surf, &st);
    /* brute force reference in the test */
    size_t missing = 0;
    for (int q = 0; q < 20000; q++) {
        s = s * 6364136223846793005ull + 1442695040888963407ull;
        double u = (double)(s >> 40) / (1 << 24);
        s = s * 6364136223846793005ull + 1442695040888963407ull;
        double v = (double)(s >> 40) / (1 << 24);
        if (u + v > 1) u = 1 - u, v = 1 - v;
        int idx[3];
        for (int k = 0; k < 3; k++)
            idx[k] = (int)floor(tp[k] + u * (tp[3 + k] - tp[k]) + v * (tp[6 + k] - tp[k]));
        missing += !vx_bitgrid_get(&surf, idx[0], idx[1], idx[2]);
    }
    printf("big triangle: %llu voxels, %zu sampled points missed\n",
           (unsigned long long)vx_bitgrid_count(&surf), missing);
    assert_int_equal(missing, 0);
    /* split 1 -> 4 the parts go to the GPU: the same voxels (up to the
     * rounding margin of the new midpoints) */
    vx_mesh *split = subdivide(big, 1);
    vx_bitgrid surf4;
    run_peel(split, &db, &surf4, &st);
    size_t words = surf.wx * 128 * 128, diff = 0;
    for (size_t w = 0; w < words; w++)
        diff += (size_t)__builtin_popcount(surf.bits[w] ^ surf4.bits[w]);
    printf("big triangle on the CPU vs split on the GPU: %llu vs %llu voxels, %zu differ\n",
           (unsigned long long)vx_bitgrid_count(&surf),
           (unsigned long long)vx_bitgrid_count(&surf4), diff);
    assert_true(diff <= vx_bitgrid_count(&surf) / 1000);
    vx_bitgrid_free(&surf4);
    vx_mesh_free(split);
    vx_bitgrid_free(&surf);
    vx_mesh_free(big);
}

static void test_slabs(void **state)
{
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_triangulated.obj", NULL, NULL);
    assert_non_null(m);
    for (int mode = 0; mode < 4; mode++) {
        vx_voxelize_desc d = {0};
        if (mode < 3)
            d.inside = (vx_inside)mode;
        else
            d.fill = VX_FILL_SURFACE;
        grid_res(m, 70, 1, &d.grid);
        vx_bitgrid one, many;
        vx_voxelize_stats st;
        run_peel(m, &d, &one, &st);
        assert_int_equal(st.chunks, 1);
        d.max_slab_rows = 7;
        run_peel(m, &d, &many, &st);
        assert_int_equal(st.chunks, (d.grid.dims[2] + 6) / 7);
        size_t words = one.wx * d.grid.dims[1] * d.grid.dims[2];
        assert_memory_equal(one.bits, many.bits, words * 4);
        printf("slabs mode %d: %d chunks, %llu voxels, identical\n", mode, st.chunks,
               (unsigned long long)vx_bitgrid_count(&one));
        assert_true(vx_bitgrid_count(&one) > 1000);
        vx_bitgrid_free(&one);
        vx_bitgrid_free(&many);
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
    assert_int_equal(vx_voxelize_peel(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_string_equal(err.code, "job_memory_limit");
    assert_null(b.bits);
    /* enough for the grid but not for one slab: slabs shrink to fit */
    d.max_memory = 400000;
    run_peel(m, &d, &b, &st);
    printf("max_memory 400000: %d chunks\n", st.chunks);
    assert_true(st.chunks > 1);
    vx_bitgrid_free(&b);
    d.max_memory = 0;

    int calls = 0;
    d.progress = count_calls;
    d.ud = &calls;
    d.max_slab_rows = 20;
    run_peel(m, &d, &b, &st);
    printf("progress calls: %d for %d chunks and %d layers\n", calls, st.chunks, st.layers);
    assert_true(calls >= st.chunks + st.layers);
    vx_bitgrid_free(&b);
    calls = 0;
    d.progress = stop_at;
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize_peel(vx_test_gl, m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "stopped_by_test");
    assert_int_equal(calls, 3);
    assert_null(b.bits);
    vx_mesh_free(m);
}

static void test_dispatcher(void **state)
{
    vx_mesh *m = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    vx_voxelize_desc d = {0};
    grid_res(m, 8, 0, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    /* auto: scan for nonzero/parity solid fills (test_scan.c), peel for
     * robust */
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), 0);
    assert_string_equal(st.method, "scan");
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

/* Timings for the report; runs only with VX_PEEL_BENCH=1. */
static void test_bench(void **state)
{
    if (!getenv("VX_PEEL_BENCH")) skip();
    const char *names[] = {"spot_triangulated.obj", "stanford-bunny.obj", "ogre.obj"};
    vx_mesh *ms[5];
    for (int i = 0; i < 3; i++) {
        char path[512];
        snprintf(path, sizeof path, "%s/%s", VX_MESH_DIR, names[i]);
        ms[i] = vx_obj_read_path(path, NULL, NULL);
        assert_non_null(ms[i]);
    }
    vx_mesh *o4 = subdivide(ms[2], 1);
    ms[3] = subdivide(o4, 4);
    vx_mesh_free(o4);
    const char *labels[] = {"spot", "bunny", "ogre", "ogre-subdiv"};
    for (int i = 0; i < 4; i++)
        for (int res = 128; res <= 256; res *= 2) {
            for (int rep = 0; rep < 2; rep++) {
                vx_voxelize_desc d = {0};
                grid_res(ms[i], res, 0, &d.grid);
                vx_bitgrid b;
                vx_voxelize_stats st;
                double t0 = now_s();
                run_peel(ms[i], &d, &b, &st);
                if (rep)
                    printf("BENCH %-12s %7zu tris %4d^3: peel %8.1f ms fill %7.2f ms layers %3d "
                           "chunks %d upload %.1f readback %.1f wall %.0f ms\n",
                           labels[i], ms[i]->ntris, res, st.gpu_peel_ms, st.gpu_fill_ms, st.layers,
                           st.chunks, st.upload_ms, st.readback_ms, 1e3 * (now_s() - t0));
                if (rep && res == 256 && i < 3) {
                    double iou;
                    compare_ref(labels[i], ms[i], &d.grid, VX_INSIDE_NONZERO, &b, &iou);
                }
                vx_bitgrid_free(&b);
            }
        }
    for (int res = 512; res <= 1024; res *= 2) {
        vx_voxelize_desc d = {0};
        grid_res(ms[1], res, 0, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        double t0 = now_s();
        run_peel(ms[1], &d, &b, &st);
        printf("BENCH %-12s %7zu tris %4d^3: peel %8.1f ms fill %7.2f ms layers %3d chunks %d "
               "upload %.1f readback %.1f wall %.0f ms (%dx%dx%d)\n",
               "bunny", ms[1]->ntris, res, st.gpu_peel_ms, st.gpu_fill_ms, st.layers, st.chunks,
               st.upload_ms, st.readback_ms, 1e3 * (now_s() - t0), d.grid.dims[0], d.grid.dims[1],
               d.grid.dims[2]);
        vx_bitgrid_free(&b);
    }
    for (int mode = 0; mode < 2; mode++) {
        vx_voxelize_desc d = {0};
        if (mode == 0)
            d.inside = VX_INSIDE_ROBUST;
        else
            d.fill = VX_FILL_SURFACE;
        grid_res(ms[1], 256, 0, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        double t0 = now_s();
        run_peel(ms[1], &d, &b, &st);
        printf("BENCH bunny %s 256^3: peel %.1f ms fill %.2f ms layers %d wall %.0f ms\n",
               mode ? "surface" : "robust", st.gpu_peel_ms, st.gpu_fill_ms, st.layers,
               1e3 * (now_s() - t0));
        vx_bitgrid_free(&b);
    }
    for (int i = 0; i < 4; i++)
        vx_mesh_free(ms[i]);
}

/* Large grids (memory and minutes): VX_PEEL_BIG=1. A cube filling a 1024^3
 * grid (128 MiB of bits: one SSBO at llvmpipe's limit) and a 2048^3 grid
 * (1 GiB of bits, several slabs) must give exact counts. */
static void test_big(void **state)
{
    if (!getenv("VX_PEEL_BIG")) skip();
    vx_mesh *m = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    for (int res = 1024; res <= 2048; res *= 2) {
        vx_voxelize_desc d = {0};
        grid_res(m, res, 0, &d.grid);
        vx_bitgrid b;
        vx_voxelize_stats st;
        double t0 = now_s();
        run_peel(m, &d, &b, &st);
        printf("BIG cube %d^3: %llu voxels, chunks %d, peel %.1f ms fill %.1f ms readback %.1f ms "
               "wall %.0f ms\n",
               res, (unsigned long long)st.voxels_inside, st.chunks, st.gpu_peel_ms, st.gpu_fill_ms,
               st.readback_ms, 1e3 * (now_s() - t0));
        assert_int_equal(st.voxels_inside, (uint64_t)res * res * res);
        vx_bitgrid_free(&b);
    }
    vx_mesh_free(m);
    m = vx_obj_read_path(VX_MESH_DIR "/stanford-bunny.obj", NULL, NULL);
    vx_voxelize_desc d = {0};
    grid_res(m, 2048, 0, &d.grid);
    vx_bitgrid b;
    vx_voxelize_stats st;
    double t0 = now_s();
    run_peel(m, &d, &b, &st);
    printf("BIG bunny 2048 (%dx%dx%d): %llu voxels, chunks %d, layers %d, peel %.1f ms fill %.1f "
           "ms readback %.1f ms wall %.0f ms\n",
           d.grid.dims[0], d.grid.dims[1], d.grid.dims[2], (unsigned long long)st.voxels_inside,
           st.chunks, st.layers, st.gpu_peel_ms, st.gpu_fill_ms, st.readback_ms,
           1e3 * (now_s() - t0));
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cube_exact),
        cmocka_unit_test(test_box_on_boundaries),
        cmocka_unit_test(test_sphere),
        cmocka_unit_test(test_torus),
        cmocka_unit_test(test_hollow_and_nested),
        cmocka_unit_test(test_overlapping_spheres),
        cmocka_unit_test(test_coincident_faces),
        cmocka_unit_test(test_grid_cuts_mesh),
        cmocka_unit_test(test_real_meshes_256),
        cmocka_unit_test(test_bunny_robust),
        cmocka_unit_test(test_robust_limits),
        cmocka_unit_test(test_surface),
        cmocka_unit_test(test_slabs),
        cmocka_unit_test(test_limits_and_progress),
        cmocka_unit_test(test_dispatcher),
        cmocka_unit_test(test_bench),
        cmocka_unit_test(test_big),
    };
    return cmocka_run_group_tests(tests, vx_test_gl_setup, vx_test_gl_teardown);
}
