/* What only the depth-peeling voxelizer (seed 000) does, on a real GL
 * context: the robust inside rule, surface fill, big grids and the timing
 * report. The cases it shares with scan are in test_solid.c. */
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
#include "voxel/peel_int.h"
#include "voxel/voxel.h"

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

static void grid_res(const vx_mesh *m, int res, int pad, vx_grid *g)
{
    assert_int_equal(vx_grid_from_resolution(m, res, pad, g, NULL), 0);
}

/* ---- tests ------------------------------------------------------------- */

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
        ref_compare(rule ? "bunny (open) parity" : "bunny (open) nonzero", m, &d.grid,
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
    /* spans most of a 128^3 grid: over SURF_GPU_WORK tests, so the CPU takes
     * it; corners on 1/128 so that the split below puts the midpoints on
     * the 1/256 the GPU methods snap to (vx_grid_unit), in the plane */
    double tp[9] = {0.0625, 0.125, 0.25, 100.0, 6.0, 80.0, 14.0, 110.0, 40.0};
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
                    ref_compare(labels[i], ms[i], &d.grid, VX_INSIDE_NONZERO, &b, &iou);
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
/* ---- progress follows the work (issue 14 #6) ---- */

typedef struct prog_log {
    double t0;
    int n;
    double t[4096], f[4096];
} prog_log;

static int log_progress(void *ud, double f, vx_err *err)
{
    (void)err;
    prog_log *l = ud;
    if (l->n < 4096) {
        l->t[l->n] = now_s() - l->t0;
        l->f[l->n++] = f;
    }
    return 0;
}

/* Robust over many slabs: the z rays, peeled once in slab 0, were a third
 * of the work but a third of one slab's share of the bar (0.0675 of the
 * job for most of it). Now the reports are proportional to the work: when
 * half the time has passed the bar is past a fifth, and it moves every
 * pass. */
static void test_robust_progress(void **state)
{
    (void)state;
    char path[512];
    snprintf(path, sizeof path, "%s/stanford-bunny.obj", VX_MESH_DIR);
    vx_mesh *m = vx_obj_read_path(path, NULL, NULL);
    assert_non_null(m);
    vx_voxelize_desc d = {.inside = VX_INSIDE_ROBUST, .max_slab_rows = 16};
    grid_res(m, 160, 1, &d.grid);
    static prog_log l;
    memset(&l, 0, sizeof l);
    d.progress = log_progress;
    d.ud = &l;
    vx_bitgrid b;
    vx_voxelize_stats st;
    l.t0 = now_s();
    run_peel(m, &d, &b, &st);
    double total = now_s() - l.t0;
    int distinct = 0;
    for (int i = 0; i < l.n; i++) {
        assert_true(i == 0 || l.f[i] >= l.f[i - 1]); /* never backwards */
        distinct += i == 0 || l.f[i] > l.f[i - 1];
    }
    printf("robust %d slabs, %.2f s: %d reports (%d distinct), last %.3f\n", st.chunks, total, l.n,
           distinct, l.n ? l.f[l.n - 1] : -1.0);
    assert_true(st.chunks >= 8);
    /* x and y of every slab and slab 0's z rays move the bar (later z
     * fills weigh nothing); how far each moves it is test_progress_weights'
     * (which report ends slab 0's z rays depends on how many passes and
     * bands the machine's speed gives: a slow build drew one in bands) */
    assert_true(distinct >= 2 * st.chunks + 1);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

/* The bar's weights, called as the engine calls them (each axis part-way,
 * then done, slab after slab): robust's z rays, peeled once in slab 0,
 * weigh a third of the job (they were a third of one slab's share). */
static int keep_f(void *ud, double f, vx_err *err)
{
    (void)err;
    *(double *)ud = f;
    return 0;
}

static void test_progress_weights(void **state)
{
    (void)state;
    double f = -1, last = 0, z_done = -1;
    vx_voxelize_desc d = {.progress = keep_f, .ud = &f};
    peel_ctx c = {.d = &d, .naxes = 3, .nslabs = 8};
    for (c.slab = 0; c.slab < c.nslabs; c.slab++)
        for (c.axis_i = 0; c.axis_i < 3; c.axis_i++)
            for (int k = 1; k <= 2; k++) {
                assert_int_equal(vx_peel_progress(&c, k / 2.0), 0);
                assert_true(f >= last);                                  /* never backwards */
                if (c.slab > 0 && c.axis_i == 2) assert_true(f == last); /* z fills: nothing */
                if (c.slab == 0 && c.axis_i == 2 && k == 2) z_done = f;
                last = f;
            }
    assert_true(fabs(last - 1) < 1e-12);
    assert_true(fabs(z_done - 10.0 / 24) < 1e-12);
    /* two axes (nonzero, parity): even halves of a slab */
    c.naxes = 2;
    c.slab = 3, c.axis_i = 1;
    assert_int_equal(vx_peel_progress(&c, 1.0), 0);
    assert_true(fabs(f - 4.0 / 8) < 1e-12);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bunny_robust),
        cmocka_unit_test(test_robust_limits),
        cmocka_unit_test(test_surface),
        cmocka_unit_test(test_bench),
        cmocka_unit_test(test_big),
        cmocka_unit_test(test_robust_progress),
        cmocka_unit_test(test_progress_weights),
    };
    return cmocka_run_group_tests(tests, vx_test_gl_setup, vx_test_gl_teardown);
}
