/* The cpu method (src/voxel/cpu.c): scan's crossing counts on the CPU
 * threads. Known answers (boxes on and off voxel centres, random
 * tetrahedra against an exact point test), exact agreement with the CPU
 * reference where every tie is in the image plane (meshes whose vertices
 * sit on column centres and 1/256-voxel steps), the same voxels as scan on
 * random grids of every shared mesh, bands of any height, hostile input,
 * and auto's choice. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "gl_fixture.h"

#include "ref_voxel.h"
#include "shapes.h"
#include "voxel/voxel.h"

/* Same LeakSanitizer setting as test_slice.c (llvmpipe's TLS). */
const char *__lsan_default_options(void);
const char *__lsan_default_suppressions(void);
const char *__lsan_default_options(void)
{
    return "use_tls=0";
}
const char *__lsan_default_suppressions(void)
{
    return "leak:add_to_global_resize\n";
}

static int cpu(const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *b, vx_voxelize_stats *st)
{
    vx_err err = {0};
    int rc = vx_voxelize_cpu(m, d, b, st, &err);
    if (rc) fprintf(stderr, "cpu: %s: %s\n", err.code, err.message);
    return rc;
}

static size_t words(const vx_bitgrid *b)
{
    return b->wx * (size_t)b->grid.dims[1] * (size_t)b->grid.dims[2];
}

static size_t bits_differ(const vx_bitgrid *a, const vx_bitgrid *b)
{
    size_t n = 0;
    for (size_t w = 0; w < words(a); w++)
        n += (size_t)__builtin_popcount(a->bits[w] ^ b->bits[w]);
    return n;
}

/* ---- known answers ------------------------------------------------------ */

/* Centres c (at c + 1/2 in grid units) with lo <= c + 1/2 < hi. */
static int centres_in(double lo, double hi, int n)
{
    int k = 0;
    for (int c = 0; c < n; c++)
        k += lo <= c + 0.5 && c + 0.5 < hi;
    return k;
}

/* Axis-aligned boxes, faces anywhere (across the rays, not within 1/512
 * voxel of a centre unless on it), also exactly on centres: the centres
 * in [lo, hi) along every axis (along x the [entry, exit) rule; across it
 * the tie rule's perturbation by (+eps, +eps^2) in y, z). */
static void test_boxes_known(void **state)
{
    (void)state;
    srand48(1);
    for (int trial = 0; trial < 200; trial++) {
        vx_grid g = {.h = 1,
                     .dims = {1 + (int)(drand48() * 70), 1 + (int)(drand48() * 40),
                              1 + (int)(drand48() * 40)}};
        double lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            int n = g.dims[a];
            /* on a centre, on a cell boundary, or anywhere; sometimes
             * beyond the grid */
            for (int e = 0; e < 2; e++) {
                double r = drand48(), v = floor(drand48() * (n + 4)) - 2, f = drand48();
                /* across the rays (y, z) coverage is decided on positions
                 * snapped to 1/256 voxel, as a GPU rasterizer decides it:
                 * a face within 1/512 voxel of a centre may go either way */
                if (a > 0 && fabs(f - 0.5) < 1.0 / 256) f += 1.0 / 64;
                double p = r < 0.3 ? v + 0.5 : r < 0.5 ? v : v + f;
                if (e == 0)
                    lo[a] = p;
                else
                    hi[a] = p;
            }
            if (hi[a] < lo[a]) {
                double t = lo[a];
                lo[a] = hi[a];
                hi[a] = t;
            }
            if (hi[a] == lo[a]) hi[a] += 1.25;
        }
        vx_mesh *m = shape_box(lo, hi);
        if (trial % 2) shape_flip(m); /* inward: winding -1, still solid */
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
            vx_voxelize_desc d = {.grid = g, .inside = (vx_inside)rule};
            vx_bitgrid b;
            vx_voxelize_stats st;
            assert_int_equal(cpu(m, &d, &b, &st), 0);
            int want[3];
            for (int a = 0; a < 3; a++)
                want[a] = centres_in(lo[a], hi[a], g.dims[a]);
            uint64_t n = (uint64_t)want[0] * want[1] * want[2];
            if (st.voxels_inside != n)
                printf("box %d [%g %g %g]-[%g %g %g] on %dx%dx%d: %llu, want %llu\n", trial, lo[0],
                       lo[1], lo[2], hi[0], hi[1], hi[2], g.dims[0], g.dims[1], g.dims[2],
                       (unsigned long long)st.voxels_inside, (unsigned long long)n);
            assert_int_equal(st.voxels_inside, n);
            assert_int_equal(vx_bitgrid_count(&b), n);
            for (int k = 0; k < g.dims[2]; k++)
                for (int j = 0; j < g.dims[1]; j++)
                    for (int i = 0; i < g.dims[0]; i++) {
                        int in = lo[0] <= i + 0.5 && i + 0.5 < hi[0] && lo[1] <= j + 0.5 &&
                                 j + 0.5 < hi[1] && lo[2] <= k + 0.5 && k + 0.5 < hi[2];
                        assert_int_equal(vx_bitgrid_get(&b, i, j, k), in);
                    }
            vx_bitgrid_free(&b);
        }
        vx_mesh_free(m);
    }
}

/* Which side of the plane (a, b, c) p lies on, as a signed volume. */
static double orient(const double *a, const double *b, const double *c, const double *p)
{
    double u[3], v[3], w[3];
    for (int k = 0; k < 3; k++) {
        u[k] = b[k] - a[k];
        v[k] = c[k] - a[k];
        w[k] = p[k] - a[k];
    }
    return w[0] * (u[1] * v[2] - u[2] * v[1]) - w[1] * (u[0] * v[2] - u[2] * v[0]) +
           w[2] * (u[0] * v[1] - u[1] * v[0]);
}

/* A random tetrahedron (4 vertices into v) as an outward mesh. */
static vx_mesh *tetra(double v[12], double span, double off)
{
    for (int i = 0; i < 12; i++)
        v[i] = off + drand48() * span;
    static const uint32_t f[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
    vx_mesh *m = shape_mesh_from(4, v, 4, f);
    if (shape_signed_volume(m) < 0) shape_flip(m);
    return m;
}

/* 1 inside, 0 outside, -1 within 1e-9 (relative) of a face: don't care. */
static int in_tetra(const vx_mesh *m, const double p[3])
{
    int inside = 1;
    for (size_t t = 0; t < 4; t++) {
        const double *a = m->pos + 3 * m->tri[3 * t], *b = m->pos + 3 * m->tri[3 * t + 1],
                     *c = m->pos + 3 * m->tri[3 * t + 2];
        double o = orient(a, b, c, p);
        if (fabs(o) < 1e-9 * 1e4) return -1;
        if (o > 0) inside = 0; /* outward faces: inside is behind every one */
    }
    return inside;
}

/* Random tetrahedra, single and overlapping in pairs: the union (nonzero)
 * and the symmetric difference (parity) against the exact point test. */
static void test_tetrahedra_known(void **state)
{
    (void)state;
    srand48(3);
    size_t checked = 0;
    for (int trial = 0; trial < 60; trial++) {
        double v[2][12];
        vx_mesh *t[2] = {tetra(v[0], 30, 1), tetra(v[1], 30, 3)};
        int two = trial % 2;
        vx_mesh *m = two ? shape_merge(t, 2) : t[0];
        vx_grid g = {.origin = {0.1 * drand48(), 0.1 * drand48(), 0.1 * drand48()},
                     .h = 0.9 + 0.2 * drand48(),
                     .dims = {40, 40, 40}};
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
            vx_voxelize_desc d = {.grid = g, .inside = (vx_inside)rule};
            vx_bitgrid b;
            vx_voxelize_stats st;
            assert_int_equal(cpu(m, &d, &b, &st), 0);
            size_t wrong = 0;
            for (int k = 0; k < 40; k++)
                for (int j = 0; j < 40; j++)
                    for (int i = 0; i < 40; i++) {
                        double p[3] = {g.origin[0] + (i + 0.5) * g.h, g.origin[1] + (j + 0.5) * g.h,
                                       g.origin[2] + (k + 0.5) * g.h};
                        int a = in_tetra(t[0], p), c = two ? in_tetra(t[1], p) : 0;
                        if (a < 0 || c < 0) continue;
                        int want = rule == VX_INSIDE_NONZERO ? (a || c) : (a ^ c);
                        wrong += vx_bitgrid_get(&b, i, j, k) != want;
                        checked++;
                    }
            if (wrong) printf("tetrahedra %d rule %d: %zu wrong\n", trial, rule, wrong);
            assert_int_equal(wrong, 0);
            vx_bitgrid_free(&b);
        }
        if (two) vx_mesh_free(m);
        vx_mesh_free(t[0]);
        vx_mesh_free(t[1]);
    }
    printf("%zu centres checked\n", checked);
}

/* ---- ties in the image plane ------------------------------------------ */

/* A sphere (and a torus) whose vertices are moved onto column centres in
 * y and z (so rays pass exactly through vertices and along edges) and to
 * 1/256-voxel steps in x, off the centres: every tie is in the image
 * plane, where cpu and the reference both perturb the ray by (eps,
 * eps^2), exactly. They must agree voxel for voxel, and no row may leak
 * (its first and last voxels, outside the mesh, stay empty). */
static void snap_to_columns(vx_mesh *m, const vx_grid *g)
{
    for (size_t v = 0; v < m->nverts; v++) {
        double *p = m->pos + 3 * v;
        p[0] = g->origin[0] + (floor((p[0] - g->origin[0]) / g->h * 256) + 0.37) / 256 * g->h;
        for (int a = 1; a < 3; a++)
            p[a] = g->origin[a] + (floor((p[a] - g->origin[a]) / g->h) + 0.5) * g->h;
    }
}

static void test_vertices_on_centres(void **state)
{
    (void)state;
    srand48(4);
    for (int trial = 0; trial < 12; trial++) {
        vx_mesh *m = trial % 3 == 2 ? shape_param_mesh(40 + trial, 20, 0, 0, 0, 0, 0, 10, 4)
                                    : shape_sphere(0, 0, 0, 12, trial % 2);
        vx_grid g = {.origin = {-16, -16, -16}, .h = 0.25 * (1 + trial % 4), .dims = {0}};
        for (int a = 0; a < 3; a++)
            g.dims[a] = (int)(32 / g.h);
        snap_to_columns(m, &g);
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
            vx_voxelize_desc d = {.grid = g, .inside = (vx_inside)rule};
            vx_bitgrid b;
            vx_voxelize_stats st;
            assert_int_equal(cpu(m, &d, &b, &st), 0);
            double iou;
            size_t mis = ref_compare("vertices on centres", m, &g, (vx_inside)rule, &b, &iou);
            assert_int_equal(mis, 0);
            assert_true(st.voxels_inside > 0);
            size_t leaks = 0;
            for (int k = 0; k < g.dims[2]; k++)
                for (int j = 0; j < g.dims[1]; j++)
                    leaks += vx_bitgrid_get(&b, 0, j, k) + vx_bitgrid_get(&b, g.dims[0] - 1, j, k);
            assert_int_equal(leaks, 0);
            vx_bitgrid_free(&b);
        }
        vx_mesh_free(m);
    }
}

/* ---- against scan ------------------------------------------------------- */

/* Random grids over every shared mesh and a few made ones, each grid
 * holding its mesh (scan draws one slab, nothing clipped): cpu gives the
 * same voxels as scan, bit for bit, wherever llvmpipe's coverage ties go
 * the way cpu's perturbation sends them. Counted over all runs: at most
 * a few in a million (seen: 0). */
static void test_same_as_scan(void **state)
{
    (void)state;
    const char *names[] = {"spot_triangulated.obj", "spot_quadrangulated.obj",
                           "spot_control_mesh.obj", "stanford-bunny.obj",
                           "rocker-arm.obj",        "fandisk.obj",
                           "suzanne.obj",           "ogre.obj",
                           "newell-teapot.bpt"};
    const int nnames = (int)(sizeof names / sizeof names[0]);
    srand48(5);
    size_t total = 0, voxels = 0;
    for (int mi = 0; mi < nnames + 2; mi++) {
        vx_mesh *m;
        if (mi < nnames) {
            m = shape_load(names[mi]);
        } else if (mi == nnames) {
            m = shape_param_mesh(48, 24, 0, 0, 0, 0, 0, 1.0, 0.35);
        } else {
            vx_mesh *s[2] = {shape_sphere(0, 0, 0, 1, 0), shape_sphere(0.6, 0.2, 0.1, 0.7, 1)};
            m = shape_merge(s, 2);
            vx_mesh_free(s[0]);
            vx_mesh_free(s[1]);
        }
        assert_non_null(m);
        for (int trial = 0; trial < 3; trial++) {
            int n = 32 + (int)(drand48() * 64);
            vx_grid g;
            assert_int_equal(vx_grid_from_resolution(m, n, 2, &g, NULL), 0);
            for (int a = 0; a < 3; a++)
                g.origin[a] -= drand48() * g.h;
            g.h *= 1.0 + 0.01 * drand48();
            for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++) {
                vx_voxelize_desc d = {.grid = g, .inside = (vx_inside)rule};
                vx_bitgrid a, b;
                vx_voxelize_stats st;
                vx_err err = {0};
                d.method = VX_METHOD_SCAN;
                assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &a, &st, &err), 0);
                assert_int_equal(st.chunks, 1);
                assert_int_equal(cpu(m, &d, &b, &st), 0);
                size_t diff = bits_differ(&a, &b);
                if (diff)
                    printf("%s n %d rule %d: %zu voxels differ from scan\n",
                           mi < nnames ? names[mi] : "made", n, rule, diff);
                total += diff;
                voxels += (size_t)g.dims[0] * g.dims[1] * g.dims[2];
                vx_bitgrid_free(&a);
                vx_bitgrid_free(&b);
            }
        }
        vx_mesh_free(m);
    }
    printf("cpu vs scan: %zu of %zu voxels differ\n", total, voxels);
    assert_true(total <= voxels / 1000000 + 2);
}

/* Bands of 1 row up to the whole grid: the same voxels. */
static void test_bands(void **state)
{
    (void)state;
    vx_mesh *m = shape_load("rocker-arm.obj");
    assert_non_null(m);
    vx_voxelize_desc d = {0};
    assert_int_equal(vx_grid_from_resolution(m, 90, 1, &d.grid, NULL), 0);
    vx_bitgrid one, b;
    vx_voxelize_stats st;
    assert_int_equal(cpu(m, &d, &one, &st), 0);
    for (int rows = 1; rows <= d.grid.dims[2] + 5; rows += 7) {
        d.max_slab_rows = rows;
        assert_int_equal(cpu(m, &d, &b, &st), 0);
        int bands = (d.grid.dims[2] + rows - 1) / rows;
        assert_int_equal(st.chunks, bands < 1 ? 1 : bands);
        assert_int_equal(st.voxels_inside, vx_bitgrid_count(&one));
        assert_memory_equal(one.bits, b.bits, words(&b) * 4);
        vx_bitgrid_free(&b);
    }
    vx_bitgrid_free(&one);
    vx_mesh_free(m);
}

/* ---- hostile input ------------------------------------------------------ */

static void test_hostile(void **state)
{
    (void)state;
    vx_voxelize_desc d = {.grid = {{0, 0, 0}, 1, {8, 8, 8}}};
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    /* a vertex 2^51 voxels away, and one that is NaN: refused */
    const double far[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0x1p51};
    const uint32_t tri[] = {0, 1, 2, 0, 2, 3};
    vx_mesh *m = shape_mesh_from(4, far, 2, tri);
    assert_int_equal(vx_voxelize_cpu(m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "invalid_params");
    assert_null(b.bits);
    m->pos[11] = NAN;
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize_cpu(m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "invalid_params");
    /* an index beyond the vertices */
    m->pos[11] = 1;
    m->tri[5] = 99;
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize_cpu(m, &d, &b, &st, &err), -1);
    assert_string_equal(err.code, "mesh_invalid");
    vx_mesh_free(m);
    /* zero-area triangles only (every projection degenerate): nothing */
    const double flat[] = {1, 1, 1, 5, 5, 5, 3, 3, 3, 1, 2, 3};
    const uint32_t ft[] = {0, 1, 2, 0, 1, 2, 3, 3, 3};
    m = shape_mesh_from(4, flat, 3, ft);
    assert_int_equal(cpu(m, &d, &b, &st), 0);
    assert_int_equal(st.voxels_inside, 0);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
    /* a box far bigger than the grid, the grid 2^38 voxels into its
     * lattice and inside the box: every voxel */
    const double big = 0x1p39;
    m = shape_box((double[]){-big, -big, -big}, (double[]){big, big, big});
    vx_voxelize_desc dd = {.grid = {{0, 0, 0}, 1, {33, 5, 3}, {(int64_t)1 << 38, -5, 7}}};
    assert_int_equal(cpu(m, &dd, &b, &st), 0);
    assert_int_equal(st.voxels_inside, 33 * 5 * 3);
    vx_bitgrid_free(&b);
    /* the same box before the grid along x: nothing */
    dd.grid.index[0] = VX_GRID_INDEX_MAX;
    assert_int_equal(cpu(m, &dd, &b, &st), 0);
    assert_int_equal(st.voxels_inside, 0);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
    /* a grid of one voxel, and a memory limit below the grid */
    m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc one = {.grid = {{-0.5, -0.5, -0.5}, 1, {1, 1, 1}}};
    assert_int_equal(cpu(m, &one, &b, &st), 0);
    assert_int_equal(st.voxels_inside, 1);
    vx_bitgrid_free(&b);
    vx_voxelize_desc small = {.grid = {{-1, -1, -1}, 1.0 / 64, {128, 128, 128}},
                              .max_memory = 1000};
    memset(&err, 0, sizeof err);
    assert_int_equal(vx_voxelize_cpu(m, &small, &b, &st, &err), -1);
    assert_string_equal(err.code, "job_memory_limit");
    assert_null(b.bits);
    vx_mesh_free(m);
}

/* auto runs cpu where the renderer is a CPU rasterizer, scan elsewhere */
/* A resolution's dims: an extent that is a whole number of voxels up to
 * rounding gets that many (0.9 / 0.1 is 9.000000000000002: an extra layer
 * put the centres on the box's faces), and the box's voxels are exact. */
static void test_resolution_dims(void **state)
{
    (void)state;
    vx_mesh *m = shape_box((double[]){0.1, 0.2, 0.3}, (double[]){1.7, 1.1, 0.9});
    vx_voxelize_desc d = {0};
    assert_int_equal(vx_grid_from_resolution(m, 16, 0, &d.grid, NULL), 0);
    assert_int_equal(d.grid.dims[0], 16);
    assert_int_equal(d.grid.dims[1], 9);
    assert_int_equal(d.grid.dims[2], 6);
    vx_bitgrid b;
    vx_voxelize_stats st;
    assert_int_equal(vx_voxelize_cpu(m, &d, &b, &st, NULL), 0);
    assert_int_equal(vx_bitgrid_count(&b), 16 * 9 * 6);
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
    /* every resolution of boxes with decimal extents, and a cube at 1e30 */
    for (int r = 1; r <= 300; r++) {
        static const double ext[][3] = {{1.6, 0.9, 0.6}, {0.3, 0.7, 0.1}, {3.3, 1.1, 2.2}};
        for (int e = 0; e < 3; e++) {
            m = shape_box((double[]){0.1, 0.2, 0.3},
                          (double[]){0.1 + ext[e][0], 0.2 + ext[e][1], 0.3 + ext[e][2]});
            assert_int_equal(vx_grid_from_resolution(m, r, 0, &d.grid, NULL), 0);
            double big = fmax(ext[e][0], fmax(ext[e][1], ext[e][2]));
            for (int a = 0; a < 3; a++) {
                /* the exact count, ext / big * r, to a rounding error */
                double want = ext[e][a] / big * r;
                int n = (int)ceil(want - 1e-9);
                if (n < 1) n = 1;
                if (d.grid.dims[a] != n)
                    fail_msg("res %d box %d axis %d: dims %d, want %d", r, e, a, d.grid.dims[a], n);
            }
            vx_mesh_free(m);
        }
    }
    m = shape_box((double[]){1e30, 2e30, 0}, (double[]){1.8e30, 2.9e30, 1e30});
    assert_int_equal(vx_grid_from_resolution(m, 16, 0, &d.grid, NULL), 0);
    assert_int_equal(d.grid.dims[0], 13);
    assert_int_equal(d.grid.dims[1], 15);
    assert_int_equal(d.grid.dims[2], 16);
    vx_mesh_free(m);
}

static void test_auto(void **state)
{
    (void)state;
    vx_mesh *m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {0};
    assert_int_equal(vx_grid_from_resolution(m, 32, 1, &d.grid, NULL), 0);
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    assert_int_equal(vx_voxelize(vx_test_gl, m, &d, &b, &st, &err), 0);
    /* cpu on every renderer (voxel.h) */
    printf("renderer %s: auto ran %s\n", vx_gl_get_info(vx_test_gl)->renderer, st.method);
    assert_string_equal(st.method, "cpu");
    vx_bitgrid_free(&b);
    vx_mesh_free(m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_boxes_known),
        cmocka_unit_test(test_tetrahedra_known),
        cmocka_unit_test(test_vertices_on_centres),
        cmocka_unit_test(test_same_as_scan),
        cmocka_unit_test(test_bands),
        cmocka_unit_test(test_hostile),
        cmocka_unit_test(test_resolution_dims),
        cmocka_unit_test(test_auto),
    };
    return cmocka_run_group_tests(tests, vx_test_gl_setup, vx_test_gl_teardown);
}
