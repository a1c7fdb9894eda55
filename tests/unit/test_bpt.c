/* .bpt reader: the teapot's patches and points, the tessellation (shared
 * vertices, outward normals, points on the Bézier surface), sniffing, and
 * every error code with its line. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "shapes.h"
#include "mesh/mesh.h"

#define TEAPOT VX_MESH_DIR "/newell-teapot.bpt"

static vx_mesh *read_str(const char *text, const vx_mesh_limits *lim, vx_err *err)
{
    char path[] = "/tmp/vx_test_bpt_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    size_t n = strlen(text);
    assert_int_equal(write(fd, text, n), (ssize_t)n);
    close(fd);
    vx_mesh *m = vx_mesh_read_path(path, lim, err); /* through the sniffer */
    unlink(path);
    return m;
}

static void test_teapot(void **state)
{
    (void)state;
    vx_err err = {0};
    vx_mesh *m = vx_mesh_read_path(TEAPOT, NULL, &err);
    if (!m) print_error("%s: %s\n", err.code, err.message);
    assert_non_null(m);
    assert_int_equal(m->npatches, 32);
    /* first patch line "1,2,3,4,..." → zero-based 0..15; the 306 points come first */
    for (int k = 0; k < 16; k++)
        assert_int_equal(m->patch_idx[k], k);
    assert_true(m->nverts > 306);
    assert_float_equal(m->pos[0], 1.4, 0);
    assert_float_equal(m->pos[3 * 305 + 0], 1.425, 0);
    assert_float_equal(m->pos[3 * 305 + 1], -0.798, 0);
    /* faces: 64 per patch minus the quads a collapsed edge removes or makes
     * triangles; every face a quad or a triangle */
    assert_true(m->nfaces <= 32 * VX_BPT_TESS * VX_BPT_TESS);
    assert_int_equal(m->faces_by_size[2], 0);
    assert_true(m->faces_by_size[1] >= 28 * VX_BPT_TESS * VX_BPT_TESS);
    assert_int_equal(m->nonmanifold_edges, 0);
    assert_int_equal(m->degenerate_tris, 0);

    /* Shared edges: unshared, the 32 patches would leave 32*4*8 = 1024
     * boundary edges; sharing by control points (duplicates merged) leaves
     * the teapot's open seams: the lid's and the rim's edges, the handle's
     * and the spout's ends (16 patch sides). */
    assert_true(m->boundary_edges <= 16 * VX_BPT_TESS);

    /* Every tessellation vertex lies on its patch's Bézier surface, and the
     * body's normals point away from the z axis. */
    for (size_t p = 0; p < m->npatches; p++) {
        double c[3], du[3], dv[3], h = 1e-6, a[3], b[3];
        shape_bezier_eval(m, p, 0.5, 0.5, c);
        shape_bezier_eval(m, p, 0.5 + h, 0.5, a);
        shape_bezier_eval(m, p, 0.5 - h, 0.5, b);
        for (int k = 0; k < 3; k++)
            du[k] = a[k] - b[k];
        shape_bezier_eval(m, p, 0.5, 0.5 + h, a);
        shape_bezier_eval(m, p, 0.5, 0.5 - h, b);
        for (int k = 0; k < 3; k++)
            dv[k] = a[k] - b[k];
        double n[3] = {du[1] * dv[2] - du[2] * dv[1], du[2] * dv[0] - du[0] * dv[2],
                       du[0] * dv[1] - du[1] * dv[0]};
        if (p >= 4 && p < 12) assert_true(n[0] * c[0] + n[1] * c[1] > 0); /* body */
        if (p >= 28) assert_true(n[2] < 0);                               /* bottom */
        /* the patch's centre vertex (4, 4) is one of the mesh vertices */
        int found = 0;
        for (size_t v = 306; v < m->nverts && !found; v++)
            found = fabs(m->pos[3 * v] - c[0]) < 1e-12 && fabs(m->pos[3 * v + 1] - c[1]) < 1e-12 &&
                    fabs(m->pos[3 * v + 2] - c[2]) < 1e-12;
        assert_true(found);
    }
    vx_mesh_free(m);
}

static void test_sniff(void **state)
{
    (void)state;
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"32\n1,2,3", 8), VX_MESH_BPT);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"\n  7 \r\n1", 8), VX_MESH_BPT);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"12345", 5), VX_MESH_BPT);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"32 1\n", 5), VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"-3\n", 3), VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"v 1 2 3\n", 8), VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"# 3\nv 1 2 3\n", 12), VX_MESH_OBJ);
}

/* A flat single patch on z = 0, the grid (i, j) at (i, j, 0). */
static char *flat_patch(void)
{
    static char buf[1024];
    char *p = buf;
    p += sprintf(p, "1\n");
    for (int k = 1; k <= 16; k++)
        p += sprintf(p, "%d%s", k, k < 16 ? "," : "\n");
    p += sprintf(p, "16\n");
    for (int k = 0; k < 16; k++)
        p += sprintf(p, "%d.0, %d.0, 0\n", k % 4, k / 4);
    return buf;
}

static void test_flat(void **state)
{
    (void)state;
    vx_err err = {0};
    vx_mesh *m = read_str(flat_patch(), NULL, &err);
    if (!m) print_error("%s: %s\n", err.code, err.message);
    assert_non_null(m);
    assert_int_equal(m->npatches, 1);
    assert_int_equal(m->nfaces, VX_BPT_TESS * VX_BPT_TESS);
    assert_int_equal(m->faces_by_size[1], VX_BPT_TESS * VX_BPT_TESS);
    /* 16 points + (T+1)^2 - 4 corners (the corners are control points) */
    assert_int_equal(m->nverts, 16 + (VX_BPT_TESS + 1) * (VX_BPT_TESS + 1) - 4);
    assert_int_equal(m->boundary_edges, 4 * VX_BPT_TESS);
    assert_float_equal(m->bbox_max[0], 3, 0);
    /* a plane patch with a uniform net: vertex (a, b) at (3a/T, 3b/T) and
     * every quad's normal along +z (u along x, v along y) */
    for (size_t f = 0; f < m->nfaces; f++) {
        const uint32_t *q = vx_mesh_face(m, f);
        const double *a = m->pos + 3 * q[0], *b = m->pos + 3 * q[1], *c = m->pos + 3 * q[2];
        double z = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        assert_true(z > 0);
        assert_float_equal(fmod(a[0] * VX_BPT_TESS / 3 + 0.5, 1), 0.5, 1e-9);
    }
    vx_mesh_free(m);
}

/* Two flat patches side by side, x in [0, 3] and [3, 6]; the second writes
 * its own copies of the shared edge's points. */
static void test_duplicate_points(void **state)
{
    (void)state;
    char buf[2048], *p = buf;
    p += sprintf(p, "2\n");
    for (int k = 1; k <= 16; k++)
        p += sprintf(p, "%d%s", k, k < 16 ? "," : "\n");
    for (int k = 17; k <= 32; k++)
        p += sprintf(p, "%d%s", k, k < 32 ? "," : "\n");
    p += sprintf(p, "32\n");
    for (int q = 0; q < 2; q++)
        for (int k = 0; k < 16; k++)
            p += sprintf(p, "%d,%d,0\n", 3 * q + k % 4, k / 4);
    vx_err err = {0};
    vx_mesh *m = read_str(buf, NULL, &err);
    if (!m) print_error("%s: %s\n", err.code, err.message);
    assert_non_null(m);
    /* the second patch's first column is the first patch's last */
    for (int j = 0; j < 4; j++)
        assert_int_equal(m->patch_idx[16 + 4 * j], m->patch_idx[4 * j + 3]);
    /* one shared edge: the outline is 6 patch sides of VX_BPT_TESS edges */
    assert_int_equal(m->boundary_edges, 6 * VX_BPT_TESS);
    assert_int_equal(m->nfaces, 2 * VX_BPT_TESS * VX_BPT_TESS);
    vx_mesh_free(m);
}

static void expect_fail(const char *text, vx_err_kind kind, const char *code, int line)
{
    vx_err err = {0};
    vx_mesh *m = read_str(text, NULL, &err);
    if (m) print_error("accepted: %.80s\n", text);
    assert_null(m);
    if (strcmp(err.code, code)) print_error("%.60s: got %s (%s)\n", text, err.code, err.message);
    assert_string_equal(err.code, code);
    assert_int_equal(err.kind, kind);
    char prefix[32];
    snprintf(prefix, sizeof prefix, "line %d: ", line);
    if (strncmp(err.message, prefix, strlen(prefix)))
        print_error("%.60s: message %s, want %s\n", text, err.message, prefix);
    assert_int_equal(strncmp(err.message, prefix, strlen(prefix)), 0);
}

/* The flat patch with one line replaced. */
static const char *edit(int line, const char *with)
{
    static char out[2048];
    const char *src = flat_patch(), *p = src;
    char *o = out;
    for (int l = 1; *p; l++) {
        const char *nl = strchr(p, '\n');
        size_t len = nl ? (size_t)(nl - p + 1) : strlen(p);
        if (l == line)
            o += sprintf(o, "%s", with);
        else {
            memcpy(o, p, len);
            o += len;
        }
        p += len;
    }
    *o = 0;
    return out;
}

static void test_errors(void **state)
{
    (void)state;
    expect_fail("0\n16\n", VX_EINVAL, "bpt_count", 1);
    expect_fail(edit(2, "1,2,3,4,5,6,7,8,9,10,11,12,13,14,15\n"), VX_EINVAL, "bpt_junk", 2);
    expect_fail(edit(2, "1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,1\n"), VX_EINVAL, "bpt_junk", 2);
    expect_fail(edit(2, "1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,17\n"), VX_EINVAL, "bpt_index", 2);
    expect_fail(edit(2, "0,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n"), VX_EINVAL, "bpt_index", 2);
    expect_fail(edit(2, "1,,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n"), VX_EINVAL, "bpt_junk", 2);
    expect_fail(edit(2, "1,x,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n"), VX_EINVAL, "bpt_junk", 2);
    expect_fail(edit(3, "0\n"), VX_EINVAL, "bpt_count", 3);
    expect_fail(edit(5, "1.0, nan, 0\n"), VX_EINVAL, "bpt_nan", 5);
    expect_fail(edit(6, "1.0, inf, 0\n"), VX_EINVAL, "bpt_nan", 6);
    expect_fail(edit(7, "1.0, 2.0\n"), VX_EINVAL, "bpt_junk", 7);
    expect_fail(edit(7, "1.0, 2.0, 3,\n"), VX_EINVAL, "bpt_junk", 7);
    expect_fail(edit(7, "1.0, 2.0x, 3\n"), VX_EINVAL, "bpt_junk", 7);
    expect_fail(edit(19, "1,1,1\n1,1,1\n"), VX_EINVAL, "bpt_junk", 20);
    expect_fail(edit(19, ""), VX_EINVAL, "bpt_truncated", 19);
    /* the second patch line cannot fit in the bytes left: refused at the count */
    expect_fail("2\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n", VX_EINVAL, "bpt_truncated", 1);
    expect_fail("2\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n                               \n",
                VX_EINVAL, "bpt_truncated", 4);
    /* a patch count over the triangle limit fails before any allocation */
    vx_err err = {0};
    vx_mesh_limits lim = {.max_triangles = 100};
    assert_null(read_str(flat_patch(), &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    assert_int_equal(err.kind, VX_ETOOBIG);
    lim = (vx_mesh_limits){.max_vertices = 20};
    assert_null(read_str(flat_patch(), &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    /* counts past 2^40 are said so, not as a cut-off number */
    assert_null(read_str("99999999999999999999\n", NULL, &err));
    assert_string_equal(err.code, "mesh_too_big");
    assert_string_equal(err.message, "line 1: a patch count over 2^40 is over the limit");
    char *big = malloc(6000);
    memset(big, '1', 5000);
    strcpy(big + 5000, "\n");
    expect_fail(big, VX_EINVAL, "bpt_line_too_long", 1);
    free(big);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_teapot), cmocka_unit_test(test_sniff),
        cmocka_unit_test(test_flat),   cmocka_unit_test(test_duplicate_points),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
