/* inside "winding" (src/voxel/winding.c): generated shapes with known
 * volumes (open, overlapping, nested), closed meshes against the exact CPU
 * reference, the tree against the direct sum, the default rule, and the
 * stop hook. Runs on the CPU: no GL context. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "ref_voxel.h"
#include "shapes.h"
#include "voxel/voxel.h"
#include "voxel/winding_int.h"

/* m without the triangles whose three vertices lie above the plane z =
 * c + slope y (a cap hole at the top); *top = the highest z left (the
 * rim of a level hole). */
static vx_mesh *cut_plane(vx_mesh *m, double c, double slope, double *top)
{
    uint32_t *idx = malloc(3 * m->ntris * sizeof *idx);
    size_t nt = 0;
    *top = -HUGE_VAL;
    for (size_t t = 0; t < m->ntris; t++) {
        int above = 1;
        for (int q = 0; q < 3; q++) {
            const double *p = m->pos + 3 * (size_t)m->tri[3 * t + q];
            above &= p[2] > c + slope * p[1];
        }
        if (above) continue;
        for (int q = 0; q < 3; q++) {
            idx[3 * nt + q] = m->tri[3 * t + q];
            double z = m->pos[3 * (size_t)m->tri[3 * t + q] + 2];
            if (z > *top) *top = z;
        }
        nt++;
    }
    vx_mesh *o = shape_mesh_from(m->nverts, m->pos, nt, idx);
    free(idx);
    vx_mesh_free(m);
    return o;
}

static vx_mesh *cut_above(vx_mesh *m, double c, double *top)
{
    return cut_plane(m, c, 0, top);
}

/* The world position of centre (i, j, k) of gr. */
static void grid_centre(const vx_grid *gr, int i, int j, int k, double c[3])
{
    const int e[3] = {i, j, k};
    for (int a = 0; a < 3; a++)
        c[a] = gr->origin[a] + (e[a] + .5) * gr->h;
}

static double ball(double r)
{
    return 4.0 / 3.0 * M_PI * r * r * r;
}

/* The segment of a ball of radius r beyond a plane at height t from its top. */
static double segment(double r, double t)
{
    return M_PI * t * t * (3 * r - t) / 3;
}

/* The lens two balls of radii a, b share at centre distance d. */
static double lens(double a, double b, double d)
{
    return M_PI * (a + b - d) * (a + b - d) * (d * d + 2 * d * (a + b) - 3 * (a - b) * (a - b)) /
           (12 * d);
}

/* Voxelizes m at resolution res; with plane finite, the grid moved along
 * z so that a cell boundary lies on z = plane (a flat hole there is then
 * not rounded by up to half a voxel one way). Returns the volume. */
static double run_at(const vx_mesh *m, vx_inside rule, int res, double plane, vx_bitgrid *b,
                     vx_voxelize_stats *st)
{
    vx_voxelize_desc d = {.inside = rule};
    assert_int_equal(vx_grid_from_resolution(m, res, 2, &d.grid, NULL), 0);
    if (isfinite(plane))
        d.grid.origin[2] = plane - ceil((plane - d.grid.origin[2]) / d.grid.h) * d.grid.h;
    vx_err err = {0};
    int rc = vx_voxelize(NULL, m, &d, b, st, &err);
    if (rc) printf("voxelize: %s\n", err.message);
    assert_int_equal(rc, 0);
    return (double)st->voxels_inside * d.grid.h * d.grid.h * d.grid.h;
}

static double run(const vx_mesh *m, vx_inside rule, int res, vx_bitgrid *b, vx_voxelize_stats *st)
{
    return run_at(m, rule, res, NAN, b, st);
}

static void near(const char *what, double got, double want, double tol)
{
    printf("%s: %.5f, analytic %.5f (%+.3f%%)\n", what, got, want, 100 * (got / want - 1));
    assert_true(fabs(got / want - 1) <= tol);
}

/* Two overlapping balls, the second with a hole on its far side: the union
 * minus the second's segment beyond the hole. */
static void test_overlap_open(void **state)
{
    (void)state;
    const double r1 = 1, r2 = 0.8, d = 1.1;
    double top;
    vx_mesh *a = shape_sphere(0.013, 0.007, 0.003, r1, 0);
    vx_mesh *b = shape_param_mesh(128, 64, 1, 0, 0.013, 0.007, 0.003 + d, r2, 0);
    b = cut_above(b, 0.003 + d + 0.6 * r2, &top);
    assert_true(b->boundary_edges > 0);
    vx_mesh *parts[2] = {a, b};
    vx_mesh *m = shape_merge(parts, 2);
    double t = 0.003 + d + r2 - top;
    double want = ball(r1) + ball(r2) - lens(r1, r2, d) - segment(r2, t);
    vx_bitgrid g;
    vx_voxelize_stats st;
    near("two balls, one open", run_at(m, VX_INSIDE_WINDING, 160, top, &g, &st), want, 0.005);
    assert_string_equal(st.method, "winding");
    vx_bitgrid_free(&g);
    /* nonzero counts the open ball's crossings along x: not the union */
    vx_mesh_free(a);
    vx_mesh_free(b);
    vx_mesh_free(m);
}

/* Nested closed shells: an inward inner shell keeps its void, an outward
 * one (winding number 2 inside it) is part of the union. */
static void test_nested(void **state)
{
    (void)state;
    vx_mesh *out = shape_sphere(0.011, 0.002, 0.005, 1, 0);
    vx_mesh *in = shape_sphere(0.011, 0.002, 0.005, 0.5, 1);
    vx_mesh *parts[2] = {out, in};
    vx_mesh *m = shape_merge(parts, 2);
    vx_bitgrid g;
    vx_voxelize_stats st;
    double outer = fabs(shape_signed_volume(out)), inner = fabs(shape_signed_volume(in));
    near("nested, void inward", run(m, VX_INSIDE_WINDING, 128, &g, &st), outer - inner, 0.005);
    /* the void is empty at the centre */
    assert_int_equal(vx_bitgrid_get(&g, g.grid.dims[0] / 2, g.grid.dims[1] / 2, g.grid.dims[2] / 2),
                     0);
    vx_bitgrid_free(&g);
    vx_mesh_free(m);
    shape_flip(in);
    parts[1] = in;
    m = shape_merge(parts, 2);
    near("nested, both outward", run(m, VX_INSIDE_WINDING, 128, &g, &st), outer, 0.005);
    vx_bitgrid_free(&g);
    vx_mesh_free(m);
    vx_mesh_free(out);
    vx_mesh_free(in);
}

/* Open shells: a bowl (the lower hemisphere) is the half ball; a ball
 * with a large cap hole is the ball less the segment beyond the hole. */
static void test_open_shells(void **state)
{
    (void)state;
    double top;
    vx_mesh *bowl = cut_above(shape_sphere(0.004, 0.009, 0.002, 1, 0), 0.002 + 1e-9, &top);
    vx_bitgrid g;
    vx_voxelize_stats st;
    double t = 1 - (top - 0.002);
    near("bowl", run_at(bowl, VX_INSIDE_WINDING, 128, top, &g, &st), ball(1) - segment(1, t),
         0.005);
    /* nothing above the rim */
    for (int k = 0; k < g.grid.dims[2]; k++) {
        double z = g.grid.origin[2] + (k + .5) * g.grid.h;
        if (z > top + g.grid.h)
            for (int j = 0; j < g.grid.dims[1]; j++)
                for (int i = 0; i < g.grid.dims[0]; i++)
                    assert_int_equal(vx_bitgrid_get(&g, i, j, k), 0);
    }
    vx_bitgrid_free(&g);
    vx_mesh_free(bowl);
    vx_mesh *cup = cut_above(shape_sphere(0.004, 0.009, 0.002, 1, 0), 0.002 + 0.3, &top);
    t = 1 - (top - 0.002);
    near("ball with a cap hole", run_at(cup, VX_INSIDE_WINDING, 128, top, &g, &st),
         ball(1) - segment(1, t), 0.005);
    vx_bitgrid_free(&g);
    vx_mesh_free(cup);
}

/* Balls cut open above tilted planes (z > c + slope y): a rim that
 * zig-zags along the mesh's edges, so the cone over it is not flat and
 * the rays (along y: the hole faces z) cross it, and runs start after
 * cone crossings as well as after crossings of the ball alone. Four
 * planes, ball centres and grid offsets (a fixed seed); every centre near
 * the hole agrees with the direct sum where that is clear of 1/2 (a run's
 * first centre that took the cone's w from before a cone crossing, off
 * by 1, did not: 8 differed in the first case). */
static void test_run_starts(void **state)
{
    (void)state;
    uint64_t s = 2026;
    double u[4][6];
    for (int t = 0; t < 4; t++)
        for (int k = 0; k < 6; k++) {
            s = s * 6364136223846793005ull + 1442695040888963407ull;
            u[t][k] = (double)(s >> 11) / 9007199254740992.0;
        }
    for (int t = 0; t < 4; t++) {
        /* the first case fixed: the plane the mutation was checked on */
        double c = t ? 0.1 + 0.4 * u[t][0] : 0.3, slope = t ? -0.6 + 1.2 * u[t][1] : 0.45, top;
        vx_mesh *m = cut_plane(
            shape_param_mesh(40, 20, 1, 0, 0.013 + 0.1 * u[t][2] * (t > 0), 0.007, 0.003, 1, 0), c,
            slope, &top);
        assert_true(m->boundary_edges > 0);
        vx_voxelize_desc d = {.inside = VX_INSIDE_WINDING};
        assert_int_equal(vx_grid_from_resolution(m, 48 + 2 * t, 2, &d.grid, NULL), 0);
        for (int a = 0; a < 3 && t; a++)
            d.grid.origin[a] -= u[t][3 + a] * d.grid.h; /* within the padding */
        vx_bitgrid g;
        vx_voxelize_stats st;
        vx_err err = {0};
        assert_int_equal(vx_voxelize(NULL, m, &d, &g, &st, &err), 0);
        const vx_grid *gr = &g.grid;
        size_t checked = 0, differ = 0;
        for (int k = 0; k < gr->dims[2]; k++)
            for (int j = 0; j < gr->dims[1]; j++)
                for (int i = 0; i < gr->dims[0]; i++) {
                    double p[3];
                    grid_centre(gr, i, j, k, p);
                    if (fabs(p[2] - c - slope * p[1]) > 0.4) continue;
                    double w = ref_winding_number(m, p);
                    if (fabs(w - 0.5) < 0.05) continue;
                    checked++;
                    differ += (w >= 0.5) != vx_bitgrid_get(&g, i, j, k);
                }
        printf("hole under z = %.3f + %.3f y: %zu of %zu centres near it clear of 1/2 differ "
               "from the direct sum\n",
               c, slope, differ, checked);
        assert_true(checked > 10000);
        assert_int_equal(differ, 0);
        vx_bitgrid_free(&g);
        vx_mesh_free(m);
    }
}

/* m's vertices moved onto the lattice of g (power-of-two h, origin a
 * multiple of h / 256, so lattice units are exact): x and y onto
 * 1/256-voxel steps, or with `centres` onto column centres (every column
 * through a vertex or along an edge: ties for the coverage rule), and z
 * to 1/256-voxel steps plus 0.37 of one (never on a centre). Coverage is
 * then decided on the true positions, and a closed mesh's winding voxels
 * must be the exact reference's. */
static void onto_lattice(vx_mesh *m, const vx_grid *g, int centres)
{
    for (size_t v = 0; v < m->nverts; v++) {
        double *p = m->pos + 3 * v;
        for (int a = 0; a < 3; a++) {
            double u = (p[a] - g->origin[a]) / g->h;
            u = a == 2    ? (floor(u * 256) + 0.37) / 256
                : centres ? floor(u) + 0.5
                          : nearbyint(u * 256) / 256;
            p[a] = g->origin[a] + u * g->h;
        }
    }
}

/* Closed meshes: winding >= 1/2 is the crossing count, the same voxels as
 * the exact nonzero reference, the shared meshes and overlapping parts,
 * with their vertices on the lattice's 1/256-voxel steps across z (where
 * winding snaps them anyway) and on column centres. */
static void test_closed_exact(void **state)
{
    (void)state;
    const char *names[] = {"spot_triangulated.obj", "rocker-arm.obj", "fandisk.obj", NULL};
    for (int n = 0; n < 4; n++) {
        vx_mesh *m;
        if (names[n]) {
            m = shape_load(names[n]);
        } else { /* the generated torus with a box through it */
            vx_mesh *parts[2] = {
                shape_param_mesh(64, 32, 0, 0, 0, 0.01, 0.02, 1, 0.4),
                shape_box((double[]){-0.3, -1.7, -0.2}, (double[]){0.35, 1.6, 0.25})};
            m = shape_merge(parts, 2);
            vx_mesh_free(parts[0]);
            vx_mesh_free(parts[1]);
        }
        assert_non_null(m);
        assert_int_equal(m->boundary_edges, 0);
        for (int centres = 0; centres < 2; centres++) {
            vx_voxelize_desc d = {.inside = VX_INSIDE_WINDING};
            assert_int_equal(vx_grid_from_resolution(m, centres ? 40 : 96, 2, &d.grid, NULL), 0);
            d.grid.h = exp2(ceil(log2(d.grid.h)));
            for (int a = 0; a < 3; a++)
                d.grid.origin[a] = floor(d.grid.origin[a] / d.grid.h * 256) * d.grid.h / 256;
            onto_lattice(m, &d.grid, centres);
            vx_bitgrid g;
            vx_voxelize_stats st;
            vx_err err = {0};
            assert_int_equal(vx_voxelize(NULL, m, &d, &g, &st, &err), 0);
            double iou;
            size_t bad = ref_compare(names[n] ? names[n] : "torus + box", m, &g.grid,
                                     VX_INSIDE_NONZERO, &g, &iou);
            assert_int_equal(bad, 0);
            assert_true(st.voxels_inside > 0);
            vx_bitgrid_free(&g);
        }
        vx_mesh_free(m);
    }
}

/* The first centre at or beyond a crossing at lattice units u along a ray:
 * u snapped to 1/VX_GRID_XING_SNAP voxel, then ceil(u - 1/2). */
static double first_centre(double u)
{
    return ceil(nearbyint(u * VX_GRID_XING_SNAP) / VX_GRID_XING_SNAP - 0.5);
}

/* Centres c of one axis (lattice index ix + c) inside [lo, hi) of a box
 * whose faces have lattice units lo, hi: across z by the snapped coverage
 * and its tie (the centre perturbed towards +), along z by the crossing's
 * first centre at or beyond it. */
static int box_centres(double lo, double hi, int64_t ix, int n, int along_ray)
{
    int k = 0;
    for (int c = 0; c < n; c++) {
        double at = (double)(ix + c);
        if (along_ray)
            k += at >= first_centre(lo) && at < first_centre(hi);
        else
            k += (ix + c) * 256 + 128 >= nearbyint(lo * 256) &&
                 (ix + c) * 256 + 128 < nearbyint(hi * 256);
    }
    return k;
}

/* 1 when a face at lattice units u along a ray's axis (x for cpu, z for
 * winding) gives the same centres by the crossing's snap (2^-20 voxel) as
 * by the coverage's (1/256) with its tie: it lies on a 1/256-voxel step
 * (within rounding), or farther than one from every centre. */
static int same_rule(double u)
{
    double f = u - 0.5 - floor(u - 0.5);
    return fabs(u * 256 - nearbyint(u * 256)) < 256 / VX_GRID_XING_SNAP ||
           (f > 1.0 / 256 && f < 1 - 1.0 / 256);
}

/* Boxes on lattices whose origin and voxel size are not binary fractions,
 * with faces anywhere and on centre planes (a face on a row of centres in
 * every axis): the voxels are the half-open [lo, hi) count along every
 * axis, in any brick, and the cpu method's (rays along x, winding's along
 * z) wherever snapping cannot move a face across a centre on either ray
 * axis. The
 * first box is one a user found: winding set 35 voxels of its top face's
 * plane and dropped the layer on its x and y entry faces. */
static void test_closed_ties(void **state)
{
    (void)state;
    srand48(7);
    int same_as_cpu = 0;
    for (int trial = 0; trial < 120; trial++) {
        double lo[3] = {0.013, 0.027, 0.05}, hi[3] = {3.013, 1.027, 2.05};
        vx_grid g = {.origin = {-0.2, -0.2, -0.2}, .h = 0.1, .dims = {34, 14, 26}};
        if (trial > 0) {
            g.h = (0.05 + drand48()) / 7;
            for (int a = 0; a < 3; a++) {
                g.origin[a] = (drand48() - 0.5) * 3;
                g.dims[a] = 4 + (int)(drand48() * 30);
                g.index[a] = trial % 3 ? 0 : (int64_t)(drand48() * 40) - 20;
                /* faces at centres (i + 1/2), at 1/256 steps, or anywhere */
                for (int e = 0; e < 2; e++) {
                    double c = (double)g.index[a] + drand48() * g.dims[a], u;
                    int kind = (int)(drand48() * 3);
                    u = kind == 0 ? floor(c) + 0.5 : kind == 1 ? floor(c * 256) / 256 : c;
                    (e ? hi : lo)[a] = g.origin[a] + u * g.h;
                }
                if (lo[a] > hi[a]) {
                    double t = lo[a];
                    lo[a] = hi[a];
                    hi[a] = t;
                }
                if (hi[a] - lo[a] < g.h / 8) hi[a] = lo[a] + g.h;
            }
        }
        vx_mesh *m = shape_box(lo, hi);
        int want = 1, comparable = 1;
        for (int a = 0; a < 3; a++) {
            double ul = (lo[a] - g.origin[a]) / g.h, uh = (hi[a] - g.origin[a]) / g.h;
            want *= box_centres(ul, uh, g.index[a], g.dims[a], a == 2);
            if (a != 1) comparable &= same_rule(ul) && same_rule(uh);
        }
        vx_voxelize_desc d = {.grid = g, .inside = VX_INSIDE_WINDING};
        vx_bitgrid w, c;
        vx_voxelize_stats st;
        vx_err err = {0};
        assert_int_equal(vx_voxelize(NULL, m, &d, &w, &st, &err), 0);
        if ((int)st.voxels_inside != want)
            printf("box %d: winding %llu, the [lo, hi) count %d\n", trial,
                   (unsigned long long)st.voxels_inside, want);
        assert_int_equal((int)st.voxels_inside, want);
        if (comparable) {
            d.inside = VX_INSIDE_NONZERO;
            assert_int_equal(vx_voxelize_cpu(m, &d, &c, &st, &err), 0);
            size_t words = c.wx * (size_t)g.dims[1] * g.dims[2], differ = 0;
            for (size_t q = 0; q < words; q++)
                differ += (size_t)__builtin_popcount(c.bits[q] ^ w.bits[q]);
            assert_int_equal(differ, 0);
            same_as_cpu++;
            vx_bitgrid_free(&c);
        }
        if (trial == 0) { /* the top face's plane (k = 22) is empty, x = 0.05 set */
            int top = 0, entry = 0;
            for (int j = 0; j < g.dims[1]; j++)
                for (int i = 0; i < g.dims[0]; i++)
                    top += vx_bitgrid_get(&w, i, j, 22);
            for (int k = 0; k < g.dims[2]; k++)
                for (int j = 0; j < g.dims[1]; j++)
                    entry += vx_bitgrid_get(&w, 2, j, k);
            assert_int_equal(top, 0);
            assert_int_equal(entry, 10 * 20);
            assert_int_equal(want, 30 * 10 * 20);
        }
        vx_bitgrid_free(&w);
        vx_mesh_free(m);
    }
    printf("120 boxes: the [lo, hi) count; %d of them also the cpu method's voxels\n", same_as_cpu);
    assert_true(same_as_cpu >= 100);
}

/* Open boxes (one face left out) on lattices whose origin and voxel size
 * are not binary fractions, the other faces on planes of centres: the
 * missing face's hole is closed by its plane (a planar cone), so the
 * voxels are the closed box's, the half-open [lo, hi) count. The mesh's
 * bounding box, outside which an open mesh's centres are outside, is
 * taken as the crossings are (snapped): unsnapped, a face 4.4e-16 voxel
 * past its plane of centres (how (p - origin) / h rounded) lost that
 * plane's voxels (a helper's one-voxel box: 0 voxels). */
static void test_open_box_ties(void **state)
{
    (void)state;
    srand48(11);
    /* the face each pair of shape_box's triangles makes: axis 2 lo, 2 hi,
     * 1 lo, 1 hi, 0 lo, 0 hi */
    static const int face_axis[6] = {2, 2, 1, 1, 0, 0}, face_hi[6] = {0, 1, 0, 1, 0, 1};
    int lost_before = 0;
    for (int trial = 0; trial < 150; trial++) {
        vx_grid g = {.h = (0.05 + drand48()) / 7};
        double lo[3], hi[3];
        int missing = trial % 6;
        for (int a = 0; a < 3; a++) {
            g.origin[a] = (drand48() - 0.5) * 3;
            g.dims[a] = 4 + (int)(drand48() * 12);
            g.index[a] = trial % 3 ? 0 : (int64_t)(drand48() * 40) - 20;
            int k0 = (int)(drand48() * (g.dims[a] - 2)),
                k1 = k0 + 1 + (int)(drand48() * (g.dims[a] - 1 - k0));
            double u0 = (double)(g.index[a] + k0) + 0.5, u1 = (double)(g.index[a] + k1) + 0.5;
            /* the hole's plane off the centres (its cone not a tie) */
            if (face_axis[missing] == a) *(face_hi[missing] ? &u1 : &u0) += 0.3;
            lo[a] = g.origin[a] + u0 * g.h;
            hi[a] = g.origin[a] + u1 * g.h;
        }
        vx_mesh *box = shape_box(lo, hi);
        uint32_t idx[30];
        for (int t = 0, w = 0; t < 12; t++)
            if (t / 2 != missing) memcpy(idx + 3 * w++, box->tri + 3 * t, 3 * sizeof *idx);
        vx_mesh *m = shape_mesh_from(8, box->pos, 10, idx);
        vx_mesh_free(box);
        assert_true(m->boundary_edges > 0);
        int want = 1;
        for (int a = 0; a < 3; a++) {
            double ul = (lo[a] - g.origin[a]) / g.h, uh = (hi[a] - g.origin[a]) / g.h;
            want *= box_centres(ul, uh, g.index[a], g.dims[a], a == 2);
            /* the old bounding box: unsnapped ceil/floor of its own units */
            lost_before |= ceil(ul - 0.5) != first_centre(ul);
        }
        vx_voxelize_desc d = {.grid = g, .inside = VX_INSIDE_WINDING};
        vx_bitgrid w;
        vx_voxelize_stats st;
        vx_err err = {0};
        assert_int_equal(vx_voxelize(NULL, m, &d, &w, &st, &err), 0);
        if ((int)st.voxels_inside != want)
            printf("open box %d (face %d left out): winding %llu, the [lo, hi) count %d\n", trial,
                   missing, (unsigned long long)st.voxels_inside, want);
        assert_int_equal((int)st.voxels_inside, want);
        vx_bitgrid_free(&w);
        vx_mesh_free(m);
    }
    /* the rounding the fix is for did occur among these lattices */
    assert_true(lost_before);
}

/* A closed box and one open sliver triangle through it, 2L long: the
 * sliver's own winding number is negligible, so the voxels are the box's
 * 1000. The cone that closes the sliver is as long; seen from the box, its
 * corners' unit vectors nearly cancel, and the solid angle once lost
 * every digit to that (1135 voxels at L = 1e8, whole planes wrong). */
static void test_far_sliver(void **state)
{
    (void)state;
    const double L[] = {1e4, 1e8, 1e10, 1e12, 1e13};
    for (int n = 0; n < 5; n++) {
        vx_mesh *parts[2] = {
            shape_box((double[]){0.01, 0.02, 0.03}, (double[]){1.01, 1.02, 1.03}),
            shape_mesh_from(3, (double[]){-L[n], 0.56, 0.57, L[n], 0.56, 0.57, L[n], 0.5601, 0.58},
                            1, (uint32_t[]){0, 1, 2})};
        vx_mesh *m = shape_merge(parts, 2);
        assert_int_equal(m->boundary_edges, 3);
        vx_voxelize_desc d = {
            .inside = VX_INSIDE_WINDING,
            .grid = {.origin = {-0.2, -0.2, -0.2}, .h = 0.1, .dims = {16, 16, 16}}};
        vx_bitgrid g;
        vx_voxelize_stats st;
        vx_err err = {0};
        assert_int_equal(vx_voxelize(NULL, m, &d, &g, &st, &err), 0);
        printf("box + sliver of half-length %g: %llu voxels\n", L[n],
               (unsigned long long)st.voxels_inside);
        assert_int_equal(st.voxels_inside, 1000);
        vx_bitgrid_free(&g);
        vx_mesh_free(m);
        vx_mesh_free(parts[0]);
        vx_mesh_free(parts[1]);
    }
}

/* Bricks of one lattice stitch to the whole grid bit for bit on an open
 * mesh, cut along z too: a run of centres between two crossings is
 * sampled over its whole length whatever brick it crosses (a brick that
 * sampled its own part of a run decided voxels near w = 1/2 otherwise:
 * the bunny's (58, 4, 79..81) in a user's slab of 13). Slabs of 13 and
 * of 5 along z, and boxes cut along every axis. */
/* Bricks of whole (3 ways of cutting it, index offsets from whole's)
 * against whole voxelized at once: 0 voxels may differ. */
static void bricks_match(const char *name, const vx_mesh *m, const vx_grid *whole)
{
    vx_voxelize_desc d = {.grid = *whole, .inside = VX_INSIDE_WINDING};
    vx_bitgrid g;
    vx_voxelize_stats st;
    vx_err err = {0};
    assert_int_equal(vx_voxelize(NULL, m, &d, &g, &st, &err), 0);
    size_t differ = 0, bricks = 0;
    const int *n = whole->dims;
    const int cuts[][3] = {{n[0], n[1], 13}, {n[0], 5, n[2]}, {40, 56, 24}};
    for (int c = 0; c < 3; c++)
        for (int k0 = 0; k0 < n[2]; k0 += cuts[c][2])
            for (int j0 = 0; j0 < n[1]; j0 += cuts[c][1])
                for (int i0 = 0; i0 < n[0]; i0 += cuts[c][0]) {
                    int o[3] = {i0, j0, k0};
                    vx_voxelize_desc b = d;
                    for (int a = 0; a < 3; a++) {
                        b.grid.index[a] = whole->index[a] + o[a];
                        b.grid.dims[a] = n[a] - o[a] < cuts[c][a] ? n[a] - o[a] : cuts[c][a];
                    }
                    vx_bitgrid bg;
                    assert_int_equal(vx_voxelize(NULL, m, &b, &bg, &st, &err), 0);
                    for (int k = 0; k < b.grid.dims[2]; k++)
                        for (int j = 0; j < b.grid.dims[1]; j++)
                            for (int i = 0; i < b.grid.dims[0]; i++)
                                differ += vx_bitgrid_get(&bg, i, j, k) !=
                                          vx_bitgrid_get(&g, i0 + i, j0 + j, k0 + k);
                    vx_bitgrid_free(&bg);
                    bricks++;
                }
    printf("%s, winding: %zu bricks, %zu voxels differ from the whole grid\n", name, bricks,
           differ);
    assert_int_equal(differ, 0);
    vx_bitgrid_free(&g);
}

/* The bunny (its holes face y: rays along z) and suzanne (its eyes face
 * z: rays along y), on lattices whose origin and voxel size are not
 * binary fractions, cut into bricks three ways. */
static void test_bricks_open(void **state)
{
    (void)state;
    vx_mesh *m = shape_load("stanford-bunny.obj");
    assert_non_null(m);
    assert_true(m->boundary_edges > 0);
    const vx_grid bunny = {
        .origin = {-0.09233759531834755, 0.03261293907263908, -0.05981440323721673},
        .h = 0.0009375380490275355,
        .dims = {170, 168, 132},
        .index = {-4, -1, -4}};
    bricks_match("bunny", m, &bunny);
    vx_mesh_free(m);
    m = shape_load("suzanne.obj");
    assert_non_null(m);
    assert_true(m->boundary_edges > 0);
    vx_grid suz;
    assert_int_equal(vx_grid_from_resolution(m, 120, 3, &suz, NULL), 0);
    suz.h *= 1.0137;
    for (int a = 0; a < 3; a++) {
        suz.origin[a] -= 0.0123 * (a + 1);
        suz.index[a] = -3 + 2 * a;
    }
    bricks_match("suzanne", m, &suz);
    vx_mesh_free(m);
}

/* The open bunny (rays along z) and suzanne (along y): every voxel agrees
 * with the direct winding number at sampled centres, and none is set
 * outside the mesh's bounding box. */
static void test_bunny(void **state)
{
    (void)state;
    const char *names[] = {"stanford-bunny.obj", "suzanne.obj"};
    for (int s_ = 0; s_ < 2; s_++) {
        vx_mesh *m = shape_load(names[s_]);
        assert_non_null(m);
        assert_true(m->boundary_edges > 0);
        vx_bitgrid g;
        vx_voxelize_stats st;
        run(m, VX_INSIDE_WINDING, 64, &g, &st);
        const vx_grid *gr = &g.grid;
        size_t agree = 0, n = 0, outside = 0;
        uint64_t s = 99;
        for (int k = 0; k < gr->dims[2]; k++)
            for (int j = 0; j < gr->dims[1]; j++)
                for (int i = 0; i < gr->dims[0]; i++) {
                    double c[3];
                    grid_centre(gr, i, j, k, c);
                    int in = vx_bitgrid_get(&g, i, j, k);
                    for (int a = 0; a < 3; a++)
                        if (in && (c[a] < m->bbox_min[a] || c[a] > m->bbox_max[a])) outside++;
                    s = s * 6364136223846793005ull + 1442695040888963407ull;
                    if ((s >> 40) % 64) continue;
                    n++;
                    agree += (ref_winding_number(m, c) >= 0.5) == in;
                }
        printf("%s 64: %llu inside, %zu/%zu sampled centres agree with the direct sum\n", names[s_],
               (unsigned long long)st.voxels_inside, agree, n);
        assert_int_equal(outside, 0);
        assert_true(agree >= n - n / 1000);
        vx_bitgrid_free(&g);
        vx_mesh_free(m);
    }
}

/* A run whose sampled ends agree while its middle does not: on the bunny at
 * resolution 128 (no padding) column (46, 2) passes under the bottom holes
 * close to their cones without crossing them, and between ends where w <
 * 1/2 the direct sum rises to 0.97 (z 49..60). The middle sample of a run
 * of 8 or more centres finds it; every centre of the columns around it
 * that is clear of 1/2 agrees with the direct sum. */
static void test_middle_sample(void **state)
{
    (void)state;
    vx_mesh *m = shape_load("stanford-bunny.obj");
    assert_non_null(m);
    vx_voxelize_desc d = {.inside = VX_INSIDE_WINDING};
    assert_int_equal(vx_grid_from_resolution(m, 128, 0, &d.grid, NULL), 0);
    vx_bitgrid g;
    vx_voxelize_stats st;
    vx_err err = {0};
    assert_int_equal(vx_voxelize(NULL, m, &d, &g, &st, &err), 0);
    const vx_grid *gr = &g.grid;
    size_t n = 0, differ = 0, bump = 0, bump_in = 0;
    for (int i = 44; i <= 48; i++)
        for (int j = 0; j <= 4; j++)
            for (int k = 0; k < gr->dims[2]; k++) {
                double c[3];
                grid_centre(gr, i, j, k, c);
                double w = ref_winding_number(m, c);
                int in = vx_bitgrid_get(&g, i, j, k);
                if (fabs(w - 0.5) < 0.05) continue;
                if (i == 46 && j == 2 && k >= 49 && k <= 60 && w > 0.5) {
                    bump++;
                    bump_in += in;
                }
                n++;
                differ += (w >= 0.5) != in;
            }
    printf("bunny 128, columns 44..48 x 0..4: %zu of %zu centres clear of 1/2 differ from the "
           "direct sum; column (46, 2), z 49..60: %zu of its %zu centres clear over 1/2 inside\n",
           differ, n, bump_in, bump);
    assert_true(bump >= 10); /* the case is still there */
    assert_int_equal(bump_in, bump);
    assert_int_equal(differ, 0);
    vx_bitgrid_free(&g);
    vx_mesh_free(m);
}

/* Triangles of m as 9 doubles each (what vx_wtree_build takes). */
static double *tri_soup(const vx_mesh *m)
{
    double *tv = malloc(9 * m->ntris * sizeof *tv);
    for (size_t t = 0; t < m->ntris; t++)
        for (int q = 0; q < 3; q++)
            memcpy(tv + 9 * t + 3 * q, m->pos + 3 * (size_t)m->tri[3 * t + q], 3 * sizeof *tv);
    return tv;
}

/* The bunny, its triangles (*tv) and a tree over them. */
static vx_mesh *bunny_tree(vx_wtree *tree, double **tv)
{
    vx_mesh *m = shape_load("stanford-bunny.obj");
    assert_non_null(m);
    *tv = tri_soup(m);
    assert_int_equal(vx_wtree_build(tree, m->ntris, *tv, NULL), 0);
    return m;
}

/* The tree against the direct sum over the bunny's own triangles. */
static void test_tree(void **state)
{
    (void)state;
    vx_wtree tree;
    double *tv;
    vx_mesh *m = bunny_tree(&tree, &tv);
    double worst = 0;
    uint64_t s = 7;
    for (int n = 0; n < 100; n++) {
        double q[3];
        for (int a = 0; a < 3; a++) {
            s = s * 6364136223846793005ull + 1442695040888963407ull;
            double u = (double)(s >> 11) / 9007199254740992.0;
            double lo = m->bbox_min[a], hi = m->bbox_max[a];
            q[a] = lo - 0.2 * (hi - lo) + 1.4 * (hi - lo) * u;
        }
        double e = fabs(vx_wtree_eval(&tree, q) - ref_winding_number(m, q));
        if (e > worst) worst = e;
    }
    printf("tree vs direct sum, 100 points: worst error %.2e\n", worst);
    assert_true(worst < 0.05); /* beta 2: about 4e-2 on the bunny's own surface */
    vx_wtree_free(&tree);
    free(tv);
    vx_mesh_free(m);
}

/* A closed octahedron is one leaf of the tree: inside it the leaf's
 * half-angles add up to 2 pi (w = 1), so the sum must count the turn past
 * pi that one atan2 of their product cannot see; outside, 0. Reversed
 * faces give -1. Points from near the centre to just off the faces. */
static void test_tree_leaf_turns(void **state)
{
    (void)state;
    const double pos[] = {1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1};
    const uint32_t idx[] = {0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5};
    vx_mesh *m = shape_mesh_from(6, pos, 8, idx);
    assert_true(shape_signed_volume(m) > 0);
    for (int flip = 0; flip < 2; flip++) {
        if (flip) shape_flip(m);
        double *tv = tri_soup(m);
        vx_wtree tree;
        assert_int_equal(vx_wtree_build(&tree, m->ntris, tv, NULL), 0);
        assert_int_equal(tree.nnodes, 1);
        double worst = 0, want_in = flip ? -1 : 1;
        uint64_t s = 11;
        for (int n = 0; n < 2000; n++) {
            double q[3], l1 = 0;
            for (int a = 0; a < 3; a++) {
                s = s * 6364136223846793005ull + 1442695040888963407ull;
                q[a] = 2.4 * ((double)(s >> 11) / 9007199254740992.0) - 1.2;
                l1 += fabs(q[a]);
            }
            if (fabs(l1 - 1) < 1e-6) continue; /* on a face */
            double w = vx_wtree_eval(&tree, q), want = l1 < 1 ? want_in : 0;
            double e = fabs(w - want), r = fabs(w - ref_winding_number(m, q));
            worst = e > worst ? e : worst;
            worst = r > worst ? r : worst;
        }
        printf("octahedron%s, one leaf: worst error %.2e over 2000 points\n",
               flip ? " (reversed)" : "", worst);
        assert_true(worst < 1e-4); /* atan2_fast: about 1e-5 radians */
        vx_wtree_free(&tree);
        free(tv);
    }
    vx_mesh_free(m);
}

/* A random box about the box at `at` of size e (its corner lo from at - 1.5 e
 * to at + 2.5 e, each side up to `side` e long), flat along axis `flat` (0..2; 3:
 * none), from the generator s. */
static void random_box(uint64_t *s, int flat, const double at[3], const double e[3], double side,
                       double lo[3], double hi[3])
{
    for (int a = 0; a < 3; a++) {
        double u[2];
        for (int k = 0; k < 2; k++) {
            *s = *s * 6364136223846793005ull + 1442695040888963407ull;
            u[k] = (double)(*s >> 11) / 9007199254740992.0;
        }
        lo[a] = at[a] - 1.5 * e[a] + 4 * e[a] * u[0];
        hi[a] = flat == a ? lo[a] : lo[a] + side * e[a] * u[1];
    }
}

/* vx_wtree_eval4 gives each of its points the bits vx_wtree_eval gives
 * (the same operations, four lanes at a time): on the bunny's tree
 * (leaves with their corners listed) and a long sliver's (the edge-on
 * fallback), for points at random, at corners of the triangles, on their
 * edges and at edge midpoints, n = 1..4 a call, the points of a call
 * near each other (one walk of the tree) or far apart (lanes masked).
 * vx_wtree_bound4 gives each box vx_wtree_bound's bits: boxes of every
 * shape about the tree, each lane its own limit and side. */
static void test_tree_four(void **state)
{
    (void)state;
    vx_wtree trees[2];
    double *tv;
    vx_mesh *m = bunny_tree(&trees[0], &tv);
    const double sliver[9] = {-1e8, 0, 0, 1e8, 0, 0, 0, 1e-3, 0};
    assert_int_equal(vx_wtree_build(&trees[1], 1, sliver, NULL), 0);
    uint64_t s = 5;
    long compared = 0, differ = 0, special = 0;
    for (int tr = 0; tr < 2; tr++) {
        const vx_wtree *t = &trees[tr];
        const double *lo = tr ? (const double[3]){-2, -1, -1} : m->bbox_min,
                     *hi = tr ? (const double[3]){2, 1, 1} : m->bbox_max;
        for (int call = 0; call < 20000; call++) {
            double q[4][3], w4[4];
            int n = 1 + call % 4;
            for (int l = 0; l < n; l++) {
                s = s * 6364136223846793005ull + 1442695040888963407ull;
                int kind = (int)(s >> 60) % 4; /* random, corner, on an edge, near the last */
                size_t k = (size_t)(s >> 20) % t->ntris;
                const double *v = t->tv + 9 * k;
                for (int a = 0; a < 3; a++) {
                    s = s * 6364136223846793005ull + 1442695040888963407ull;
                    double u = (double)(s >> 11) / 9007199254740992.0;
                    if (kind == 0 || (kind == 3 && l == 0))
                        q[l][a] = lo[a] - 0.2 * (hi[a] - lo[a]) + 1.4 * (hi[a] - lo[a]) * u;
                    else if (kind == 1)
                        q[l][a] = v[a];
                    else if (kind == 2)
                        q[l][a] = call % 3 ? v[a] + u * (v[3 + a] - v[a]) : (v[a] + v[3 + a]) / 2;
                    else
                        q[l][a] = q[l - 1][a] + 1e-3 * (hi[a] - lo[a]) * (u - 0.5);
                }
                special += kind == 1 || kind == 2;
            }
            vx_wtree_eval4(t, (const double(*)[3])q, n, w4);
            for (int l = 0; l < n; l++) {
                double w = vx_wtree_eval(t, q[l]);
                compared++;
                if (memcmp(&w, &w4[l], sizeof w) && !(w == 0 && w4[l] == 0)) {
                    if (differ++ < 5)
                        printf("tree %d call %d lane %d: %.17g, alone %.17g\n", tr, call, l, w4[l],
                               w);
                }
            }
        }
    }
    printf("eval4 against eval: %ld points (%ld at corners or on edges), %ld differ\n", compared,
           special, differ);
    assert_int_equal(differ, 0);
    assert_true(special > 10000);
    long boxes = 0, bdiffer = 0, under = 0;
    for (int tr = 0; tr < 2; tr++) {
        const vx_wtree *t = &trees[tr];
        double at[3], e[3];
        for (int a = 0; a < 3; a++) {
            at[a] = tr ? -1 : m->bbox_min[a];
            e[a] = tr ? 0.5 : (m->bbox_max[a] - m->bbox_min[a]) / 4;
        }
        for (int call = 0; call < 5000; call++) {
            double lo[4][3], hi[4][3], limit[4], b4[4];
            int side[4], n = 1 + call % 4;
            for (int l = 0; l < n; l++) {
                random_box(&s, (call + l) % 4, at, e, l % 2 ? 0.05 : 0.6, lo[l], hi[l]);
                s = s * 6364136223846793005ull + 1442695040888963407ull;
                limit[l] = 0.5 + (double)(s >> 61); /* 0.5 .. 7.5 */
                side[l] = (int)(s >> 40) % 3 - 1;
            }
            vx_wtree_bound4(t, (const double(*)[3])lo, (const double(*)[3])hi, limit, side, n, b4);
            for (int l = 0; l < n; l++) {
                double b = vx_wtree_bound(t, lo[l], hi[l], limit[l], side[l]);
                boxes++;
                under += b < limit[l];
                if (memcmp(&b, &b4[l], sizeof b) && bdiffer++ < 5)
                    printf("tree %d box call %d lane %d: %.17g, alone %.17g\n", tr, call, l, b4[l],
                           b);
            }
        }
    }
    printf("bound4 against bound: %ld boxes (%ld under their limits), %ld differ\n", boxes, under,
           bdiffer);
    assert_int_equal(bdiffer, 0);
    assert_true(under > boxes / 10 && under < boxes - boxes / 10);
    for (int tr = 0; tr < 2; tr++)
        vx_wtree_free(&trees[tr]);
    free(tv);
    vx_mesh_free(m);
}

/* vx_wtree_bound over a box is at least |w| anywhere in it: boxes of
 * every shape (segments along each axis included) at random places
 * around the bunny, w sampled at their corners and inside. */
static void test_tree_bound_box(void **state)
{
    (void)state;
    vx_wtree tree;
    double *tv;
    vx_mesh *m = bunny_tree(&tree, &tv);
    uint64_t s = 5;
    int bounded = 0;
    for (int n = 0; n < 300; n++) {
        double lo[3], hi[3], e[3];
        for (int a = 0; a < 3; a++)
            e[a] = m->bbox_max[a] - m->bbox_min[a];
        random_box(&s, n % 4, m->bbox_min, e, 0.8, lo, hi);
        double b = vx_wtree_bound(&tree, lo, hi, 10, 0);
        if (b >= 10) continue;
        bounded++;
        for (int k = 0; k < 27; k++) {
            double q[3];
            for (int a = 0; a < 3; a++) {
                int f = k / (a == 0 ? 1 : a == 1 ? 3 : 9) % 3; /* 0, middle, 1 */
                q[a] = lo[a] + (hi[a] - lo[a]) * (f == 0 ? 0 : f == 1 ? 0.37 : 1);
            }
            double w = fabs(vx_wtree_eval(&tree, q));
            if (w > b) printf("box %d point %d: |w| %.4f over the bound %.4f\n", n, k, w, b);
            assert_true(w <= b);
        }
    }
    printf("%d of 300 boxes bounded under 10, none exceeded\n", bounded);
    assert_true(bounded >= 100);
    vx_wtree_free(&tree);
    free(tv);
    vx_mesh_free(m);
    /* one triangle, segments along each axis from 10 away to 1 away
     * (either end the near one): the bound holds at the near end */
    const double tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    assert_int_equal(vx_wtree_build(&tree, 1, tri, NULL), 0);
    for (int a = 0; a < 3; a++)
        for (int near_hi = 0; near_hi < 2; near_hi++) {
            double lo[3] = {0.3, 0.3, 0.3}, hi[3] = {0.3, 0.3, 0.3}, q[3] = {0.3, 0.3, 0.3};
            lo[a] = near_hi ? -10 : 1.5;
            hi[a] = near_hi ? -1.5 : 10;
            q[a] = near_hi ? hi[a] : lo[a];
            double b = vx_wtree_bound(&tree, lo, hi, 10, 0), w = fabs(vx_wtree_eval(&tree, q));
            printf("one triangle, axis %d, near end %s: bound %.4f, |w| there %.4f\n", a,
                   near_hi ? "hi" : "lo", b, w);
            assert_true(w > 1e-3);
            assert_true(b >= w);
        }
    vx_wtree_free(&tree);
}

/* The one-sided bounds on an open surface, where w does not cancel: a
 * shallow cone of 48 triangles over a unit circle (a hole's cap), random
 * segments and boxes within 2 of it. Where a side's bound is under 1/2,
 * w sampled in the box stays under it; and from beside the cap, on the
 * side where w < 0, the bound from above is often under 1/2 where the
 * magnitude's is not. */
static void test_tree_bound_sides(void **state)
{
    (void)state;
    enum { N = 48 };
    double tv[9 * N];
    for (int t = 0; t < N; t++) {
        double a0 = 2 * M_PI * t / N, a1 = 2 * M_PI * (t + 1) / N;
        double v[9] = {cos(a1), sin(a1), 0, cos(a0), sin(a0), 0, 0, 0, 0.2};
        memcpy(tv + 9 * t, v, sizeof v);
    }
    vx_wtree tree;
    assert_int_equal(vx_wtree_build(&tree, N, tv, NULL), 0);
    uint64_t s = 11;
    int checked = 0, gained[2] = {0, 0};
    for (int n = 0; n < 2000; n++) {
        double lo[3], hi[3];
        random_box(&s, n % 4, (const double[3]){-0.5, -0.5, -0.5}, (const double[3]){1, 1, 1}, 0.6,
                   lo, hi);
        double b = vx_wtree_bound(&tree, lo, hi, 0.5, 0),
               bp = vx_wtree_bound(&tree, lo, hi, 0.5, 1),
               bn = vx_wtree_bound(&tree, lo, hi, 0.5, -1);
        gained[0] += bp < 0.5 && b >= 0.5;
        gained[1] += bn < 0.5 && b >= 0.5;
        for (int k = 0; k < 27 && (bp < 0.5 || bn < 0.5); k++) {
            double q[3];
            for (int a = 0; a < 3; a++) {
                int f = k / (a == 0 ? 1 : a == 1 ? 3 : 9) % 3;
                q[a] = lo[a] + (hi[a] - lo[a]) * (f == 0 ? 0 : f == 1 ? 0.61 : 1);
            }
            double w = vx_wtree_eval(&tree, q);
            if ((bp < 0.5 && w > bp) || (bn < 0.5 && -w > bn))
                printf("box %d point %d: w %.4f over the one-sided bounds %.4f, %.4f\n", n, k, w,
                       bp, bn);
            assert_true(bp >= 0.5 || w <= bp);
            assert_true(bn >= 0.5 || -w <= bn);
            checked++;
        }
    }
    printf("a cap: %d points checked; w bounded under 1/2 from above %d times, from below %d "
           "times, where |w| was not\n",
           checked, gained[0], gained[1]);
    assert_true(gained[0] >= 50 && gained[1] >= 50);
    vx_wtree_free(&tree);
}

/* A memory limit the crossings pass: job_memory_limit, nothing returned;
 * a larger one runs. */
static void test_memory_limit(void **state)
{
    (void)state;
    double top;
    vx_mesh *bowl = cut_above(shape_sphere(0, 0, 0, 1, 0), 0.5, &top);
    vx_voxelize_desc d = {.inside = VX_INSIDE_WINDING};
    assert_int_equal(vx_grid_from_resolution(bowl, 128, 0, &d.grid, NULL), 0);
    uint64_t grid = vx_bitgrid_bytes(d.grid.dims, 1);
    d.max_memory = grid + 1024;
    vx_bitgrid g;
    vx_voxelize_stats st;
    vx_err err = {0};
    assert_int_equal(vx_voxelize(NULL, bowl, &d, &g, &st, &err), -1);
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_string_equal(err.code, "job_memory_limit");
    assert_null(g.bits);
    d.max_memory = grid + (16u << 20);
    assert_int_equal(vx_voxelize(NULL, bowl, &d, &g, &st, &err), 0);
    assert_true(st.voxels_inside > 0);
    vx_bitgrid_free(&g);
    vx_mesh_free(bowl);
}

static int stop_now(void *ud, double f, vx_err *err)
{
    (void)f;
    (*(int *)ud)++;
    return vx_err_set(err, VX_ETIMEOUT, "job_timeout", "stop");
}

/* The default rule and the stop hook. */
static void test_default_and_stop(void **state)
{
    (void)state;
    double top;
    vx_mesh *bowl = cut_above(shape_sphere(0, 0, 0, 1, 0), 1e-9, &top);
    vx_mesh *ball_m = shape_sphere(0, 0, 0, 1, 0);
    vx_voxelize_desc d = {.supersample = 1};
    assert_int_equal(vx_voxelize_default_inside(bowl, &d), VX_INSIDE_WINDING);
    assert_int_equal(vx_voxelize_default_inside(ball_m, &d), VX_INSIDE_NONZERO);
    d.method = VX_METHOD_PEEL;
    assert_int_equal(vx_voxelize_default_inside(bowl, &d), VX_INSIDE_NONZERO);
    d.method = VX_METHOD_AUTO;
    d.supersample = 2;
    assert_int_equal(vx_voxelize_default_inside(bowl, &d), VX_INSIDE_NONZERO);
    d.samples = VX_SAMPLES_FACES;
    assert_int_equal(vx_voxelize_default_inside(bowl, &d), VX_INSIDE_WINDING);

    int calls = 0;
    vx_voxelize_desc s = {.inside = VX_INSIDE_WINDING, .progress = stop_now, .ud = &calls};
    assert_int_equal(vx_grid_from_resolution(bowl, 256, 0, &s.grid, NULL), 0);
    vx_bitgrid g;
    vx_voxelize_stats st;
    vx_err err = {0};
    assert_int_equal(vx_voxelize(NULL, bowl, &s, &g, &st, &err), -1);
    assert_int_equal(err.kind, VX_ETIMEOUT);
    assert_true(calls >= 1);
    assert_null(g.bits);
    /* supersample 2 with the cube samples is refused */
    s.progress = NULL;
    s.supersample = 2;
    assert_int_equal(vx_voxelize(NULL, bowl, &s, &g, &st, &err), -1);
    assert_int_equal(err.kind, VX_EUNPROC);
    vx_mesh_free(bowl);
    vx_mesh_free(ball_m);
}

int main(int argc, char **argv)
{
    if (argc > 1) cmocka_set_test_filter(argv[1]); /* e.g. test_tree */
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_overlap_open),   cmocka_unit_test(test_nested),
        cmocka_unit_test(test_open_shells),    cmocka_unit_test(test_run_starts),
        cmocka_unit_test(test_closed_exact),   cmocka_unit_test(test_closed_ties),
        cmocka_unit_test(test_far_sliver),     cmocka_unit_test(test_open_box_ties),
        cmocka_unit_test(test_bricks_open),    cmocka_unit_test(test_bunny),
        cmocka_unit_test(test_middle_sample),  cmocka_unit_test(test_tree),
        cmocka_unit_test(test_tree_four),      cmocka_unit_test(test_tree_leaf_turns),
        cmocka_unit_test(test_tree_bound_box), cmocka_unit_test(test_tree_bound_sides),
        cmocka_unit_test(test_memory_limit),   cmocka_unit_test(test_default_and_stop),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
