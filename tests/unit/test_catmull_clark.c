/* Uniform Catmull-Clark through OpenSubdiv: counts predicted from the
 * refinement rules and Euler's formula, closedness, boundaries, n-gons,
 * limit positions and normals. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "shapes.h"
#include "gregory/catmull_clark.h"

static const double cube_pos[] = {-1, -1, -1, 1, -1, -1, 1, 1, -1, -1, 1, -1,
                                  -1, -1, 1,  1, -1, 1,  1, 1, 1,  -1, 1, 1};
static const uint32_t cube_sizes[] = {4, 4, 4, 4, 4, 4};
static const uint32_t cube_idx[] = {0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4,
                                    1, 2, 6, 5, 2, 3, 7, 6, 3, 0, 4, 7}; /* outward (CCW) */

static size_t edges(const vx_mesh *m)
{
    /* every interior edge is shared by two faces */
    size_t corners = 0;
    for (size_t f = 0; f < m->nfaces; f++)
        corners += vx_mesh_face_size(m, f);
    return (corners + m->boundary_edges) / 2;
}

/* V, E, F after one level: V' = V + E + F, E' = 2E + corners, F' = corners. */
static void predict(size_t *v, size_t *e, size_t *f, size_t corners)
{
    size_t nv = *v + *e + *f, ne = 2 * *e + corners;
    *v = nv;
    *e = ne;
    *f = corners;
}

static void check_counts(const vx_mesh *m, int maxlev)
{
    size_t v = m->nverts, e = edges(m), f = m->nfaces, corners = 0;
    for (size_t i = 0; i < m->nfaces; i++)
        corners += vx_mesh_face_size(m, i);
    for (int l = 1; l <= maxlev; l++) {
        predict(&v, &e, &f, corners);
        corners = 4 * f;
        vx_mesh *o;
        float *n;
        vx_err err = {0};
        assert_int_equal(vx_cc_refine(m, l, 0, &o, &n, &err), 0);
        assert_int_equal(o->nverts, v);
        assert_int_equal(o->nfaces, f);
        assert_int_equal(o->nfaces, vx_cc_quads(m, l));
        assert_int_equal(o->faces_by_size[1], f); /* all quads */
        assert_int_equal(edges(o), e);
        /* the boundary doubles with each level; closed stays closed */
        assert_int_equal(o->boundary_edges, m->boundary_edges << l);
        assert_int_equal(o->nonmanifold_edges, 0);
        for (size_t i = 0; i < o->nverts; i++) {
            double len = sqrt(n[3 * i] * n[3 * i] + n[3 * i + 1] * n[3 * i + 1] +
                              n[3 * i + 2] * n[3 * i + 2]);
            assert_float_equal(len, 1.0, 1e-5);
        }
        vx_mesh_free(o);
        free(n);
    }
}

static void test_cube(void **state)
{
    (void)state;
    vx_mesh *m = shape_poly_mesh(8, cube_pos, 6, cube_sizes, cube_idx);
    check_counts(m, 4);
    for (int l = 1; l <= 4; l++) {
        vx_mesh *o;
        float *n;
        vx_err err = {0};
        assert_int_equal(vx_cc_refine(m, l, 0, &o, &n, &err), 0);
        /* quads 6 * 4^l, Euler characteristic 2 */
        assert_int_equal(o->nfaces, 6u << (2 * l));
        assert_int_equal((long)o->nverts - (long)edges(o) + (long)o->nfaces, 2);
        /* limit normals point outward on the convex cube */
        for (size_t i = 0; i < o->nverts; i++) {
            const double *p = o->pos + 3 * i;
            assert_true(p[0] * n[3 * i] + p[1] * n[3 * i + 1] + p[2] * n[3 * i + 2] > 0);
        }
        vx_mesh_free(o);
        free(n);
    }
    vx_mesh_free(m);
}

static void test_limit(void **state)
{
    (void)state;
    vx_mesh *m = shape_poly_mesh(8, cube_pos, 6, cube_sizes, cube_idx);
    vx_mesh *a, *b, *c;
    float *na, *nb, *nc;
    vx_err err = {0};
    assert_int_equal(vx_cc_refine(m, 2, 0, &a, &na, &err), 0);
    assert_int_equal(vx_cc_refine(m, 2, 1, &b, &nb, &err), 0);
    assert_int_equal(vx_cc_refine(m, 6, 0, &c, &nc, &err), 0);
    assert_int_equal(a->nverts, b->nverts);
    /* Projecting moves the refined points (a) inward on the convex cube,
     * and the limit points (b) are where refinement converges: vertex i of
     * level 2 is vertex i of level 6 (OpenSubdiv numbers the children of
     * vertices first), whose position (c) is much closer to b than to a. */
    double da = 0, db = 0, moved = 0;
    for (size_t i = 0; i < a->nverts; i++) {
        double ra = 0, rb = 0;
        for (int k = 0; k < 3; k++) {
            ra += a->pos[3 * i + k] * a->pos[3 * i + k];
            rb += b->pos[3 * i + k] * b->pos[3 * i + k];
        }
        moved = fmax(moved, fabs(ra - rb));
        assert_true(rb <= ra + 1e-12);
        double dA = 0, dB = 0;
        for (int k = 0; k < 3; k++) {
            dA += pow(a->pos[3 * i + k] - c->pos[3 * i + k], 2);
            dB += pow(b->pos[3 * i + k] - c->pos[3 * i + k], 2);
        }
        da = fmax(da, sqrt(dA));
        db = fmax(db, sqrt(dB));
    }
    assert_true(moved > 1e-3);
    assert_true(db < 0.1 * da);
    vx_mesh_free(a);
    vx_mesh_free(b);
    vx_mesh_free(c);
    free(na);
    free(nb);
    free(nc);
    vx_mesh_free(m);
}

static void test_open_and_ngons(void **state)
{
    (void)state;
    /* one quad: a boundary everywhere */
    static const double qp[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    static const uint32_t qs[] = {4}, qi[] = {0, 1, 2, 3};
    vx_mesh *q = shape_poly_mesh(4, qp, 1, qs, qi);
    assert_int_equal(q->boundary_edges, 4);
    check_counts(q, 3);
    vx_mesh_free(q);
    /* a pyramid: four triangles and a square base, closed */
    static const double pp[] = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0, 0, 0, 1};
    static const uint32_t ps[] = {3, 3, 3, 3, 4},
                          pi[] = {0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4, 0, 3, 2, 1};
    vx_mesh *p = shape_poly_mesh(5, pp, 5, ps, pi);
    assert_int_equal(p->boundary_edges, 0);
    check_counts(p, 3);
    /* a pentagon fan with an open rim: n-gon faces and a boundary */
    static const double gp[] = {0, 0, 0, 1, 0, 0, 2, 1, 0, 1, 2, 0, 0, 1, 0, 3, 0, 0, 3, 2, 0};
    static const uint32_t gs[] = {5, 4}, gi[] = {0, 1, 2, 3, 4, 1, 5, 6, 2};
    vx_mesh *g = shape_poly_mesh(7, gp, 2, gs, gi);
    assert_int_equal(g->faces_by_size[2], 1);
    check_counts(g, 3);
    vx_mesh_free(g);
    vx_err err = {0};
    vx_mesh *o;
    float *n;
    assert_int_equal(vx_cc_refine(p, 0, 0, &o, &n, &err), -1);
    assert_string_equal(err.code, "invalid_params");
    assert_int_equal(vx_cc_refine(p, VX_CC_MAX_LEVELS + 1, 0, &o, &n, &err), -1);
    vx_mesh_free(p);
}

/* A vertex with more faces around it than OpenSubdiv takes (65535): the
 * error names it (it was "OpenSubdiv cannot take the mesh's topology (70000
 * faces)"). A fan of 70,000 triangles round its centre. */
static void test_valence_limit(void **state)
{
    (void)state;
    enum { K = 70000 };
    double *pos = malloc(3 * (K + 1) * sizeof *pos);
    uint32_t *sizes = malloc(K * sizeof *sizes), *idx = malloc(3 * K * sizeof *idx);
    pos[0] = pos[1] = pos[2] = 0;
    for (uint32_t i = 0; i < K; i++) {
        pos[3 * (i + 1)] = cos(2 * M_PI * i / K);
        pos[3 * (i + 1) + 1] = sin(2 * M_PI * i / K);
        pos[3 * (i + 1) + 2] = 0;
        sizes[i] = 3;
        idx[3 * i] = 0;
        idx[3 * i + 1] = 1 + i;
        idx[3 * i + 2] = 1 + (i + 1) % K;
    }
    vx_mesh *m = shape_poly_mesh(K + 1, pos, K, sizes, idx);
    vx_err err = {0};
    vx_mesh *o = NULL;
    float *n = NULL;
    assert_int_equal(vx_cc_refine(m, 1, 0, &o, &n, &err), -1);
    assert_string_equal(err.code, "osd_topology");
    print_message("%s\n", err.message);
    assert_non_null(strstr(err.message, "vertex 1 has 65535 or more faces"));
    vx_mesh_free(m);
    free(pos);
    free(sizes);
    free(idx);
}

static void test_real_meshes(void **state)
{
    (void)state;
    const char *names[] = {"spot_control_mesh.obj", "suzanne.obj"};
    for (int i = 0; i < 2; i++) {
        char path[512];
        snprintf(path, sizeof path, "%s/%s", VX_MESH_DIR, names[i]);
        vx_err err = {0};
        vx_mesh *m = vx_mesh_read_path(path, NULL, &err);
        assert_non_null(m);
        check_counts(m, 2);
        vx_mesh_free(m);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cube),           cmocka_unit_test(test_limit),
        cmocka_unit_test(test_open_and_ngons), cmocka_unit_test(test_real_meshes),
        cmocka_unit_test(test_valence_limit),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
