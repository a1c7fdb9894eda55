/* Gregory meshes (seed 001): G1 of the interpolate construction across
 * every shared edge, predicted counts, welding, the GPU tessellator against
 * the CPU evaluator, frames against fresh builds, the teapot's Bézier
 * patches, max_edge divisions, and the job params. */
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
#include "shapes.h"
#include "gregory/gregory.h"
#include "gregory/job.h"
#include "gregory/tess.h"
#include "gregory/tess_int.h"

static vx_mesh *load(const char *name)
{
    vx_mesh *m = shape_load(name);
    assert_non_null(m);
    return m;
}

/* A closed pentagonal prism, one side split into two triangles, twisted
 * and bent so that nothing is planar: pentagons, quads and triangles. */
static vx_mesh *ngon_mesh(void)
{
    vx_mesh *m = vx_mesh_new();
    assert_non_null(m);
    m->nverts = 10;
    m->pos = malloc(30 * sizeof *m->pos);
    for (int k = 0; k < 5; k++)
        for (int top = 0; top < 2; top++) {
            double a = 2 * M_PI * k / 5 + (top ? 0.3 : 0), r = top ? 0.8 : 1.0 + 0.1 * k;
            double *p = m->pos + 3 * (5 * top + k);
            p[0] = r * cos(a);
            p[1] = r * sin(a);
            p[2] = top ? 1.2 + 0.1 * sin(3 * a) : 0.05 * k;
        }
    static const uint32_t idx[] = {4, 3, 2, 1, 0, 5, 6, 7, 8, 9, 0, 1, 6, 0, 6, 5,
                                   1, 2, 7, 6, 2, 3, 8, 7, 3, 4, 9, 8, 4, 0, 5, 9};
    static const uint32_t start[] = {0, 5, 10, 13, 16, 20, 24, 28, 32};
    m->nfaces = 8;
    m->face_idx = malloc(sizeof idx);
    m->face_start = malloc(sizeof start);
    memcpy(m->face_idx, idx, sizeof idx);
    memcpy(m->face_start, start, sizeof start);
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    assert_int_equal(m->boundary_edges, 0);
    return m;
}

static vx_gpatch_set *build(const vx_mesh *m, vx_gregory_topo **topo_out)
{
    vx_err err = {0};
    vx_gregory_topo *t = vx_gregory_topo_new(m, &err);
    assert_non_null(t);
    vx_gpatch_set *s = vx_gpatch_set_new(vx_gregory_topo_npatches(t));
    assert_non_null(s);
    vx_gregory_build(t, m->pos, s);
    if (topo_out)
        *topo_out = t;
    else
        vx_gregory_topo_free(t);
    return s;
}

static double diag(const vx_mesh *m)
{
    double d = 0;
    for (int c = 0; c < 3; c++)
        d += (m->bbox_max[c] - m->bbox_min[c]) * (m->bbox_max[c] - m->bbox_min[c]);
    return sqrt(d);
}

/* (u, v) of parameter t along patch edge e (from corner e to corner e+1). */
static void edge_uv(int e, double t, double *u, double *v)
{
    switch (e) {
    case 0:
        *u = t, *v = 0;
        break;
    case 1:
        *u = 1, *v = t;
        break;
    case 2:
        *u = 1 - t, *v = 1;
        break;
    default:
        *u = 0, *v = 1 - t;
        break;
    }
}

/* Whether the two boundary tangents at corner c (0..3) of a patch are
 * parallel: where fewer than three patches meet at a node (a vertex of
 * valence 2), each patch's corner is a straight angle and its normal there
 * is only a limit along the diagonal, which the construction does not make
 * match across the edge. Such corner points are left out of the G1 and
 * GPU-normal comparisons, and counted. */
static int corner_degenerate(const double *cp, int c)
{
    static const int at[4] = {0, 3, 15, 12}, nu[4] = {1, 2, 14, 13}, nv[4] = {4, 7, 11, 8};
    double a[3], b[3], x[3];
    for (int d = 0; d < 3; d++) {
        a[d] = cp[3 * nu[c] + d] - cp[3 * at[c] + d];
        b[d] = cp[3 * nv[c] + d] - cp[3 * at[c] + d];
    }
    x[0] = a[1] * b[2] - a[2] * b[1];
    x[1] = a[2] * b[0] - a[0] * b[2];
    x[2] = a[0] * b[1] - a[1] * b[0];
    double la = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]),
           lb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    return sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) <= 1e-6 * la * lb;
}

/* Corner index of (u, v) when it is a patch corner, else -1. */
static int corner_of(double u, double v)
{
    if (u == 0 && v == 0) return 0;
    if (u == 1 && v == 0) return 1;
    if (u == 1 && v == 1) return 2;
    if (u == 0 && v == 1) return 3;
    return -1;
}

static size_t g1_skipped;

/* Largest angle (degrees) between the normals of two patches at the same
 * point of a shared edge, over every pair of patch edges with the same
 * corner keys; also the largest position gap and the number of shared
 * edges. */
static double g1_max_angle(const vx_gpatch_set *s, double *max_gap, size_t *shared)
{
    double worst = 0;
    *max_gap = 0;
    *shared = 0;
    for (size_t a = 0; a < 4 * s->npatches; a++) {
        uint32_t a0 = s->corner_key[a], a1 = s->corner_key[4 * (a / 4) + (a % 4 + 1) % 4];
        for (size_t b = a + 1; b < 4 * s->npatches; b++) {
            if (b / 4 == a / 4) continue;
            uint32_t b0 = s->corner_key[b], b1 = s->corner_key[4 * (b / 4) + (b % 4 + 1) % 4];
            int same = a0 == b0 && a1 == b1, rev = a0 == b1 && a1 == b0;
            if (!same && !rev) continue;
            (*shared)++;
            for (int k = 0; k <= 32; k++) {
                double t = k / 32.0, ua, va, ub, vb, pa[3], pb[3], na[3], nb[3];
                edge_uv((int)(a % 4), t, &ua, &va);
                edge_uv((int)(b % 4), rev ? 1 - t : t, &ub, &vb);
                vx_gpatch_eval(s->cp + (a / 4) * 60, ua, va, pa, na);
                vx_gpatch_eval(s->cp + (b / 4) * 60, ub, vb, pb, nb);
                int ca = corner_of(ua, va), cb = corner_of(ub, vb);
                if ((ca >= 0 && corner_degenerate(s->cp + (a / 4) * 60, ca)) ||
                    (cb >= 0 && corner_degenerate(s->cp + (b / 4) * 60, cb))) {
                    g1_skipped++;
                    continue;
                }
                double d = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2];
                double ang = acos(d > 1 ? 1 : d < -1 ? -1 : d) * 180 / M_PI;
                if (ang > worst) worst = ang;
                if (ang > 1 && getenv("G1_DEBUG"))
                    fprintf(stderr,
                            "p%zu e%zu / p%zu e%zu t=%g: %g deg na=(%g %g %g) nb=(%g %g %g) keys "
                            "%u %u\n",
                            a / 4, a % 4, b / 4, b % 4, t, ang, na[0], na[1], na[2], nb[0], nb[1],
                            nb[2], a0, a1);
                double gap =
                    sqrt((pa[0] - pb[0]) * (pa[0] - pb[0]) + (pa[1] - pb[1]) * (pa[1] - pb[1]) +
                         (pa[2] - pb[2]) * (pa[2] - pb[2]));
                if (gap > *max_gap) *max_gap = gap;
            }
        }
    }
    return worst;
}

/* Largest angle between the two end normals of any patch edge: how curved
 * the surface is (so that a G1 result is not the trivial one of a plane). */
static double curvature_spread(const vx_gpatch_set *s)
{
    double worst = 0;
    for (size_t p = 0; p < s->npatches; p++) {
        double x[3], n0[3], n1[3];
        vx_gpatch_eval(s->cp + p * 60, 0, 0, x, n0);
        vx_gpatch_eval(s->cp + p * 60, 1, 1, x, n1);
        double d = n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2];
        double a = acos(d > 1 ? 1 : d < -1 ? -1 : d) * 180 / M_PI;
        if (a > worst) worst = a;
    }
    return worst;
}

static void check_g1(const vx_mesh *m, size_t want_patches)
{
    vx_gpatch_set *s = build(m, NULL);
    assert_int_equal(s->npatches, want_patches);
    double gap;
    size_t shared;
    g1_skipped = 0;
    double ang = g1_max_angle(s, &gap, &shared);
    fprintf(stderr,
            "  %zu patches, %zu shared edges: max normal angle %.3g deg, gap %.3g "
            "(%zu degenerate corner points left out)\n",
            s->npatches, shared, ang, gap, g1_skipped);
    assert_true(g1_skipped * 100 < shared * 33); /* rare: of 33 points per edge */
    assert_true(shared > 0);
    assert_true(ang <= 1e-3);
    assert_true(gap <= 1e-12 * diag(m));
    assert_true(curvature_spread(s) > 5); /* curved, not flat */
    /* The surface faces the way the input faces do (triangles are wound
     * along du x dv): the patch normal at its centre against its face's
     * Newell normal. */
    size_t along = 0;
    for (size_t p = 0; p < s->npatches; p++) {
        const uint32_t *fv = vx_mesh_face(m, s->face[p]);
        uint32_t k = vx_mesh_face_size(m, s->face[p]);
        double fn[3] = {0, 0, 0}, x[3], nn[3];
        for (uint32_t i = 0; i < k; i++) {
            const double *a = m->pos + 3 * fv[i], *b = m->pos + 3 * fv[(i + 1) % k];
            fn[0] += (a[1] - b[1]) * (a[2] + b[2]);
            fn[1] += (a[2] - b[2]) * (a[0] + b[0]);
            fn[2] += (a[0] - b[0]) * (a[1] + b[1]);
        }
        vx_gpatch_eval(s->cp + p * 60, 0.5, 0.5, x, nn);
        along += fn[0] * nn[0] + fn[1] * nn[1] + fn[2] * nn[2] > 0;
    }
    fprintf(stderr, "  %zu of %zu patch centres face along their face\n", along, s->npatches);
    /* Not all: where a control cage is crumpled (spot's: faces whose
     * normals point apart by more than 90 degrees around one vertex), the
     * interpolating surface folds inside some patches (about 4 % on spot). */
    assert_true(along * 100 >= s->npatches * 90);
    /* Every patch corner sits on its node: input vertices are interpolated. */
    for (size_t p = 0; p < s->npatches; p++)
        for (int c = 0; c < 4; c++)
            if (s->corner_key[4 * p + c] < m->nverts) {
                static const int slot[4] = {0, 3, 15, 12};
                const double *x = s->cp + p * 60 + 3 * slot[c],
                             *y = m->pos + 3 * s->corner_key[4 * p + c];
                assert_true(fabs(x[0] - y[0]) + fabs(x[1] - y[1]) + fabs(x[2] - y[2]) == 0);
            }
    vx_gpatch_set_free(s);
}

static size_t corners(const vx_mesh *m)
{
    size_t c = 0;
    for (size_t f = 0; f < m->nfaces; f++)
        c += vx_mesh_face_size(m, f);
    return c;
}

static void test_g1_spot(void **state)
{
    (void)state;
    vx_mesh *m = load("spot_control_mesh.obj");
    check_g1(m, m->faces_by_size[1] == m->nfaces ? m->nfaces : corners(m));
    vx_mesh_free(m);
}

static void test_g1_suzanne(void **state)
{
    (void)state;
    vx_mesh *m = load("suzanne.obj");
    assert_true(m->boundary_edges > 0 && m->faces_by_size[0] > 0);
    check_g1(m, corners(m));
    vx_mesh_free(m);
}

/* A flat disc of n triangles around one vertex (z = 0): the surface is the
 * disc itself, every patch in the plane and facing +z everywhere. The
 * curves from edge midpoints to face centres used to leave square to the
 * edge: in sectors under ~12 degrees (n >= 30) the two from the spokes
 * crossed, and every centre patch folded over (40 of 120 at n = 40). */
static void test_flat_fan(void **state)
{
    (void)state;
    const int ns[] = {6, 29, 30, 40, 100, 300, 1000};
    for (size_t k = 0; k < sizeof ns / sizeof ns[0]; k++) {
        int n = ns[k];
        double *p = malloc(3 * (size_t)(n + 1) * sizeof *p);
        uint32_t *f = malloc(3 * (size_t)n * sizeof *f), *sz = malloc((size_t)n * sizeof *sz);
        assert_true(p && f && sz);
        p[0] = p[1] = p[2] = 0;
        for (int i = 0; i < n; i++) {
            p[3 * (i + 1)] = cos(2 * M_PI * i / n);
            p[3 * (i + 1) + 1] = sin(2 * M_PI * i / n);
            p[3 * (i + 1) + 2] = 0;
            f[3 * i] = 0;
            f[3 * i + 1] = (uint32_t)(1 + i);
            f[3 * i + 2] = (uint32_t)(1 + (i + 1) % n);
            sz[i] = 3;
        }
        vx_mesh *m = shape_poly_mesh((size_t)n + 1, p, (size_t)n, sz, f);
        assert_non_null(m);
        vx_gpatch_set *s = build(m, NULL);
        size_t folded = vx_gpatch_folded(s, m), flipped = 0;
        for (size_t q = 0; q < s->npatches; q++) {
            const double *cp = s->cp + q * VX_GPATCH_POINTS * 3;
            for (int i = 0; i < VX_GPATCH_POINTS; i++)
                assert_true(cp[3 * i + 2] == 0);
            for (int a = 0; a <= 4; a++)
                for (int b = 0; b <= 4; b++) {
                    double x[3], nrm[3];
                    vx_gpatch_eval(cp, 0.05 + 0.225 * a, 0.05 + 0.225 * b, x, nrm);
                    flipped += !(nrm[2] > 0);
                }
        }
        print_message("flat fan of %d: %zu of %zu patches folded, %zu of %zu samples facing -z\n",
                      n, folded, s->npatches, flipped, 25 * s->npatches);
        assert_int_equal(folded, 0);
        assert_int_equal(flipped, 0);
        vx_gpatch_set_free(s);
        vx_mesh_free(m);
        free(p);
        free(f);
        free(sz);
    }
}

/* A face alone (every corner on one face only): the corners are corners.
 * A lone flat quad bulged 0.18 past its edges, and at two of its corners
 * (which two, by the vertex its face starts at) the patches folded, their
 * normals facing -z: the open fan's angle, spread to pi, made the corner
 * flat. Every start, a triangle and a pentagon too: flat, +z, inside. */
static void test_lone_faces(void **state)
{
    (void)state;
    static const double quad[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0},
                        tri[] = {0, 0, 0, 2, 0, 0, 0.5, 1, 0},
                        pent[] = {0, 0, 0, 1, 0, 0, 1.3, 0.8, 0, 0.5, 1.4, 0, -0.3, 0.8, 0};
    const struct {
        const double *p;
        uint32_t n;
    } faces[] = {{quad, 4}, {tri, 3}, {pent, 5}};
    for (size_t k = 0; k < sizeof faces / sizeof faces[0]; k++)
        for (uint32_t start = 0; start < faces[k].n; start++) {
            uint32_t n = faces[k].n, f[5], sz = n;
            double lo[2] = {1e9, 1e9}, hi[2] = {-1e9, -1e9};
            for (uint32_t i = 0; i < n; i++) {
                f[i] = (start + i) % n;
                for (int c = 0; c < 2; c++) {
                    lo[c] = fmin(lo[c], faces[k].p[3 * i + c]);
                    hi[c] = fmax(hi[c], faces[k].p[3 * i + c]);
                }
            }
            vx_mesh *m = shape_poly_mesh(n, faces[k].p, 1, &sz, f);
            assert_non_null(m);
            vx_gpatch_set *s = build(m, NULL);
            size_t flipped = 0, outside = 0;
            for (size_t q = 0; q < s->npatches; q++) {
                const double *cp = s->cp + q * VX_GPATCH_POINTS * 3;
                for (int a = 0; a <= 8; a++)
                    for (int b = 0; b <= 8; b++) {
                        double x[3], nrm[3];
                        vx_gpatch_eval(cp, 0.02 + 0.12 * a, 0.02 + 0.12 * b, x, nrm);
                        flipped += !(nrm[2] > 0) || x[2] != 0;
                        outside += x[0] < lo[0] - 1e-9 || x[0] > hi[0] + 1e-9 ||
                                   x[1] < lo[1] - 1e-9 || x[1] > hi[1] + 1e-9;
                    }
            }
            print_message("lone %u-gon from vertex %u: %zu samples off +z, %zu outside its box\n",
                          n, start, flipped, outside);
            assert_int_equal(flipped, 0);
            assert_int_equal(outside, 0);
            vx_gpatch_set_free(s);
            vx_mesh_free(m);
        }
}

static void test_g1_ngon(void **state)
{
    (void)state;
    vx_mesh *m = ngon_mesh();
    check_g1(m, 32);
    vx_mesh_free(m);
}

/* An all-quad mesh keeps one patch per face: a cube's six faces. */
static void test_g1_quads(void **state)
{
    (void)state;
    vx_mesh *m = vx_mesh_new();
    m->nverts = 8;
    m->pos = malloc(24 * sizeof *m->pos);
    for (int i = 0; i < 8; i++) {
        m->pos[3 * i] = (i & 1) ? 1 : -1;
        m->pos[3 * i + 1] = (i & 2) ? 1 : -1;
        m->pos[3 * i + 2] = (i & 4) ? 1.5 : -1;
    }
    static const uint32_t idx[] = {0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4,
                                   2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5};
    static const uint32_t start[] = {0, 4, 8, 12, 16, 20, 24};
    m->nfaces = 6;
    m->face_idx = malloc(sizeof idx);
    m->face_start = malloc(sizeof start);
    memcpy(m->face_idx, idx, sizeof idx);
    memcpy(m->face_start, start, sizeof start);
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    check_g1(m, 6);
    /* Quad mode: nodes are the vertices, patch edges the mesh edges. */
    vx_gpatch_set *s = build(m, NULL);
    for (int n = 1; n <= 6; n += 5) {
        uint32_t *nd = vx_gregory_divisions(s, n, 0, &err);
        vx_gtess_layout *w = vx_gregory_layout_new(s, nd, 1, &err);
        assert_int_equal(w->nverts, 8 + 12 * (n - 1) + 6 * (n - 1) * (n - 1));
        assert_int_equal(w->ntris, 12 * n * n);
        vx_gregory_layout_free(w);
        free(nd);
    }
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

static int u64_cmp(const void *x, const void *y)
{
    uint64_t a = *(const uint64_t *)x, b = *(const uint64_t *)y;
    return a < b ? -1 : a > b;
}

/* An open mesh of quads only (one patch per face, boundary fans): a bumpy
 * 4 x 3 sheet. */
static void test_g1_open_quads(void **state)
{
    (void)state;
    vx_mesh *m = vx_mesh_new();
    m->nverts = 20;
    m->pos = malloc(60 * sizeof *m->pos);
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 5; i++) {
            double *p = m->pos + 3 * (5 * j + i);
            p[0] = i + 0.1 * j;
            p[1] = j;
            p[2] = 0.4 * sin(1.3 * i) * cos(0.9 * j);
        }
    m->nfaces = 12;
    m->face_start = malloc(13 * sizeof *m->face_start);
    m->face_idx = malloc(48 * sizeof *m->face_idx);
    for (uint32_t f = 0; f < 12; f++) {
        uint32_t i = f % 4, j = f / 4, a = 5 * j + i;
        uint32_t q[4] = {a, a + 1, a + 6, a + 5};
        memcpy(m->face_idx + 4 * f, q, sizeof q);
        m->face_start[f] = 4 * f;
    }
    m->face_start[12] = 48;
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    assert_int_equal(m->boundary_edges, 14);
    check_g1(m, 12);
    /* Boundary curves run smoothly through boundary vertices: the two
     * boundary patch edges meeting at a boundary vertex have opposite
     * tangents there (vertex 2 on the j = 0 side: patches 1 and 2). */
    vx_gpatch_set *s = build(m, NULL);
    const double *c1 = s->cp + 60 * 1, *c2 = s->cp + 60 * 2;
    double t1[3], t2[3];
    for (int c = 0; c < 3; c++) {
        t1[c] = c1[3 * 2 + c] - c1[3 * 3 + c]; /* patch 1, v = 0 row, towards its corner 1 */
        t2[c] = c2[3 * 1 + c] - c2[3 * 0 + c]; /* patch 2, from its corner 0 */
    }
    double d = t1[0] * t2[0] + t1[1] * t2[1] + t1[2] * t2[2];
    double l1 = sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2]);
    double l2 = sqrt(t2[0] * t2[0] + t2[1] * t2[1] + t2[2] * t2[2]);
    assert_true(d / (l1 * l2) < -1 + 1e-12);
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

/* Edges of a triangle list used by exactly one triangle. */
static size_t boundary_edges(const uint32_t *tri, size_t ntris, size_t nverts)
{
    size_t n = 3 * ntris, once = 0;
    uint64_t *k = malloc(n * sizeof *k);
    for (size_t t = 0; t < ntris; t++)
        for (int e = 0; e < 3; e++) {
            uint64_t a = tri[3 * t + e], b = tri[3 * t + (e + 1) % 3];
            k[3 * t + e] = a < b ? a * nverts + b : b * nverts + a;
        }
    qsort(k, n, sizeof *k, u64_cmp);
    for (size_t i = 0; i < n;) {
        size_t j = i;
        while (j < n && k[j] == k[i])
            j++;
        once += j - i == 1;
        i = j;
    }
    free(k);
    return once;
}

static void test_counts_and_weld(void **state)
{
    (void)state;
    vx_mesh *m = load("spot_control_mesh.obj");
    assert_int_equal(m->boundary_edges, 0);
    vx_gpatch_set *s = build(m, NULL);
    size_t C = corners(m), E = C / 2, F = m->nfaces, V = m->nverts;
    vx_err err = {0};
    for (int n = 1; n <= 9; n += 4) {
        uint32_t *nd = vx_gregory_divisions(s, n, 0, &err);
        vx_gtess_layout *w = vx_gregory_layout_new(s, nd, 1, &err);
        vx_gtess_layout *u = vx_gregory_layout_new(s, nd, 0, &err);
        assert_non_null(w);
        assert_non_null(u);
        /* Nodes: vertices, edge midpoints, face centres; 2C patch edges. */
        size_t want = V + E + F + 2 * C * (size_t)(n - 1) + C * (size_t)(n - 1) * (n - 1);
        assert_int_equal(w->nverts, want);
        assert_int_equal(w->ntris, 2 * C * (size_t)n * n);
        assert_int_equal(u->nverts, C * (size_t)(n + 1) * (n + 1));
        assert_int_equal(u->ntris, w->ntris);
        assert_int_equal(boundary_edges(w->tri, w->ntris, w->nverts), 0);
        /* Genus 0: V - E + F = 2 with E = 3T/2. */
        assert_int_equal((long)w->nverts - (long)(3 * w->ntris / 2) + (long)w->ntris, 2);
        /* Unwelded: every patch is open on its own. */
        assert_int_equal(boundary_edges(u->tri, u->ntris, u->nverts), C * 4 * (size_t)n);
        vx_gregory_layout_free(w);
        vx_gregory_layout_free(u);
        free(nd);
    }
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

/* The interpolate construction and the patch normals do not depend on
 * where the mesh is: the twisted prism moved 1e12 away has the same
 * patches up to that shift and the same normals (to its coordinates'
 * rounding), and none folded, nor at 1e15.
 * Newell's face normals summed positions (p + q, 2e15 for a unit face:
 * vertex normals off by degrees), and vx_gpatch_eval took tangents under
 * 1e-12 of the coordinates for noise (a unit patch at 1e12: the normal
 * (0, 0, 1), so folded_patches counted every face looking down). */
static void test_far_from_origin(void **state)
{
    (void)state;
    vx_mesh *m = ngon_mesh();
    vx_gpatch_set *s = build(m, NULL);
    assert_int_equal(vx_gpatch_folded(s, m), 0);
    const double shifts[] = {1e12, 1e15};
    for (int k = 0; k < 2; k++) {
        vx_mesh *f = ngon_mesh();
        for (size_t i = 0; i < 3 * f->nverts; i++)
            f->pos[i] += shifts[k];
        vx_err err = {0};
        assert_int_equal(vx_mesh_analyze(f, &err), 0);
        vx_gpatch_set *t = build(f, NULL);
        assert_int_equal(t->npatches, s->npatches);
        size_t folded = vx_gpatch_folded(t, f);
        double worst = 0, moved = 0;
        for (size_t p = 0; p < s->npatches; p++) {
            const double *a = s->cp + p * VX_GPATCH_POINTS * 3,
                         *b = t->cp + p * VX_GPATCH_POINTS * 3;
            for (int q = 0; q < 3 * VX_GPATCH_POINTS; q++)
                moved = fmax(moved, fabs(b[q] - shifts[k] - a[q]));
            for (int iu = 0; iu <= 4; iu++)
                for (int iv = 0; iv <= 4; iv++) {
                    double pa[3], na[3], pb[3], nb[3];
                    vx_gpatch_eval(a, iu / 4.0, iv / 4.0, pa, na);
                    vx_gpatch_eval(b, iu / 4.0, iv / 4.0, pb, nb);
                    double d = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2];
                    worst = fmax(worst, acos(fmin(1, d)) * 180 / M_PI);
                }
        }
        printf("  shifted %g: control points within %.3g, normals within %.3g deg, %zu folded\n",
               shifts[k], moved, worst, folded);
        assert_int_equal(folded, 0);
        /* The coordinates themselves round, by 1e-4 at 1e12 (normals
         * within 0.06 deg) and 0.125 at 1e15, 6% of the prism: only its
         * patches' orientation (none folded) is kept there. */
        assert_true(moved < (k ? 1.0 : 1e-3));
        if (k == 0) assert_true(worst < 0.5);
        vx_gpatch_set_free(t);
        vx_mesh_free(f);
    }
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

/* Grid vertices of the tessellator's engine against vx_gpatch_eval. */
static void check_engine(const vx_gpatch_set *s, const uint32_t *nd, double dg, double ptol,
                         double ntol_deg, size_t stride, vx_gtess_engine engine)
{
    vx_err err = {0};
    vx_gtess_layout *l = vx_gregory_layout_new(s, nd, 0, &err);
    assert_non_null(l);
    float *grid = malloc(6 * l->voff[s->npatches] * sizeof *grid);
    double origin[3] = {0.25, -0.5, 0.125}, ms = 0;
    vx_gtess *t = vx_gtess_new_on(vx_test_gl, l, engine, &err);
    assert_non_null(t);
    assert_string_equal(vx_gtess_engine_name(t), engine == VX_GTESS_CPU ? "cpu" : "gpu");
    assert_int_equal(vx_gtess_run(t, s, origin, grid, &ms, &err), 0);
    vx_gtess_free(t);
    if (engine == VX_GTESS_CPU) {
        /* the 4-lane kernel (x86-64's baseline) against the widest one
         * the CPU has (here AVX2 with FMA, 8 lanes, where it has them) */
        uint64_t ng = l->voff[s->npatches];
        float *g4 = malloc(6 * ng * sizeof *g4);
        double ms4;
        assert_int_equal(vx_gtess_cpu_run(l, s, origin, g4, 4, &ms4, &err), 0);
        /* the same formulas, rounded differently (fused multiply-adds in
         * the wider one): positions and normal angles within the bounds
         * against the double evaluator */
        double worst = 0, worst_a = 0;
        for (uint64_t v = 0; v < ng; v++) {
            double dp = 0, dn = 0;
            for (int c = 0; c < 3; c++) {
                dp += pow(g4[6 * v + c] - grid[6 * v + c], 2);
                dn += pow(g4[6 * v + 3 + c] - grid[6 * v + 3 + c], 2);
            }
            worst = fmax(worst, sqrt(dp) / dg);
            worst_a = fmax(worst_a, 2 * asin(fmin(1, sqrt(dn) / 2)) * 180 / M_PI);
        }
        fprintf(
            stderr,
            "  cpu 4 lanes vs widest: position %.3g, normal %.3g deg (%.2f ms against %.2f ms)\n",
            worst, worst_a, ms4, ms);
        assert_true(worst <= ptol);
        assert_true(worst_a <= ntol_deg);
        free(g4);
    }
    double worst_p = 0, worst_n = 0;
    size_t seen = 0;
    for (size_t p = 0; p < s->npatches; p++) {
        uint32_t n = nd[p];
        for (uint32_t j = 0; j <= n; j++)
            for (uint32_t i = 0; i <= n; i++) {
                /* every stride-th vertex, and every patch's first and last */
                if (seen++ % stride && !(i == 0 && j == 0) && !(i == n && j == n)) continue;
                const float *g = grid + 6 * (l->voff[p] + j * (n + 1) + i);
                int cn = corner_of((double)i / n, (double)j / n);
                int skip_n = cn >= 0 && corner_degenerate(s->cp + p * 60, cn);
                double x[3], nn[3];
                vx_gpatch_eval(s->cp + p * 60, (double)i / n, (double)j / n, x, nn);
                double dp = 0, d = 0;
                for (int c = 0; c < 3; c++) {
                    dp += (g[c] + origin[c] - x[c]) * (g[c] + origin[c] - x[c]);
                    d += (g[3 + c] - nn[c]) * (g[3 + c] - nn[c]);
                }
                dp = sqrt(dp) / dg;
                /* the angle from the chord between the unit normals (acos
                 * of a dot product near 1 loses half the digits) */
                double a = 2 * asin(fmin(1, sqrt(d) / 2)) * 180 / M_PI;
                if (dp > worst_p) worst_p = dp;
                if (a > worst_n && !skip_n) worst_n = a;
                if (a > 0.01 && getenv("G1_DEBUG"))
                    fprintf(stderr, "p%zu (%u,%u)/%u: %g deg gpu (%g %g %g) cpu (%g %g %g)\n", p, i,
                            j, n, a, g[3], g[4], g[5], nn[0], nn[1], nn[2]);
            }
    }
    fprintf(stderr,
            "  %s float vs double CPU: position %.3g of the diagonal, normal %.3g deg (%.2f ms)\n",
            engine == VX_GTESS_CPU ? "cpu" : "gpu", worst_p, worst_n, ms);
    assert_true(worst_p <= ptol);
    assert_true(worst_n <= ntol_deg);
    free(grid);
    vx_gregory_layout_free(l);
}

/* GPU against CPU on shared mesh NAME at n divisions per patch (n = 0:
 * max_edge = bbox diagonal / edge_div), every stride-th grid vertex; the
 * smallest and largest N and the grid vertex count for the caller. */
static void gpu_vs_cpu(const char *name, int n, double edge_div, size_t stride, uint32_t *lo,
                       uint32_t *hi, uint64_t *grid_verts)
{
    vx_mesh *m = load(name);
    vx_gpatch_set *s = build(m, NULL);
    vx_err err = {0};
    uint32_t *nd = vx_gregory_divisions(s, n, n ? 0 : diag(m) / edge_div, &err);
    assert_non_null(nd);
    *lo = UINT32_MAX;
    *hi = 0;
    for (size_t p = 0; p < s->npatches; p++) {
        if (nd[p] < *lo) *lo = nd[p];
        if (nd[p] > *hi) *hi = nd[p];
    }
    uint64_t nv, nt;
    assert_int_equal(vx_gregory_count(s, nd, grid_verts, &nv, &nt, &err), 0);
    /* the GPU pass and the CPU engine (the shader's formulas in float) */
    check_engine(s, nd, diag(m), 1e-5, 0.01, stride, VX_GTESS_GPU);
    check_engine(s, nd, diag(m), 1e-5, 0.01, stride, VX_GTESS_CPU);
    free(nd);
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

/* Divisions that differ between patches (max_edge on suzanne's parts):
 * the shader finds each row's patch by search instead of by division. */
static void test_gpu_mixed_divisions(void **state)
{
    (void)state;
    uint32_t lo, hi;
    uint64_t gv;
    gpu_vs_cpu("suzanne.obj", 0, 40, 1, &lo, &hi, &gv);
    assert_true(hi > lo);
}

/* Over 128 MiB of output: several chunks, each its own buffers; sampled
 * vertices of every chunk against the CPU. */
static void test_gpu_chunks(void **state)
{
    (void)state;
    uint32_t lo, hi;
    uint64_t gv;
    gpu_vs_cpu("spot_control_mesh.obj", 128, 0, 997, &lo, &hi, &gv);
    assert_true(gv * 24 > 2 * (128u << 20)); /* at least three chunks */
}

static void test_gpu_matches_cpu(void **state)
{
    (void)state;
    uint32_t lo, hi;
    uint64_t gv;
    gpu_vs_cpu("spot_control_mesh.obj", 7, 0, 1, &lo, &hi, &gv);
    assert_true(lo == 7 && hi == 7);
}

/* Frame k through the reused topology equals a fresh build on its positions. */
static void test_frames_reuse_topology(void **state)
{
    (void)state;
    vx_mesh *m = load("suzanne.obj");
    vx_gregory_topo *t;
    vx_gpatch_set *s0 = build(m, &t);
    double *moved = malloc(3 * m->nverts * sizeof *moved);
    for (size_t v = 0; v < m->nverts; v++) {
        const double *p = m->pos + 3 * v;
        moved[3 * v] = p[0] + 0.2 * sin(3 * p[1]);
        moved[3 * v + 1] = p[1] * 1.1;
        moved[3 * v + 2] = p[2] + 0.1 * p[0] * p[0];
    }
    vx_gpatch_set *s1 = vx_gpatch_set_new(s0->npatches);
    vx_gregory_build(t, moved, s1);
    vx_mesh *m2 = load("suzanne.obj");
    memcpy(m2->pos, moved, 3 * m->nverts * sizeof *moved);
    vx_gpatch_set *fresh = build(m2, NULL);
    assert_int_equal(fresh->npatches, s1->npatches);
    assert_memory_equal(fresh->cp, s1->cp, s1->npatches * 60 * sizeof(double));
    assert_memory_equal(fresh->corner_key, s1->corner_key, 4 * s1->npatches * sizeof(uint32_t));
    assert_memory_not_equal(s0->cp, s1->cp, s1->npatches * 60 * sizeof(double));
    /* The frame is G1 too. */
    double gap;
    size_t shared;
    assert_true(g1_max_angle(s1, &gap, &shared) <= 1e-3);
    vx_gpatch_set_free(s0);
    vx_gpatch_set_free(s1);
    vx_gpatch_set_free(fresh);
    vx_gregory_topo_free(t);
    free(moved);
    vx_mesh_free(m);
    vx_mesh_free(m2);
}

static void test_teapot_bezier(void **state)
{
    (void)state;
    vx_mesh *m = load("newell-teapot.bpt");
    assert_int_equal(m->npatches, 32);
    vx_err err = {0};
    vx_gpatch_set *s = vx_gregory_from_bezier(m, NULL, &err);
    assert_non_null(s);
    const uint32_t n = 16;
    uint32_t *nd = vx_gregory_divisions(s, (int)n, 0, &err);
    vx_gtess_layout *l = vx_gregory_layout_new(s, nd, 0, &err);
    float *grid = malloc(6 * l->voff[s->npatches] * sizeof *grid);
    double origin[3], ms, dg = diag(m), worst_gpu = 0, worst_cpu = 0, worst_n = 0;
    for (int c = 0; c < 3; c++)
        origin[c] = 0.5 * (m->bbox_min[c] + m->bbox_max[c]);
    assert_int_equal(vx_gregory_tessellate(vx_test_gl, s, l, origin, grid, &ms, &err), 0);
    for (size_t p = 0; p < s->npatches; p++)
        for (uint32_t j = 0; j <= n; j++)
            for (uint32_t i = 0; i <= n; i++) {
                double b[3], x[3];
                shape_bezier_eval(m, p, (double)i / n, (double)j / n, b);
                double nn[3], dn = 0;
                vx_gpatch_eval(s->cp + p * 60, (double)i / n, (double)j / n, x, nn);
                const float *g = grid + 6 * (l->voff[p] + j * (n + 1) + i);
                for (int c = 0; c < 3; c++)
                    dn += (g[3 + c] - nn[c]) * (g[3 + c] - nn[c]);
                double ang = 2 * asin(fmin(1, sqrt(dn) / 2)) * 180 / M_PI;
                if (ang > worst_n) worst_n = ang;
                if (ang > 0.1 && getenv("G1_DEBUG"))
                    fprintf(stderr, "tp p%zu (%u,%u): %g deg gpu (%g %g %g) cpu (%g %g %g)\n", p, i,
                            j, ang, g[3], g[4], g[5], nn[0], nn[1], nn[2]);
                double dg2 = 0, dc2 = 0;
                for (int c = 0; c < 3; c++) {
                    dg2 += (g[c] + origin[c] - b[c]) * (g[c] + origin[c] - b[c]);
                    dc2 += (x[c] - b[c]) * (x[c] - b[c]);
                }
                if (sqrt(dg2) / dg > worst_gpu) worst_gpu = sqrt(dg2) / dg;
                if (sqrt(dc2) / dg > worst_cpu) worst_cpu = sqrt(dc2) / dg;
            }
    fprintf(stderr,
            "  teapot: GPU %.3g, CPU %.3g of the diagonal from the Bezier patches; normals "
            "GPU vs CPU %.3g deg (the poles' collapsed edges included)\n",
            worst_gpu, worst_cpu, worst_n);
    assert_true(worst_gpu <= 1e-6);
    assert_true(worst_n <= 0.01);
    assert_true(worst_cpu <= 1e-12);
    /* Welded through the merged corner points: fewer vertices than the
     * patches have on their own, and every triangle still there except
     * those collapsed onto the lid's and bottom's poles. */
    vx_gtess_layout *w = vx_gregory_layout_new(s, nd, 1, &err);
    assert_non_null(w);
    assert_true(w->nverts < l->nverts);
    assert_true(w->ntris < l->ntris && w->ntris > l->ntris * 9 / 10);
    vx_gregory_layout_free(w);
    free(grid);
    free(nd);
    vx_gregory_layout_free(l);
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

/* A hand-made Bézier mesh: the interior pairs are equal and the corner
 * keys merge equal points. */
static void test_from_bezier_small(void **state)
{
    (void)state;
    vx_mesh *m = vx_mesh_new();
    m->nverts = 32;
    m->pos = calloc(3 * 32, sizeof *m->pos);
    m->npatches = 2;
    m->patch_idx = malloc(32 * sizeof *m->patch_idx);
    for (int p = 0; p < 2; p++)
        for (int j = 0; j < 4; j++)
            for (int i = 0; i < 4; i++) {
                int k = 16 * p + 4 * j + i;
                m->patch_idx[k] = (uint32_t)k;
                m->pos[3 * k] = i / 3.0 + p; /* patch 1's i = 0 column is patch 0's i = 3 */
                m->pos[3 * k + 1] = j / 3.0;
                m->pos[3 * k + 2] = 0.1 * ((i * 7 + j * 3) % 5);
            }
    for (int j = 0; j < 4; j++) /* make the shared column bitwise equal */
        memcpy(m->pos + 3 * (16 + 4 * j), m->pos + 3 * (4 * j + 3), 3 * sizeof(double));
    vx_err err = {0};
    vx_gpatch_set *s = vx_gregory_from_bezier(m, NULL, &err);
    assert_non_null(s);
    static const int pairs[4][2] = {{5, 16}, {6, 17}, {9, 18}, {10, 19}};
    for (int p = 0; p < 2; p++)
        for (int k = 0; k < 4; k++)
            assert_memory_equal(s->cp + 60 * p + 3 * pairs[k][0], s->cp + 60 * p + 3 * pairs[k][1],
                                3 * sizeof(double));
    assert_int_equal(s->corner_key[4 + 0], s->corner_key[1]); /* p1 (0,0) = p0 (1,0) */
    assert_int_equal(s->corner_key[4 + 3], s->corner_key[2]); /* p1 (0,1) = p0 (1,1) */
    assert_int_not_equal(s->corner_key[0], s->corner_key[1]);
    uint32_t nd[2] = {4, 4};
    vx_gtess_layout *w = vx_gregory_layout_new(s, nd, 1, &err);
    assert_int_equal(w->nverts, 2 * 25 - 5);
    vx_gregory_layout_free(w);
    vx_gpatch_set_free(s);
    /* No patches: refused. */
    m->npatches = 0;
    assert_null(vx_gregory_from_bezier(m, NULL, &err));
    m->npatches = 2;
    vx_mesh_free(m);
}

/* An open strip of five quads of very different widths (one patch each),
 * bent out of the plane: max_edge gives neighbours different divisions. */
static vx_mesh *strip_mesh(void)
{
    static const double x[6] = {0, 0.2, 1.2, 4.2, 4.7, 6.7};
    vx_mesh *m = vx_mesh_new();
    assert_non_null(m);
    m->nverts = 12;
    m->pos = malloc(36 * sizeof *m->pos);
    for (int k = 0; k < 6; k++)
        for (int top = 0; top < 2; top++) {
            double *p = m->pos + 3 * (2 * k + top);
            p[0] = x[k];
            p[1] = top;
            p[2] = 0.3 * sin(x[k]) + 0.2 * top * x[k] / 6.7;
        }
    m->nfaces = 5;
    m->face_start = malloc(6 * sizeof *m->face_start);
    m->face_idx = malloc(20 * sizeof *m->face_idx);
    for (uint32_t f = 0; f < 5; f++) {
        uint32_t q[4] = {2 * f, 2 * f + 2, 2 * f + 3, 2 * f + 1};
        memcpy(m->face_idx + 4 * f, q, sizeof q);
        m->face_start[f] = 4 * f;
    }
    m->face_start[5] = 20;
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    return m;
}

typedef struct kedge {
    uint64_t k; /* corner keys lo << 32 | hi */
    uint32_t pe;
} kedge;

static int kedge_cmp(const void *x, const void *y)
{
    const kedge *a = x, *b = y;
    return (a->k > b->k) - (a->k < b->k);
}

static uint64_t edge_key(const vx_gpatch_set *s, size_t q)
{
    uint64_t a = s->corner_key[q], b = s->corner_key[4 * (q / 4) + (q % 4 + 1) % 4];
    return a < b ? a << 32 | b : b << 32 | a;
}

/* Patch edges sorted by their corner keys. */
static kedge *kedges(const vx_gpatch_set *s)
{
    kedge *e = malloc(4 * s->npatches * sizeof *e);
    for (size_t q = 0; q < 4 * s->npatches; q++)
        e[q] = (kedge){edge_key(s, q), (uint32_t)q};
    qsort(e, 4 * s->npatches, sizeof *e, kedge_cmp);
    return e;
}

/* The patch and grid (i, j) of grid vertex g. */
static size_t grid_at(const vx_gtess_layout *l, uint64_t g, uint32_t *i, uint32_t *j)
{
    size_t lo = 0, hi = l->npatches; /* last p with voff[p] <= g */
    while (hi - lo > 1) {
        size_t mid = (lo + hi) / 2;
        if (l->voff[mid] <= g)
            lo = mid;
        else
            hi = mid;
    }
    uint32_t w = l->ndiv[lo] + 1;
    *i = (uint32_t)((g - l->voff[lo]) % w);
    *j = (uint32_t)((g - l->voff[lo]) / w);
    return lo;
}

static int u64_has(const uint64_t *a, size_t n, uint64_t x)
{
    return bsearch(&x, a, n, sizeof x, u64_cmp) != NULL;
}

/* (u, v) in patch p of output vertex v, which lies in p's grid or, where
 * another patch's grid gives it, on a corner or edge p shares with that
 * patch (matched by corner keys; no collapsed edges). */
static void uv_in(const vx_gpatch_set *s, const vx_gtess_layout *l, size_t p, uint32_t v,
                  double uv[2])
{
    uint32_t i, j;
    size_t r = grid_at(l, l->rep[v], &i, &j);
    uint32_t n = l->ndiv[r];
    uv[0] = (double)i / n, uv[1] = (double)j / n;
    if (r == p) return;
    const uint32_t *kr = s->corner_key + 4 * r, *kp = s->corner_key + 4 * p;
    int ci = i == 0 || i == n, cj = j == 0 || j == n;
    if (ci && cj) { /* a corner: p's corner of the same key */
        int c = i == 0 ? (j == 0 ? 0 : 3) : (j == 0 ? 1 : 2);
        for (int d = 0; d < 4; d++)
            if (kp[d] == kr[c]) {
                uv[0] = d == 1 || d == 2, uv[1] = d >= 2;
                return;
            }
        fail_msg("vertex %u: corner not in patch %zu", v, p);
    }
    int er = j == 0 ? 0 : i == n ? 1 : j == n ? 2 : 3;
    uint32_t t = er == 0 ? i : er == 1 ? j : er == 2 ? n - i : n - j;
    for (int d = 0; d < 4; d++) {
        uint32_t a = kp[d], b = kp[(d + 1) % 4];
        if (a == kr[er] && b == kr[(er + 1) % 4]) return edge_uv(d, (double)t / n, uv, uv + 1);
        if (b == kr[er] && a == kr[(er + 1) % 4]) return edge_uv(d, 1 - (double)t / n, uv, uv + 1);
    }
    fail_msg("vertex %u: edge not in patch %zu", v, p);
}

/* Triangles of layout l counter-clockwise in their patch's (u, v) domain,
 * where the surface normal is du x dv; the smallest doubled area there. */
static double min_uv_area(const vx_gpatch_set *s, const vx_gtess_layout *l)
{
    double worst = INFINITY;
    for (size_t t = 0; t < l->ntris; t++) {
        double a[2], b[2], c[2];
        size_t p = l->tri_patch[t];
        uv_in(s, l, p, l->tri[3 * t], a);
        uv_in(s, l, p, l->tri[3 * t + 1], b);
        uv_in(s, l, p, l->tri[3 * t + 2], c);
        double x = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if (x < worst) worst = x;
    }
    return worst;
}

/* CPU positions and normals of a layout's output vertices, at their grid
 * points. */
static void cpu_eval(const vx_gpatch_set *s, const vx_gtess_layout *l, double *pos, double *nrm)
{
    for (size_t v = 0; v < l->nverts; v++) {
        uint32_t i, j;
        size_t p = grid_at(l, l->rep[v], &i, &j);
        vx_gpatch_eval(s->cp + p * 60, (double)i / l->ndiv[p], (double)j / l->ndiv[p], pos + 3 * v,
                       nrm + 3 * v);
    }
}

/* Triangles with a vertex normal on their back (marked per patch in back),
 * the smallest doubled area (of dg^2) and the smallest cosine between a
 * triangle's normal and its vertex normals. */
static size_t facing(const vx_gtess_layout *l, const double *pos, const double *nrm, double dg,
                     double *min_area, double *min_dot, uint8_t *back)
{
    size_t n = 0;
    *min_area = *min_dot = INFINITY;
    for (size_t t = 0; t < l->ntris; t++) {
        const double *a = pos + 3 * l->tri[3 * t], *b = pos + 3 * l->tri[3 * t + 1],
                     *c = pos + 3 * l->tri[3 * t + 2];
        double x[3], y[3], z[3];
        for (int d = 0; d < 3; d++)
            x[d] = b[d] - a[d], y[d] = c[d] - a[d];
        z[0] = x[1] * y[2] - x[2] * y[1];
        z[1] = x[2] * y[0] - x[0] * y[2];
        z[2] = x[0] * y[1] - x[1] * y[0];
        double len = sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2]), worst = INFINITY;
        if (len / (dg * dg) < *min_area) *min_area = len / (dg * dg);
        for (int k = 0; k < 3; k++) {
            const double *nn = nrm + 3 * l->tri[3 * t + k];
            double dot = (z[0] * nn[0] + z[1] * nn[1] + z[2] * nn[2]) / len;
            if (dot < worst) worst = dot;
        }
        if (worst < *min_dot) *min_dot = worst;
        if (!(worst > 0)) {
            n++;
            back[l->tri_patch[t]] = 1;
        }
    }
    return n;
}

/* max_edge with per-patch divisions on a mesh with no collapsed edges:
 * neighbours differ, the welded output is closed wherever the input is (its
 * only open edges are the segments of unshared patch edges), every vertex
 * on a shared patch edge is used by all the patches on it (no T-junction),
 * no triangle is degenerate (CPU evaluation at each output vertex's grid
 * point) and all are counter-clockwise in their patch's domain, welded and
 * unwelded. Facing against the vertex normals in space is only reported:
 * where a patch folds (a few of suzanne's and spot's, the strip's ends) the
 * uniform grid has the same backfacing triangles. */
static void check_transitions(const vx_mesh *m, double max_edge, const char *what)
{
    vx_gpatch_set *s = build(m, NULL);
    vx_err err = {0};
    uint32_t *nd = vx_gregory_divisions(s, 0, max_edge, &err);
    assert_non_null(nd);
    size_t np = s->npatches, nshared = 0, ndiffer = 0, open = 0, ntrans = 0;
    uint8_t *trans = calloc(np, 1);
    kedge *e = kedges(s);
    for (size_t q = 0; q < 4 * np;) {
        size_t r = q;
        while (r < 4 * np && e[r].k == e[q].k)
            r++;
        if (r - q == 1) open += nd[e[q].pe / 4];
        for (size_t k = q + 1; k < r; k++) {
            nshared++;
            ndiffer += nd[e[k].pe / 4] != nd[e[q].pe / 4];
        }
        for (size_t k = q; k < r; k++)
            for (size_t k2 = q; k2 < r; k2++)
                if (nd[e[k2].pe / 4] > nd[e[k].pe / 4]) trans[e[k].pe / 4] = 1;
        q = r;
    }
    for (size_t p = 0; p < np; p++)
        assert_true(nd[p] >= 2 || ndiffer == 0);
    assert_true(ndiffer > 0); /* neighbours with different divisions */
    vx_gtess_layout *w = vx_gregory_layout_new(s, nd, 1, &err);
    vx_gtess_layout *u = vx_gregory_layout_new(s, nd, 0, &err);
    assert_non_null(w);
    assert_non_null(u);
    uint64_t gv, nv, nt;
    assert_int_equal(vx_gregory_count(s, nd, &gv, &nv, &nt, &err), 0);
    assert_int_equal(gv, w->voff[np]);
    assert_int_equal(u->nverts, nv);
    assert_int_equal(u->ntris, nt); /* nothing collapses here */
    assert_int_equal(w->ntris, nt);
    assert_true(w->nverts < u->nverts);
    size_t bw = boundary_edges(w->tri, w->ntris, w->nverts);
    assert_int_equal(bw, open);
    double *pos = malloc(3 * w->nverts * sizeof *pos), *nrm = malloc(3 * w->nverts * sizeof *nrm);
    cpu_eval(s, w, pos, nrm);
    /* No T-junctions. */
    uint64_t *uses = malloc(3 * w->ntris * sizeof *uses);
    for (size_t t = 0; t < 3 * w->ntris; t++)
        uses[t] = (uint64_t)w->tri[t] << 32 | w->tri_patch[t / 3];
    qsort(uses, 3 * w->ntris, sizeof *uses, u64_cmp);
    size_t on_edges = 0;
    for (size_t v = 0; v < w->nverts; v++) {
        uint32_t i, j;
        size_t p = grid_at(w, w->rep[v], &i, &j);
        uint32_t n = nd[p];
        int ci = i == 0 || i == n, cj = j == 0 || j == n;
        if (!(ci ^ cj)) continue; /* interior or corner */
        int ed = j == 0 ? 0 : i == n ? 1 : j == n ? 2 : 3;
        kedge key = {edge_key(s, 4 * p + (size_t)ed), 0};
        kedge *k = bsearch(&key, e, 4 * np, sizeof *e, kedge_cmp);
        assert_non_null(k);
        while (k > e && k[-1].k == key.k)
            k--;
        for (; k < e + 4 * np && k->k == key.k; k++) {
            assert_true(u64_has(uses, 3 * w->ntris, (uint64_t)v << 32 | (k->pe / 4)));
            on_edges++;
        }
    }
    assert_true(on_edges > 0);
    /* No degenerate triangles. Triangles facing away from a vertex normal:
     * where a patch folds (the strip's ends, a few of suzanne's and spot's)
     * uniform grids have them too. Elsewhere only in transition patches of
     * 2, which fan from their centre to every point of their finer edges:
     * on a strongly curved patch one of those thin triangles can face away
     * (suzanne has one such patch, spot two); at most 2% of them. */
    double dg = diag(m), min_area, min_dot;
    uint8_t *back = calloc(np, 1), *uback = calloc(np, 1);
    size_t nback = facing(w, pos, nrm, dg, &min_area, &min_dot, back), nuback = 0;
    uint32_t lo = UINT32_MAX, hi = 0;
    for (size_t p = 0; p < np; p++) {
        if (nd[p] < lo) lo = nd[p];
        if (nd[p] > hi) hi = nd[p];
    }
    uint32_t *und = malloc(np * sizeof *und);
    for (uint32_t n = lo; n <= hi; n++) {
        for (size_t p = 0; p < np; p++)
            und[p] = n;
        vx_gtess_layout *g = vx_gregory_layout_new(s, und, 1, &err);
        double *gp = malloc(3 * g->nverts * sizeof *gp), *gn = malloc(3 * g->nverts * sizeof *gn);
        double ga, gd;
        cpu_eval(s, g, gp, gn);
        nuback += facing(g, gp, gn, dg, &ga, &gd, uback);
        free(gp);
        free(gn);
        vx_gregory_layout_free(g);
    }
    size_t stray = 0;
    for (size_t p = 0; p < np; p++) {
        stray += back[p] && !uback[p];
        if (back[p] && !uback[p]) assert_int_equal(nd[p], 2); /* a fan, see above */
        ntrans += trans[p];
    }
    fprintf(stderr,
            "  %s: N %u..%u, %zu of %zu shared edges differ; welded %zu vertices %zu triangles, "
            "%zu open edges; smallest 2 area %.3g of diag^2; %zu triangles face away from a "
            "vertex normal (uniform N = %u..%u: %zu), in %zu of %zu transition patches where no "
            "uniform grid has them\n",
            what, lo, hi, ndiffer, nshared, w->nverts, w->ntris, bw, min_area, nback, lo, hi,
            nuback, stray, ntrans);
    assert_true(min_area > 1e-12);
    assert_true(50 * stray <= ntrans);
    free(trans);
    free(und);
    free(back);
    free(uback);
    double uvw = min_uv_area(s, w), uvu = min_uv_area(s, u);
    fprintf(stderr, "  %s: smallest doubled (u, v) area welded %.3g, unwelded %.3g\n", what, uvw,
            uvu);
    assert_true(uvw > 0 && uvu > 0);
    free(uses);
    free(pos);
    free(nrm);
    free(e);
    vx_gregory_layout_free(w);
    vx_gregory_layout_free(u);
    free(nd);
    vx_gpatch_set_free(s);
}

static void test_max_edge_strip(void **state)
{
    (void)state;
    vx_mesh *m = strip_mesh();
    check_transitions(m, 0.25, "strip");
    vx_gpatch_set *s = build(m, NULL);
    vx_err err = {0};
    /* Needs of 1 next to needs of 2 become 2: a transition needs an interior. */
    uint32_t *nd = vx_gregory_divisions(s, 0, 1.5, &err); /* patch 0 needs 1 */
    uint32_t lo = 1000, hi = 0;
    for (size_t p = 0; p < s->npatches; p++) {
        if (nd[p] < lo) lo = nd[p];
        if (nd[p] > hi) hi = nd[p];
    }
    assert_int_equal(lo, 2);
    assert_true(hi > 2);
    /* Such a patch left at 1 is refused. */
    nd[0] = 1;
    assert_null(vx_gregory_layout_new(s, nd, 1, &err));
    assert_string_equal(err.code, "gregory_divisions");
    free(nd);
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

/* max_edge on suzanne and spot: several divisions inside one connected
 * component, and a finer target gives more divisions. */
static void test_max_edge(void **state)
{
    (void)state;
    vx_mesh *m = load("suzanne.obj");
    double d = diag(m);
    check_transitions(m, d / 50, "suzanne");
    vx_gpatch_set *s = build(m, NULL);
    vx_err err = {0};
    uint32_t *a = vx_gregory_divisions(s, 0, d / 50, &err),
             *b = vx_gregory_divisions(s, 0, d / 200, &err);
    for (size_t p = 0; p < s->npatches; p++) {
        assert_true(b[p] >= a[p]);
        assert_true(a[p] >= 1 && b[p] <= VX_GREGORY_MAX_DIVISIONS);
    }
    free(a);
    free(b);
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
    m = load("spot_control_mesh.obj");
    assert_int_equal(m->boundary_edges, 0);
    check_transitions(m, diag(m) / 30, "spot");
    vx_mesh_free(m);
}

/* Unwelded max_edge output on the GPU: the duplicated points of every
 * shared edge (each patch's own copies, the finer neighbour's grid points)
 * are at the same place in every patch. The unwelded and welded layouts
 * list the same triangles, so each welded vertex names its copies. */
static void test_gpu_transitions_unwelded(void **state)
{
    (void)state;
    vx_mesh *m = load("spot_control_mesh.obj");
    vx_gpatch_set *s = build(m, NULL);
    vx_err err = {0};
    double dg = diag(m);
    uint32_t *nd = vx_gregory_divisions(s, 0, dg / 30, &err);
    vx_gtess_layout *w = vx_gregory_layout_new(s, nd, 1, &err),
                    *u = vx_gregory_layout_new(s, nd, 0, &err);
    assert_int_equal(w->ntris, u->ntris);
    float *grid = malloc(6 * u->voff[s->npatches] * sizeof *grid);
    double origin[3] = {0, 0, 0}, ms;
    assert_int_equal(vx_gregory_tessellate(vx_test_gl, s, u, origin, grid, &ms, &err), 0);
    double *pos = malloc(3 * u->nverts * sizeof *pos);
    vx_gregory_gather(u, grid, origin, pos, NULL, NULL);
    uint32_t *first = malloc(w->nverts * sizeof *first);
    for (size_t v = 0; v < w->nverts; v++)
        first[v] = UINT32_MAX;
    double worst = 0;
    size_t copies = 0;
    for (size_t k = 0; k < 3 * w->ntris; k++) {
        uint32_t wv = w->tri[k], uv = u->tri[k];
        if (first[wv] == UINT32_MAX) {
            first[wv] = uv;
            continue;
        }
        if (first[wv] == uv) continue;
        copies++;
        double d2 = 0;
        for (int c = 0; c < 3; c++)
            d2 += (pos[3 * uv + c] - pos[3 * first[wv] + c]) *
                  (pos[3 * uv + c] - pos[3 * first[wv] + c]);
        if (sqrt(d2) / dg > worst) worst = sqrt(d2) / dg;
    }
    fprintf(stderr, "  unwelded copies of shared points: %zu, apart at most %.3g of the diagonal\n",
            copies, worst);
    assert_true(copies > 0);
    assert_true(worst <= 1e-6);
    free(first);
    free(pos);
    free(grid);
    vx_gregory_layout_free(w);
    vx_gregory_layout_free(u);
    free(nd);
    vx_gpatch_set_free(s);
    vx_mesh_free(m);
}

static cJSON *parse(const char *json, vx_err *err)
{
    cJSON *in = cJSON_Parse(json);
    vx_limits lim = {.max_triangles = 1000000};
    cJSON *out = vx_kind_parse(&vx_kind_gregory, in, &lim, err);
    cJSON_Delete(in);
    return out;
}

static void test_params(void **state)
{
    (void)state;
    vx_err err = {0};
    cJSON *o = parse("{}", &err);
    assert_non_null(o);
    assert_int_equal(cJSON_GetObjectItem(o, "divisions")->valueint, 8);
    assert_true(cJSON_IsNull(cJSON_GetObjectItem(o, "max_edge")));
    assert_string_equal(cJSON_GetObjectItem(o, "construction")->valuestring, "interpolate");
    assert_true(cJSON_IsTrue(cJSON_GetObjectItem(o, "weld")));
    assert_string_equal(cJSON_GetObjectItem(o, "format")->valuestring, "obj");
    cJSON_Delete(o);
    o = parse("{\"construction\": \"approximate-cc\"}", &err);
    assert_non_null(o);
    assert_string_equal(cJSON_GetObjectItem(o, "construction")->valuestring, "approximate-cc");
    cJSON_Delete(o);
    o = parse("{\"max_edge\": 0.5, \"frames\": [[0,0,0,1,1,1], [[0,0,0],[1,1,2]]]}", &err);
    assert_non_null(o);
    assert_true(cJSON_IsNull(cJSON_GetObjectItem(o, "divisions")));
    /* frames normalise flat, however given: the same positions are the
     * same params (reuse, Idempotency-Key) */
    char *fr = cJSON_PrintUnformatted(cJSON_GetObjectItem(o, "frames"));
    assert_string_equal(fr, "[[0,0,0,1,1,1],[0,0,0,1,1,2]]");
    free(fr);
    cJSON_Delete(o);
    cJSON *flat = parse("{\"frames\": [[0,0,0,1,1,2]]}", &err),
          *nested = parse("{\"frames\": [[[0,0,0],[1,1,2]]]}", &err);
    assert_true(flat && nested && cJSON_Compare(flat, nested, 1));
    cJSON_Delete(flat);
    cJSON_Delete(nested);
    static const char *bad[][2] = {
        {"{\"divisions\": 4, \"max_edge\": 1}", "max_edge"},
        {"{\"divisions\": 0}", "divisions"},
        {"{\"divisions\": 257}", "divisions"},
        {"{\"max_edge\": -1}", "max_edge"},
        {"{\"construction\": \"loop\"}", "construction"},
        {"{\"format\": \"stl\"}", "format"},
        {"{\"weld\": 1}", "weld"},
        {"{\"frames\": [[0,0]]}", "frames[0]"},
        {"{\"frames\": [[0,0,0], [0,0,0,1,1,1]]}", "frames[1]"},
        {"{\"frames\": [\"abc\"]}", "frames[0]"},
        {"{\"frames\": 3}", "frames"},
        {"{\"colour\": 3}", "colour"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        vx_err_clear(&err);
        assert_null(parse(bad[i][0], &err));
        assert_int_equal(err.kind, VX_EUNPROC);
        if (!strstr(err.message, bad[i][1])) fprintf(stderr, "%s: %s\n", bad[i][0], err.message);
        assert_non_null(strstr(err.message, bad[i][1]));
    }
    /* divisions over the triangle limit on one patch: 2 * 256^2 > 100000 */
    cJSON *in = cJSON_Parse("{\"divisions\": 256}");
    vx_limits lim = {.max_triangles = 100000};
    assert_null(vx_kind_parse(&vx_kind_gregory, in, &lim, &err));
    assert_non_null(strstr(err.message, "divisions"));
    cJSON_Delete(in);
    /* mesh ids of frames are the kind's further meshes */
    const char *id = "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef";
    char json[256];
    snprintf(json, sizeof json, "{\"frames\": [\"%s\", \"%s\"]}", id, id);
    o = parse(json, &err);
    assert_non_null(o);
    const char *ids[4];
    assert_int_equal(vx_kind_gregory.mesh_refs(o, ids, 4), 2);
    assert_string_equal(ids[1], id);
    cJSON_Delete(o);
}

int main(void)
{
    const struct CMUnitTest cpu[] = {
        cmocka_unit_test(test_g1_spot),
        cmocka_unit_test(test_g1_suzanne),
        cmocka_unit_test(test_g1_ngon),
        cmocka_unit_test(test_flat_fan),
        cmocka_unit_test(test_lone_faces),
        cmocka_unit_test(test_g1_open_quads),
        cmocka_unit_test(test_g1_quads),
        cmocka_unit_test(test_counts_and_weld),
        cmocka_unit_test(test_frames_reuse_topology),
        cmocka_unit_test(test_from_bezier_small),
        cmocka_unit_test(test_max_edge),
        cmocka_unit_test(test_max_edge_strip),
        cmocka_unit_test(test_params),
        cmocka_unit_test(test_far_from_origin),
    };
    const struct CMUnitTest gl[] = {
        cmocka_unit_test(test_gpu_matches_cpu), cmocka_unit_test(test_gpu_mixed_divisions),
        cmocka_unit_test(test_gpu_chunks),      cmocka_unit_test(test_gpu_transitions_unwelded),
        cmocka_unit_test(test_teapot_bezier),
    };
    int rc = cmocka_run_group_tests_name("gregory", cpu, NULL, NULL);
    return rc |
           cmocka_run_group_tests_name("gregory_gl", gl, vx_test_gl_setup, vx_test_gl_teardown);
}
