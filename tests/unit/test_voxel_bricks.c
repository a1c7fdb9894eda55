/* Bricks of one lattice (issue 14 #2): a grid voxelized whole and as
 * bricks that name their place with grid.index (index_offset in the API)
 * gives the same voxels bit for bit, for every method, inside rule, fill
 * and supersampling, on lattices whose origin and voxel size are not
 * binary fractions. The GPU methods decide every crossing from the
 * lattice's own numbers (src/voxel/xing.h), so this holds exactly, near
 * ties included: random bricks of the shared meshes, and random lattices
 * far from the origin (index offsets up to 2^30) cut into random bricks,
 * with meshes that reach far outside the bricks, open meshes and
 * overlapping parts. */
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

static const char *const method_name[] = {"auto", "peel", "slice", "scan", "cpu"};
static const char *const rule_name[] = {"nonzero", "parity", "robust", "winding"};

/* A configuration to voxelize with. */
typedef struct cfg {
    vx_method method;
    vx_inside rule;
    vx_fill fill;
    int ss;             /* 0/1, or 2 */
    vx_samples samples; /* with ss 2 */
} cfg;

static void voxelize_cfg(const vx_mesh *m, const vx_grid *g, const cfg *c, vx_bitgrid *out)
{
    vx_voxelize_desc d = {.grid = *g,
                          .method = c->method,
                          .inside = c->rule,
                          .fill = c->fill,
                          .supersample = c->ss,
                          .samples = c->samples};
    vx_voxelize_stats st;
    vx_err err = {0};
    int rc = vx_voxelize(vx_test_gl, m, &d, out, &st, &err);
    if (rc) fprintf(stderr, "voxelize: %s: %s\n", err.code, err.message);
    assert_int_equal(rc, 0);
}

static void voxelize(const vx_mesh *m, const vx_grid *g, vx_method method, vx_inside rule,
                     vx_fill fill, vx_bitgrid *out)
{
    vx_voxelize_desc d = {.grid = *g, .method = method, .inside = rule, .fill = fill};
    vx_voxelize_stats st;
    vx_err err = {0};
    int rc = vx_voxelize(vx_test_gl, m, &d, out, &st, &err);
    if (rc) fprintf(stderr, "voxelize: %s: %s\n", err.code, err.message);
    assert_int_equal(rc, 0);
}

/* Voxels of brick b (at lattice index b->grid.index) that differ from the
 * whole grid w (index 0). */
static size_t brick_diff(const vx_bitgrid *w, const vx_bitgrid *b)
{
    size_t n = 0;
    const int64_t *o = b->grid.index;
    for (int k = 0; k < b->grid.dims[2]; k++)
        for (int j = 0; j < b->grid.dims[1]; j++)
            for (int i = 0; i < b->grid.dims[0]; i++)
                n += vx_bitgrid_get(b, i, j, k) !=
                     vx_bitgrid_get(w, (int)o[0] + i, (int)o[1] + j, (int)o[2] + k);
    return n;
}

/* Voxels (bits, and counts when both have them) of brick b that differ
 * from the whole grid w; b->grid.index and w->grid.index on one lattice. */
static size_t brick_diff_at(const vx_bitgrid *w, const vx_bitgrid *b)
{
    size_t n = 0;
    int64_t o[3];
    for (int a = 0; a < 3; a++)
        o[a] = b->grid.index[a] - w->grid.index[a];
    const int *bd = b->grid.dims, *wd = w->grid.dims;
    for (int k = 0; k < bd[2]; k++)
        for (int j = 0; j < bd[1]; j++)
            for (int i = 0; i < bd[0]; i++) {
                int wi = (int)o[0] + i, wj = (int)o[1] + j, wk = (int)o[2] + k;
                int bad = vx_bitgrid_get(b, i, j, k) != vx_bitgrid_get(w, wi, wj, wk);
                if (b->counts && w->counts)
                    bad |= b->counts[((size_t)k * bd[1] + j) * bd[0] + i] !=
                           w->counts[((size_t)wk * wd[1] + wj) * wd[0] + wi];
                n += bad;
            }
    return n;
}

/* Cuts [0, n) into 1 to 3 random pieces: cut[0] = 0 < ... < cut[*np] = n. */
static void cuts(int n, int cut[4], int *np)
{
    int want = 1 + (int)(drand48() * 3);
    cut[0] = 0;
    *np = 0;
    for (int p = 1; p < want; p++) {
        int c = 1 + (int)(drand48() * (n - 1));
        if (c > cut[*np]) cut[++*np] = c;
    }
    cut[++*np] = n;
}

/* The lattice: the bbox x 1.05, n voxels along the longest side. */
static void lattice(const vx_mesh *m, int n, vx_grid *g)
{
    double ext = 0;
    for (int a = 0; a < 3; a++)
        ext = fmax(ext, m->bbox_max[a] - m->bbox_min[a]);
    memset(g, 0, sizeof *g);
    g->h = ext * 1.05 / n;
    for (int a = 0; a < 3; a++) {
        g->origin[a] = m->bbox_min[a] - ext * 0.025;
        g->dims[a] = n;
    }
}

static void test_bricks_stitch(void **state)
{
    (void)state;
    const char *names[] = {"spot_triangulated.obj", "rocker-arm.obj", "fandisk.obj",
                           "stanford-bunny.obj"};
    srand48(2);
    size_t total = 0, voxels = 0;
    for (int mi = 0; mi < 4; mi++) {
        vx_mesh *m = shape_load(names[mi]);
        assert_non_null(m);
        vx_grid whole;
        lattice(m, 64, &whole);
        for (int method = 0; method < 5; method++)
            for (int rule = 0; rule < 3; rule++)
                for (int fill = 0; fill < 2; fill++) {
                    if (method == VX_METHOD_SLICE && fill == VX_FILL_SURFACE) continue;
                    if (method == VX_METHOD_CPU && (fill || rule == VX_INSIDE_ROBUST)) continue;
                    if (fill == VX_FILL_SURFACE && rule != VX_INSIDE_NONZERO) continue;
                    vx_bitgrid w;
                    voxelize(m, &whole, (vx_method)method, (vx_inside)rule, (vx_fill)fill, &w);
                    size_t bad = 0;
                    /* four random bricks */
                    for (int r = 0; r < 4; r++) {
                        vx_grid g = whole;
                        for (int a = 0; a < 3; a++) {
                            int lo = (int)(drand48() * 48), len = 8 + (int)(drand48() * 40);
                            if (lo + len > 64) len = 64 - lo;
                            g.index[a] = lo;
                            g.dims[a] = len;
                        }
                        vx_bitgrid b;
                        voxelize(m, &g, (vx_method)method, (vx_inside)rule, (vx_fill)fill, &b);
                        bad += brick_diff(&w, &b);
                        voxels += (size_t)g.dims[0] * g.dims[1] * g.dims[2];
                        vx_bitgrid_free(&b);
                    }
                    if (bad)
                        printf("%s %s %s%s: %zu voxels differ from the whole grid\n", names[mi],
                               method_name[method], rule_name[rule], fill ? " surface" : "", bad);
                    total += bad;
                    vx_bitgrid_free(&w);
                }
        vx_mesh_free(m);
    }
    printf("%zu of %zu brick voxels differ\n", total, voxels);
    assert_int_equal(total, 0);
}

/* Boxes whose faces lie within eps of voxel centres' planes (eps from
 * 1e-3 down to 0, either side) on lattice `whole`: near ties for every
 * ray that meets them, along the ray (faces across it) and in the image
 * (faces along it); some turned slightly, so their faces pass near many
 * centres at once. */
static vx_mesh *tie_boxes(const vx_grid *whole, int nbox)
{
    static const double eps[] = {1e-3, 1e-5, 1e-7, 1e-9, 0};
    vx_mesh **parts = malloc((size_t)nbox * sizeof *parts);
    assert_non_null(parts);
    for (int b = 0; b < nbox; b++) {
        double lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            int n = whole->dims[a];
            int i0 = (int)(drand48() * (n - 2)), i1 = i0 + 1 + (int)(drand48() * (n - 1 - i0));
            double e0 = eps[(int)(drand48() * 5)] * (drand48() < 0.5 ? -1 : 1),
                   e1 = eps[(int)(drand48() * 5)] * (drand48() < 0.5 ? -1 : 1);
            /* lattice units: centre i is at index + i + 1/2 */
            lo[a] = (double)whole->index[a] + i0 + 0.5 + e0;
            hi[a] = (double)whole->index[a] + i1 + 0.5 + e1;
        }
        vx_mesh *box = shape_box(lo, hi);
        double ang = b % 2 ? (drand48() - 0.5) * 1e-4 : 0, c = cos(ang), sn = sin(ang);
        for (size_t v = 0; v < box->nverts; v++) {
            double *p = box->pos + 3 * v, x = p[0], y = p[1];
            /* turned about z through the box's corner, then into space */
            p[0] = lo[0] + (x - lo[0]) * c - (y - lo[1]) * sn;
            p[1] = lo[1] + (x - lo[0]) * sn + (y - lo[1]) * c;
            for (int a = 0; a < 3; a++)
                p[a] = whole->origin[a] + p[a] * whole->h;
        }
        parts[b] = box;
    }
    vx_mesh *m = shape_merge(parts, nbox);
    for (int b = 0; b < nbox; b++)
        vx_mesh_free(parts[b]);
    free(parts);
    return m;
}

/* Random lattices: voxel size and origin not binary fractions, the whole
 * grid at a random index offset (up to 2^30 from the lattice's origin),
 * cut into random bricks that cover it; every configuration below, on
 * meshes chosen for ties: a torus, overlapping spheres (one inside out),
 * the open bunny, rocker-arm (slivers seen edge-on) and a box that reaches
 * hundreds of voxels beyond the grid on every side. */
static void test_bricks_random(void **state)
{
    (void)state;
    vx_mesh *meshes[6];
    meshes[0] = shape_param_mesh(48, 24, 0, 0, 0, 0, 0, 1.0, 0.35);
    vx_mesh *sph[2] = {shape_sphere(0, 0, 0, 1, 0), shape_sphere(0.6, 0.2, 0.1, 0.7, 1)};
    meshes[1] = shape_merge(sph, 2);
    vx_mesh_free(sph[0]);
    vx_mesh_free(sph[1]);
    assert_non_null(meshes[2] = shape_load("stanford-bunny.obj"));
    assert_non_null(meshes[3] = shape_load("rocker-arm.obj"));
    meshes[4] = shape_box((double[]){-7, -9, -8}, (double[]){8, 6.5, 7});
    meshes[5] = NULL; /* tie boxes, made on each trial's lattice */
    const char *names[6] = {"torus", "spheres", "bunny", "rocker-arm", "far box", "tie boxes"};
    const cfg cfgs[] = {
        {VX_METHOD_SCAN, VX_INSIDE_NONZERO, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_SCAN, VX_INSIDE_PARITY, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_CPU, VX_INSIDE_NONZERO, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_CPU, VX_INSIDE_PARITY, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_CPU, VX_INSIDE_NONZERO, VX_FILL_SOLID, 2, VX_SAMPLES_FACES},
        {VX_METHOD_PEEL, VX_INSIDE_NONZERO, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_PEEL, VX_INSIDE_PARITY, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_PEEL, VX_INSIDE_ROBUST, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_PEEL, VX_INSIDE_NONZERO, VX_FILL_SURFACE, 1, 0},
        {VX_METHOD_SLICE, VX_INSIDE_NONZERO, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_SLICE, VX_INSIDE_PARITY, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_SLICE, VX_INSIDE_ROBUST, VX_FILL_SOLID, 1, 0},
        {VX_METHOD_SLICE, VX_INSIDE_NONZERO, VX_FILL_SOLID, 2, VX_SAMPLES_CUBE},
        {VX_METHOD_AUTO, VX_INSIDE_NONZERO, VX_FILL_SOLID, 2, VX_SAMPLES_FACES},
        {VX_METHOD_AUTO, VX_INSIDE_WINDING, VX_FILL_SOLID, 1, 0},
    };
    const int ncfg = (int)(sizeof cfgs / sizeof cfgs[0]);
    srand48(15);
    size_t total = 0, voxels = 0, runs = 0;
    for (int mi = 0; mi < 6; mi++) {
        const vx_mesh *m = meshes[mi == 5 ? 0 : mi];
        /* the far box: the mesh's own bbox is the cube in the middle */
        double lo[3], hi[3], ext = 0;
        for (int a = 0; a < 3; a++) {
            lo[a] = mi == 4 ? -1.0 : m->bbox_min[a];
            hi[a] = mi == 4 ? 1.0 : m->bbox_max[a];
            ext = fmax(ext, hi[a] - lo[a]);
        }
        for (int trial = 0; trial < 4; trial++) {
            int n = 24 + (int)(drand48() * 24);
            vx_grid whole = {.h = ext * (1.0 + 0.2 * drand48()) / n};
            for (int a = 0; a < 3; a++) {
                int64_t at = (int64_t)((drand48() - 0.5) * 2.0 * (double)(1 << 30));
                whole.index[a] = at;
                whole.dims[a] = (int)ceil((hi[a] - lo[a]) / whole.h) + 4;
                /* the lattice's origin: the whole grid starts 2 voxels
                 * (and a fraction) below the bbox */
                whole.origin[a] = lo[a] - (2.0 + drand48()) * whole.h - (double)at * whole.h;
            }
            if (mi == 5) {
                vx_mesh_free(meshes[5]);
                m = meshes[5] = tie_boxes(&whole, 12);
            }
            /* three configurations a trial, every one over the trials;
             * all of them on the tie boxes */
            for (int q = 0; q < (mi == 5 ? ncfg : 3); q++) {
                const cfg *c = &cfgs[(trial * 3 + q + mi) % ncfg];
                vx_bitgrid w;
                voxelize_cfg(m, &whole, c, &w);
                int cx[4], cy[4], cz[4], nx, ny, nz;
                cuts(whole.dims[0], cx, &nx);
                cuts(whole.dims[1], cy, &ny);
                cuts(whole.dims[2], cz, &nz);
                size_t bad = 0;
                for (int bz = 0; bz < nz; bz++)
                    for (int by = 0; by < ny; by++)
                        for (int bx = 0; bx < nx; bx++) {
                            vx_grid g = whole;
                            int lo3[3] = {cx[bx], cy[by], cz[bz]},
                                hi3[3] = {cx[bx + 1], cy[by + 1], cz[bz + 1]};
                            for (int a = 0; a < 3; a++) {
                                g.index[a] = whole.index[a] + lo3[a];
                                g.dims[a] = hi3[a] - lo3[a];
                            }
                            vx_bitgrid b;
                            voxelize_cfg(m, &g, c, &b);
                            bad += brick_diff_at(&w, &b);
                            vx_bitgrid_free(&b);
                        }
                runs++;
                voxels += (size_t)whole.dims[0] * whole.dims[1] * whole.dims[2];
                if (bad)
                    printf("%s trial %d: %s %s%s ss%d%s, %dx%dx%d bricks: %zu voxels differ\n",
                           names[mi], trial, method_name[c->method], rule_name[c->rule],
                           c->fill ? " surface" : "", c->ss ? c->ss : 1,
                           c->samples == VX_SAMPLES_FACES ? " faces" : "", nx, ny, nz, bad);
                total += bad;
                vx_bitgrid_free(&w);
            }
        }
    }
    printf("random lattices: %zu runs, %zu of %zu voxels differ\n", runs, total, voxels);
    assert_int_equal(total, 0);
    for (int i = 0; i < 6; i++)
        vx_mesh_free(meshes[i]);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bricks_stitch),
        cmocka_unit_test(test_bricks_random),
    };
    return cmocka_run_group_tests(tests, vx_test_gl_setup, vx_test_gl_teardown);
}
