/* The CPU reference voxelizer itself, against analytic answers. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <cmocka.h>

#include "ref_voxel.h"

/* Axis-aligned box [lo, hi] as 12 outward-facing triangles. */
static vx_mesh *box(const double lo[3], const double hi[3])
{
    vx_mesh *m = vx_mesh_new();
    m->nverts = 8;
    m->pos = malloc(24 * sizeof(double));
    for (int v = 0; v < 8; v++)
        for (int a = 0; a < 3; a++)
            m->pos[3 * v + a] = (v >> a) & 1 ? hi[a] : lo[a];
    static const uint32_t f[36] = {0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4,
                                   2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5};
    m->nfaces = 12;
    m->face_idx = malloc(sizeof f);
    for (int i = 0; i < 36; i++)
        m->face_idx[i] = f[i];
    vx_mesh_analyze(m, NULL);
    return m;
}

static size_t count(const uint8_t *v, size_t n)
{
    size_t c = 0;
    for (size_t i = 0; i < n; i++)
        c += v[i];
    return c;
}

static void test_box_exact(void **state)
{
    /* a cube filling an 8^3 grid gives 512 voxels */
    vx_mesh *m = box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    vx_grid g;
    assert_int_equal(vx_grid_from_resolution(m, 8, 0, &g, NULL), 0);
    assert_int_equal(g.dims[0], 8);
    uint8_t *out = malloc(512);
    assert_int_equal(ref_voxelize(m, &g, VX_INSIDE_NONZERO, out), 0);
    assert_int_equal(count(out, 512), 512);
    assert_int_equal(ref_voxelize(m, &g, VX_INSIDE_PARITY, out), 0);
    assert_int_equal(count(out, 512), 512);
    /* padding 2: 12^3 grid, still 512 inside */
    assert_int_equal(vx_grid_from_resolution(m, 8, 2, &g, NULL), 0);
    assert_int_equal(g.dims[2], 12);
    out = realloc(out, 12 * 12 * 12);
    assert_int_equal(ref_voxelize(m, &g, VX_INSIDE_NONZERO, out), 0);
    assert_int_equal(count(out, 1728), 512);
    free(out);
    /* winding number: 1 inside, 0 outside */
    assert_true(fabs(ref_winding_number(m, (double[]){0.3, 0.5, 0.7}) - 1) < 1e-9);
    assert_true(fabs(ref_winding_number(m, (double[]){1.3, 0.5, 0.7})) < 1e-9);
    vx_mesh_free(m);
}

static void test_two_boxes(void **state)
{
    /* overlapping boxes: nonzero = union, parity = symmetric difference */
    vx_mesh *a = box((double[]){0, 0, 0}, (double[]){2, 2, 2});
    vx_mesh *b = box((double[]){1, 1, 1}, (double[]){3, 3, 3});
    vx_mesh *m = vx_mesh_new();
    m->nverts = 16;
    m->pos = malloc(48 * sizeof(double));
    for (int i = 0; i < 24; i++)
        m->pos[i] = a->pos[i], m->pos[24 + i] = b->pos[i];
    m->nfaces = 24;
    m->face_idx = malloc(72 * sizeof(uint32_t));
    for (int i = 0; i < 36; i++)
        m->face_idx[i] = a->face_idx[i], m->face_idx[36 + i] = b->face_idx[i] + 8;
    vx_mesh_analyze(m, NULL);
    vx_grid g = {{0, 0, 0}, 0.25, {12, 12, 12}, {0, 0, 0}};
    uint8_t *out = malloc(1728);
    ref_voxelize(m, &g, VX_INSIDE_NONZERO, out);
    assert_int_equal(count(out, 1728), 2 * 512 - 64);
    ref_voxelize(m, &g, VX_INSIDE_PARITY, out);
    assert_int_equal(count(out, 1728), 2 * 512 - 2 * 64);
    free(out);
    vx_mesh_free(a), vx_mesh_free(b), vx_mesh_free(m);
}

static void test_real_mesh_volume(void **state)
{
    /* spot is closed: parity and nonzero agree, and the winding number at
     * sampled centres agrees with the ray answer */
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_triangulated.obj", NULL, NULL);
    assert_non_null(m);
    vx_grid g;
    vx_grid_from_resolution(m, 64, 1, &g, NULL);
    size_t n = (size_t)g.dims[0] * g.dims[1] * g.dims[2];
    uint8_t *p = malloc(n), *w = malloc(n);
    ref_voxelize(m, &g, VX_INSIDE_PARITY, p);
    ref_voxelize(m, &g, VX_INSIDE_NONZERO, w);
    size_t diff = 0;
    for (size_t i = 0; i < n; i++)
        diff += p[i] != w[i];
    assert_int_equal(diff, 0);
    assert_true(count(p, n) > n / 20);
    for (size_t s = 0; s < 200; s++) {
        size_t i = (s * 7919u) % n;
        int x = (int)(i % g.dims[0]), y = (int)(i / g.dims[0] % g.dims[1]),
            z = (int)(i / g.dims[0] / g.dims[1]);
        double c[3] = {g.origin[0] + (x + .5) * g.h, g.origin[1] + (y + .5) * g.h,
                       g.origin[2] + (z + .5) * g.h};
        assert_int_equal(ref_winding_number(m, c) > 0.5, p[i]);
    }
    free(p), free(w);
    vx_mesh_free(m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_box_exact),
        cmocka_unit_test(test_two_boxes),
        cmocka_unit_test(test_real_mesh_volume),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
