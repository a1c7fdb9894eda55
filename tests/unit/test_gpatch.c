/* The CPU Gregory patch evaluator: Bézier special case, blend limits at the
 * corners, normals against finite differences. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <cmocka.h>

#include "gregory/gregory.h"

static double rnd(unsigned *s)
{
    *s = *s * 1103515245u + 12345u;
    return ((*s >> 8) & 0xffff) / 65536.0;
}

/* A bumpy patch over the unit square with distinct k = 0 / k = 1 points. */
static void make_patch(double cp[60], int bezier, unsigned seed)
{
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++) {
            double *p = cp + 3 * (4 * j + i);
            p[0] = i / 3.0;
            p[1] = j / 3.0;
            p[2] = 0.3 * rnd(&seed);
        }
    const int slot0[4] = {5, 6, 9, 10}; /* (1,1) (2,1) (1,2) (2,2) */
    for (int k = 0; k < 4; k++)
        for (int c = 0; c < 3; c++)
            cp[3 * (16 + k) + c] = cp[3 * slot0[k] + c] + (bezier ? 0 : 0.2 * (rnd(&seed) - 0.5));
}

static void bezier(const double cp[60], double u, double v, double p[3])
{
    double bu[4] = {(1 - u) * (1 - u) * (1 - u), 3 * u * (1 - u) * (1 - u), 3 * u * u * (1 - u),
                    u * u * u};
    double bv[4] = {(1 - v) * (1 - v) * (1 - v), 3 * v * (1 - v) * (1 - v), 3 * v * v * (1 - v),
                    v * v * v};
    p[0] = p[1] = p[2] = 0;
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++)
            for (int c = 0; c < 3; c++)
                p[c] += bu[i] * bv[j] * cp[3 * (4 * j + i) + c];
}

static void test_bezier_case(void **state)
{
    (void)state;
    double cp[60];
    make_patch(cp, 1, 7);
    for (int a = 0; a <= 10; a++)
        for (int b = 0; b <= 10; b++) {
            double p[3], q[3], n[3];
            vx_gpatch_eval(cp, a / 10.0, b / 10.0, p, n);
            bezier(cp, a / 10.0, b / 10.0, q);
            for (int c = 0; c < 3; c++)
                assert_true(fabs(p[c] - q[c]) < 1e-14);
            assert_true(fabs(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1) < 1e-12);
            assert_true(n[2] > 0); /* the net faces +z */
        }
}

/* The boundary curves are the net's boundary rows whatever the interior. */
static void test_boundaries_and_normals(void **state)
{
    (void)state;
    double g[60], b[60];
    make_patch(g, 0, 3);
    make_patch(b, 1, 3);
    for (int a = 0; a <= 20; a++) {
        double t = a / 20.0, p[3], q[3];
        double uv[4][2] = {{t, 0}, {1, t}, {t, 1}, {0, t}};
        for (int e = 0; e < 4; e++) {
            vx_gpatch_eval(g, uv[e][0], uv[e][1], p, NULL);
            bezier(b, uv[e][0], uv[e][1], q);
            for (int c = 0; c < 3; c++)
                assert_true(fabs(p[c] - q[c]) < 1e-14);
        }
    }
    /* Interior differs from the Bézier patch of the k = 0 points. */
    double p[3], q[3];
    vx_gpatch_eval(g, 0.4, 0.3, p, NULL);
    bezier(b, 0.4, 0.3, q);
    assert_true(fabs(p[2] - q[2]) > 1e-4);
    /* Normals are the normalised cross product of finite differences. */
    const double h = 1e-6;
    for (int a = 1; a < 10; a++)
        for (int c = 1; c < 10; c++) {
            double u = a / 10.0, v = c / 10.0, n[3], pu0[3], pu1[3], pv0[3], pv1[3], x[3];
            vx_gpatch_eval(g, u, v, x, n);
            vx_gpatch_eval(g, u - h, v, pu0, NULL);
            vx_gpatch_eval(g, u + h, v, pu1, NULL);
            vx_gpatch_eval(g, u, v - h, pv0, NULL);
            vx_gpatch_eval(g, u, v + h, pv1, NULL);
            double du[3], dv[3], m[3];
            for (int k = 0; k < 3; k++) {
                du[k] = pu1[k] - pu0[k];
                dv[k] = pv1[k] - pv0[k];
            }
            m[0] = du[1] * dv[2] - du[2] * dv[1];
            m[1] = du[2] * dv[0] - du[0] * dv[2];
            m[2] = du[0] * dv[1] - du[1] * dv[0];
            double l = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
            for (int k = 0; k < 3; k++)
                assert_true(fabs(m[k] / l - n[k]) < 1e-6);
        }
}

/* A patch whose v = 1 edge collapses to a point (the teapot lid's apex):
 * the normal there is still a unit vector, the limit of the nearby ones. */
static void test_collapsed_edge(void **state)
{
    (void)state;
    double cp[60];
    make_patch(cp, 1, 11);
    for (int i = 0; i < 4; i++)
        for (int c = 0; c < 3; c++)
            cp[3 * (12 + i) + c] = (c == 2) ? 0.5 : 0.5;
    double p[3], n[3], pn[3], nn[3];
    vx_gpatch_eval(cp, 0.5, 1.0, p, n);
    vx_gpatch_eval(cp, 0.5, 1.0 - 1e-4, pn, nn);
    assert_true(fabs(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1) < 1e-9);
    assert_true(n[0] * nn[0] + n[1] * nn[1] + n[2] * nn[2] > 0.99);
}

/* The same with coordinates that are not exact in binary (the teapot's):
 * the derivative along the collapsed edge is then rounding noise in a
 * random direction, which must not be taken for a tangent. */
static void test_collapsed_edge_inexact(void **state)
{
    (void)state;
    double cp[60];
    make_patch(cp, 1, 13);
    for (int i = 0; i < 4; i++) {
        cp[3 * (12 + i)] = 0.1;
        cp[3 * (12 + i) + 1] = 0.7;
        cp[3 * (12 + i) + 2] = 0.3;
    }
    for (int k = 0; k <= 10; k++) {
        double p[3], n[3], pn[3], nn[3];
        vx_gpatch_eval(cp, k / 10.0, 1.0, p, n);
        vx_gpatch_eval(cp, 0.5 + (k / 10.0 - 0.5) * (1 - 1e-4), 1.0 - 1e-4, pn, nn);
        assert_true(fabs(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1) < 1e-9);
        assert_true(n[0] * nn[0] + n[1] * nn[1] + n[2] * nn[2] > 0.99);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bezier_case),
        cmocka_unit_test(test_boundaries_and_normals),
        cmocka_unit_test(test_collapsed_edge),
        cmocka_unit_test(test_collapsed_edge_inexact),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
