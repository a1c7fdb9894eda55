/* The approximate-cc construction: our 20-point patches evaluate exactly as
 * OpenSubdiv's own patches they came from (the proof of the point mapping),
 * the distance to the Catmull-Clark limit surface is ~0 on an all-regular
 * mesh and bounded elsewhere, and neighbouring patches meet (corner keys,
 * shared edges). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "shapes.h"
#include "gregory/osd.h"

static vx_mesh *load(const char *name)
{
    vx_mesh *m = shape_load(name);
    assert_non_null(m);
    return m;
}

static vx_mesh *cube(void)
{
    static const double p[] = {-1, -1, -1, 1, -1, -1, 1, 1, -1, -1, 1, -1,
                               -1, -1, 1,  1, -1, 1,  1, 1, 1,  -1, 1, 1};
    static const uint32_t f[] = {0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4,
                                 1, 2, 6, 5, 2, 3, 7, 6, 3, 0, 4, 7};
    return shape_poly_mesh(8, p, 6, NULL, f);
}

/* A torus of nu x nv quads: every vertex has valence 4, so every patch is a
 * regular B-spline patch. */
static vx_mesh *torus(int nu, int nv)
{
    double *p = malloc(3 * (size_t)(nu * nv) * sizeof(double));
    uint32_t *f = malloc(4 * (size_t)(nu * nv) * sizeof(uint32_t));
    for (int j = 0; j < nv; j++)
        for (int i = 0; i < nu; i++) {
            double a = 2 * M_PI * i / nu, b = 2 * M_PI * j / nv, r = 2 + 0.7 * cos(b);
            double *q = p + 3 * (j * nu + i);
            q[0] = r * cos(a);
            q[1] = r * sin(a);
            q[2] = 0.7 * sin(b) + 0.1 * sin(3 * a); /* not a surface of revolution */
            uint32_t *g = f + 4 * (j * nu + i);
            g[0] = (uint32_t)(j * nu + i);
            g[1] = (uint32_t)(j * nu + (i + 1) % nu);
            g[2] = (uint32_t)(((j + 1) % nv) * nu + (i + 1) % nu);
            g[3] = (uint32_t)(((j + 1) % nv) * nu + i);
        }
    vx_mesh *m = shape_poly_mesh((size_t)(nu * nv), p, (size_t)(nu * nv), NULL, f);
    free(p);
    free(f);
    return m;
}

static double diag(const vx_mesh *m)
{
    double d = 0;
    for (int a = 0; a < 3; a++)
        d += pow(m->bbox_max[a] - m->bbox_min[a], 2);
    return sqrt(d);
}

static double dist3(const double *a, const double *b)
{
    return sqrt(pow(a[0] - b[0], 2) + pow(a[1] - b[1], 2) + pow(a[2] - b[2], 2));
}

static const double corner_uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};

/* Patches meet: every corner key is one point, and a shared edge (the same
 * two keys) is the same curve in both patches. Returns the worst gap. */
static double seam_gap(const vx_gpatch_set *s)
{
    double worst = 0;
    for (size_t p = 0; p < s->npatches; p++)
        for (size_t q = p + 1; q < s->npatches; q++)
            for (int a = 0; a < 4; a++)
                for (int b = 0; b < 4; b++) {
                    if (s->corner_key[4 * p + a] != s->corner_key[4 * q + b]) continue;
                    double x[3], y[3];
                    const double *cp = s->cp + p * 60, *cq = s->cp + q * 60;
                    vx_gpatch_eval(cp, corner_uv[a][0], corner_uv[a][1], x, NULL);
                    vx_gpatch_eval(cq, corner_uv[b][0], corner_uv[b][1], y, NULL);
                    worst = fmax(worst, dist3(x, y));
                    /* the edge a -> a+1 of p against b -> b-1 of q (opposite
                     * directions in consistently oriented neighbours) */
                    int a1 = (a + 1) % 4, b1 = (b + 3) % 4;
                    if (s->corner_key[4 * p + a1] != s->corner_key[4 * q + b1]) continue;
                    for (int k = 1; k < 8; k++) {
                        double t = k / 8.0;
                        vx_gpatch_eval(
                            cp, corner_uv[a][0] + t * (corner_uv[a1][0] - corner_uv[a][0]),
                            corner_uv[a][1] + t * (corner_uv[a1][1] - corner_uv[a][1]), x, NULL);
                        vx_gpatch_eval(
                            cq, corner_uv[b][0] + t * (corner_uv[b1][0] - corner_uv[b][0]),
                            corner_uv[b][1] + t * (corner_uv[b1][1] - corner_uv[b][1]), y, NULL);
                        worst = fmax(worst, dist3(x, y));
                    }
                }
    return worst;
}

/* Builds, checks the exact mapping and the seams, returns the distance to
 * the limit surface (relative to the bbox diagonal). */
static double check(const char *what, vx_mesh *m, size_t want_patches)
{
    vx_gpatch_set *s = NULL;
    vx_err err = {0};
    if (vx_gregory_build_approx_cc(m, &s, &err)) print_error("%s: %s\n", what, err.message);
    assert_non_null(s);
    assert_int_equal(s->npatches, want_patches);
    double mis = vx_gregory_cc_mismatch(m, s, 9, &err);
    double d = vx_gregory_cc_distance(m, s, 9, &err);
    double gap = seam_gap(s) / diag(m);
    print_message("%s: %zu patches, vs OpenSubdiv's patches %.3g, to the limit %.3g, seams %.3g "
                  "(relative to the bbox diagonal)\n",
                  what, s->npatches, mis, d, gap);
    assert_true(mis >= 0 && mis < 1e-12);
    assert_true(d >= 0);
    assert_true(gap < 1e-12);
    /* faces: every input face gives as many patches as it has corners
     * (quads: one, when the whole mesh is quads and used as it is) */
    int quads = m->faces_by_size[1] == m->nfaces && want_patches == m->nfaces;
    size_t p = 0;
    for (size_t f = 0; f < m->nfaces; f++)
        for (uint32_t k = 0; k < (quads ? 1 : vx_mesh_face_size(m, f)); k++, p++) {
            assert_true(p < s->npatches);
            assert_int_equal(s->face[p], f);
        }
    assert_int_equal(p, s->npatches);
    vx_gpatch_set_free(s);
    return d;
}

static void test_torus_regular(void **state)
{
    (void)state;
    vx_mesh *m = torus(12, 8);
    double d = check("torus (all regular)", m, 96);
    /* regular patches are the limit surface itself: rounding only */
    assert_true(d < 1e-12);
    vx_mesh_free(m);
}

static void test_cube(void **state)
{
    (void)state;
    vx_mesh *m = cube();
    /* all quads: one patch per face, each with four valence-3 corners */
    double d = check("cube", m, 6);
    /* measured 0.0123 (a Gregory end cap on a whole cube face, all four
     * corners extraordinary, is the coarsest case); bound a bit above */
    assert_true(d > 1e-4);
    assert_true(d < 0.015);
    vx_mesh_free(m);
}

static void test_spot(void **state)
{
    (void)state;
    vx_mesh *m = load("spot_control_mesh.obj");
    size_t corners = 0;
    int quads = 1;
    for (size_t f = 0; f < m->nfaces; f++) {
        corners += vx_mesh_face_size(m, f);
        quads &= vx_mesh_face_size(m, f) == 4;
    }
    double d = check("spot_control_mesh", m, quads ? m->nfaces : corners);
    /* measured 0.00461 (patches on the once-refined mesh: it has
     * non-quads); bound a bit above */
    assert_true(d > 1e-5);
    assert_true(d < 0.006);
    vx_mesh_free(m);
}

static void test_suzanne_boundaries(void **state)
{
    (void)state;
    vx_mesh *m = load("suzanne.obj");
    assert_true(m->boundary_edges > 0);
    size_t corners = 0;
    for (size_t f = 0; f < m->nfaces; f++)
        corners += vx_mesh_face_size(m, f);
    double d = check("suzanne (boundaries, triangles)", m, corners);
    /* measured 0.00524; bound a bit above */
    assert_true(d > 1e-5);
    assert_true(d < 0.0065);
    vx_mesh_free(m);
}

/* Two quads on the same four corners, facing away from each other (a
 * double-sided sheet): OpenSubdiv's end caps of such quads index points
 * that do not exist (a crash), so the mesh is refined once first, as a mesh
 * with non-quads is: four patches a quad. Flat, it stays flat; bent, the
 * patches still meet and stay inside the corners' box. */
static void test_twin_quads(void **state)
{
    (void)state;
    for (int bent = 0; bent < 2; bent++) {
        const double p[] = {0, 0, 0, 1, 0, 0, 1, 1, 0.5 * bent, 0, 1, 0};
        const uint32_t f[] = {0, 1, 2, 3, 3, 2, 1, 0};
        vx_mesh *m = shape_poly_mesh(4, p, 2, NULL, f);
        assert_non_null(m);
        vx_gpatch_set *s = NULL;
        vx_err err = {0};
        assert_int_equal(vx_gregory_build_approx_cc(m, &s, &err), 0);
        assert_int_equal(s->npatches, 8);
        for (size_t i = 0; i < s->npatches; i++)
            assert_int_equal(s->face[i], i / 4);
        for (size_t i = 0; i < s->npatches * VX_GPATCH_POINTS; i++) {
            const double *c = s->cp + 3 * i;
            for (int a = 0; a < 3; a++) {
                assert_true(isfinite(c[a]));
                assert_true(c[a] >= m->bbox_min[a] - 1e-12 && c[a] <= m->bbox_max[a] + 1e-12);
            }
            if (!bent) assert_true(fabs(c[2]) < 1e-15);
        }
        assert_true(seam_gap(s) < 1e-12);
        vx_gpatch_set_free(s);
        vx_mesh_free(m);
    }
}

/* Max |a - b| over two sets' control points. */
static double cp_diff(const vx_gpatch_set *a, const vx_gpatch_set *b)
{
    assert_int_equal(a->npatches, b->npatches);
    double worst = 0;
    for (size_t i = 0; i < a->npatches * VX_GPATCH_POINTS * 3; i++)
        worst = fmax(worst, fabs(a->cp[i] - b->cp[i]));
    assert_memory_equal(a->corner_key, b->corner_key, a->npatches * 4 * sizeof(uint32_t));
    assert_memory_equal(a->face, b->face, a->npatches * sizeof(uint32_t));
    return worst;
}

/* A plan re-evaluated on new positions (a deformation frame) gives what a
 * fresh build on those positions gives, frame after frame. */
static void test_frames(void **state)
{
    (void)state;
    const char *names[] = {"spot_control_mesh.obj", "suzanne.obj"};
    for (int n = 0; n < 2; n++) {
        vx_mesh *m = load(names[n]);
        vx_err err = {0};
        vx_gregory_cc_plan *plan = vx_gregory_cc_plan_new(m, &err);
        assert_non_null(plan);
        vx_gpatch_set *s = vx_gpatch_set_new(vx_gregory_cc_plan_patches(plan));
        vx_gpatch_set *first = NULL;
        double *orig = malloc(3 * m->nverts * sizeof(double));
        memcpy(orig, m->pos, 3 * m->nverts * sizeof(double));
        for (int frame = 0; frame < 3; frame++) {
            /* frame k: a twist about z and a bend, growing with k; the
             * mesh's own positions become the frame's for the fresh build */
            for (size_t i = 0; i < m->nverts; i++) {
                double *q = m->pos + 3 * i, *o = orig + 3 * i, a = 0.3 * frame * o[2];
                q[0] = o[0] * cos(a) - o[1] * sin(a);
                q[1] = o[0] * sin(a) + o[1] * cos(a) + 0.1 * frame * o[0] * o[0];
                q[2] = o[2];
            }
            assert_int_equal(vx_mesh_analyze(m, &err), 0);
            assert_int_equal(vx_gregory_cc_plan_eval(plan, m->pos, s, &err), 0);
            vx_gpatch_set *fresh = NULL;
            assert_int_equal(vx_gregory_build_approx_cc(m, &fresh, &err), 0);
            double d = cp_diff(s, fresh);
            assert_true(d <= 1e-14 * diag(m));
            if (frame == 0) {
                first = vx_gpatch_set_new(s->npatches);
                memcpy(first->cp, s->cp, s->npatches * VX_GPATCH_POINTS * 3 * sizeof(double));
                memcpy(first->corner_key, s->corner_key, s->npatches * 4 * sizeof(uint32_t));
                memcpy(first->face, s->face, s->npatches * sizeof(uint32_t));
            } else {
                /* the frame moved the patches, and they are still exactly
                 * OpenSubdiv's patches of the moved mesh */
                assert_true(cp_diff(s, first) > 1e-3 * diag(m));
                assert_true(vx_gregory_cc_mismatch(m, s, 5, &err) < 1e-12);
            }
            vx_gpatch_set_free(fresh);
        }
        /* a set of the wrong size is refused */
        vx_gpatch_set *wrong = vx_gpatch_set_new(3);
        assert_int_equal(vx_gregory_cc_plan_eval(plan, m->pos, wrong, &err), -1);
        assert_string_equal(err.code, "patch_mismatch");
        vx_gpatch_set_free(wrong);
        vx_gpatch_set_free(s);
        vx_gpatch_set_free(first);
        vx_gregory_cc_plan_free(plan);
        free(orig);
        vx_mesh_free(m);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_torus_regular), cmocka_unit_test(test_cube),
        cmocka_unit_test(test_spot),          cmocka_unit_test(test_suzanne_boundaries),
        cmocka_unit_test(test_frames),        cmocka_unit_test(test_twin_quads),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
