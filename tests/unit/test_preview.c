/* The preview renderer against analytic answers: a cube seen face-on is a
 * centred square of known size and known Lambert shade. Also the PNG writer,
 * read back with libpng. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>
#include <png.h>

#include "gl/gl.h"
#include "image/png.h"
#include "preview/preview.h"
#include "shapes.h"

static vx_gl *g_gl;

static int setup(void **state)
{
    vx_err err = {0};
    vx_gl_desc d = {0};
    g_gl = vx_gl_new(&d, &err);
    if (!g_gl) fprintf(stderr, "vx_gl_new: %s: %s\n", err.code, err.message);
    return g_gl ? 0 : -1;
}

static int teardown(void **state)
{
    vx_gl_free(g_gl);
    return 0;
}

/* ---- meshes built by hand ---------------------------------------------- */

static const double cube_v[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                    {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
/* Outward-facing quads (counter-clockwise seen from outside). */
static const uint32_t cube_q[6][4] = {{4, 5, 6, 7}, {1, 0, 3, 2}, {5, 1, 2, 6},
                                      {0, 4, 7, 3}, {7, 6, 2, 3}, {0, 1, 5, 4}};

static vx_mesh *cube(int quads, double scale, double dx, double dy, double dz)
{
    vx_mesh *m = vx_mesh_new();
    assert_non_null(m);
    m->nverts = 8;
    m->pos = malloc(sizeof cube_v);
    for (int i = 0; i < 8; i++) {
        m->pos[3 * i] = cube_v[i][0] * scale + dx;
        m->pos[3 * i + 1] = cube_v[i][1] * scale + dy;
        m->pos[3 * i + 2] = cube_v[i][2] * scale + dz;
    }
    m->nfaces = quads ? 6 : 12;
    if (quads) {
        m->face_start = malloc(7 * sizeof(uint32_t));
        m->face_idx = malloc(24 * sizeof(uint32_t));
        for (int f = 0; f <= 6; f++)
            m->face_start[f] = 4u * (uint32_t)f;
        memcpy(m->face_idx, cube_q, sizeof cube_q);
    } else {
        m->face_idx = malloc(36 * sizeof(uint32_t));
        for (int f = 0; f < 6; f++) {
            const uint32_t *q = cube_q[f];
            uint32_t t[6] = {q[0], q[1], q[2], q[0], q[2], q[3]};
            memcpy(m->face_idx + 6 * f, t, sizeof t);
        }
    }
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    assert_int_equal(m->ntris, 12);
    return m;
}

/* A wavy height field of nx * ny quads (2 triangles each) in the XY plane. */
static vx_mesh *grid(int nx, int ny)
{
    vx_mesh *m = vx_mesh_new();
    assert_non_null(m);
    m->nverts = (size_t)(nx + 1) * (size_t)(ny + 1);
    m->nfaces = 2 * (size_t)nx * (size_t)ny;
    m->pos = malloc(m->nverts * 3 * sizeof(double));
    m->face_idx = malloc(m->nfaces * 3 * sizeof(uint32_t));
    assert_non_null(m->pos);
    assert_non_null(m->face_idx);
    for (int j = 0; j <= ny; j++)
        for (int i = 0; i <= nx; i++) {
            double *p = m->pos + 3 * ((size_t)j * (size_t)(nx + 1) + (size_t)i);
            double x = (double)i / nx, y = (double)j / ny;
            p[0] = 2 * x - 1;
            p[1] = 2 * y - 1;
            p[2] = 0.1 * sin(12 * x) * cos(9 * y);
        }
    uint32_t *t = m->face_idx;
    for (int j = 0; j < ny; j++)
        for (int i = 0; i < nx; i++) {
            uint32_t a = (uint32_t)(j * (nx + 1) + i), b = a + 1, c = a + (uint32_t)nx + 1,
                     d = c + 1;
            uint32_t q[6] = {a, b, d, a, d, c};
            memcpy(t, q, sizeof q);
            t += 6;
        }
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    return m;
}

/* ---- rendering helpers -------------------------------------------------- */

static vx_preview_params params(int w, int h, double az, double el, double fov)
{
    vx_preview_params p = {
        .azimuth_deg = az,
        .elevation_deg = el,
        .width = w,
        .height = h,
        .fov_deg = fov,
        .color = {0.8f, 0.6f, 0.4f},
        .background = {1, 1, 1, 1},
        .ambient = 0.2f,
        .samples = 4,
    };
    return p;
}

static uint8_t *render(const vx_mesh *m, const vx_preview_params *p, vx_preview_stats *st)
{
    uint8_t *rgba = malloc((size_t)p->width * (size_t)p->height * 4);
    assert_non_null(rgba);
    vx_err err = {0};
    vx_preview_stats local;
    if (!st) st = &local;
    int rc = vx_preview_render(g_gl, m, p, rgba, st, &err);
    if (rc) fprintf(stderr, "render: %s: %s\n", err.code, err.message);
    assert_int_equal(rc, 0);
    return rgba;
}

typedef struct box {
    int x0, y0, x1, y1; /* inclusive; x0 > x1 when empty */
    uint64_t covered;
} box;

static int is_bg(const uint8_t *px, const vx_preview_params *p)
{
    for (int k = 0; k < 4; k++)
        if (px[k] != (uint8_t)lrint(255.0 * p->background[k])) return 0;
    return 1;
}

static box bounds(const uint8_t *rgba, const vx_preview_params *p)
{
    box b = {p->width, p->height, -1, -1, 0};
    for (int y = 0; y < p->height; y++)
        for (int x = 0; x < p->width; x++) {
            if (is_bg(rgba + 4 * ((size_t)y * (size_t)p->width + (size_t)x), p)) continue;
            b.covered++;
            if (x < b.x0) b.x0 = x;
            if (x > b.x1) b.x1 = x;
            if (y < b.y0) b.y0 = y;
            if (y > b.y1) b.y1 = y;
        }
    return b;
}

static const uint8_t *pixel(const uint8_t *rgba, const vx_preview_params *p, int x, int y)
{
    return rgba + 4 * ((size_t)y * (size_t)p->width + (size_t)x);
}

/* The shade of a face whose normal points at the camera. */
static void expected_front(const vx_preview_params *p, uint8_t out[3])
{
    double lx = VX_PREVIEW_LIGHT_X, ly = VX_PREVIEW_LIGHT_Y, lz = VX_PREVIEW_LIGHT_Z;
    double ndotl = lz / sqrt(lx * lx + ly * ly + lz * lz);
    for (int k = 0; k < 3; k++)
        out[k] = (uint8_t)lrint(255.0 * p->color[k] * (p->ambient + (1 - p->ambient) * ndotl));
}

static void assert_centred_square(const uint8_t *rgba, const vx_preview_params *p, double side)
{
    box b = bounds(rgba, p);
    int w = b.x1 - b.x0 + 1, h = b.y1 - b.y0 + 1;
    printf("  bbox [%d,%d]-[%d,%d] size %dx%d expected %.1f covered %llu\n", b.x0, b.y0, b.x1, b.y1,
           w, h, side, (unsigned long long)b.covered);
    assert_true(fabs(0.5 * (b.x0 + b.x1) - 0.5 * (p->width - 1)) <= 2.0);
    assert_true(fabs(0.5 * (b.y0 + b.y1) - 0.5 * (p->height - 1)) <= 2.0);
    assert_true(fabs(w - side) <= 3.0);
    assert_true(fabs(h - side) <= 3.0);
    /* A square: nearly its whole bbox is covered. */
    assert_true((double)b.covered >= 0.97 * w * h);
    /* Corners are background, the centre is the lit front face. */
    assert_true(is_bg(pixel(rgba, p, 0, 0), p));
    assert_true(is_bg(pixel(rgba, p, p->width - 1, 0), p));
    assert_true(is_bg(pixel(rgba, p, 0, p->height - 1), p));
    assert_true(is_bg(pixel(rgba, p, p->width - 1, p->height - 1), p));
    const uint8_t *c = pixel(rgba, p, p->width / 2, p->height / 2);
    uint8_t want[3];
    expected_front(p, want);
    printf("  centre %d,%d,%d,%d expected %d,%d,%d\n", c[0], c[1], c[2], c[3], want[0], want[1],
           want[2]);
    for (int k = 0; k < 3; k++)
        assert_true(abs((int)c[k] - (int)want[k]) <= 2);
    assert_int_equal(c[3], 255);
}

/* ---- tests --------------------------------------------------------------- */

static void test_cube_ortho(void **state)
{
    vx_mesh *m = cube(0, 1, 0, 0, 0);
    vx_preview_params p = params(256, 256, 0, 0, 0);
    vx_preview_stats st;
    uint8_t *img = render(m, &p, &st);
    /* A sphere VX_PREVIEW_MARGIN times the bounding one spans the image;
     * the cube's side is 2/sqrt(3) of the bounding sphere's radius. */
    assert_centred_square(img, &p, 256.0 / sqrt(3.0) / VX_PREVIEW_MARGIN);
    box b = bounds(img, &p);
    assert_int_equal(st.pixels_covered, b.covered);
    assert_true(st.samples >= 1 && st.samples <= 4);
    printf("  gpu %.3f ms upload %.3f ms samples %d\n", st.gpu_ms, st.upload_ms, st.samples);
    free(img);
    vx_mesh_free(m);
}

static void test_cube_perspective(void **state)
{
    vx_mesh *m = cube(0, 1, 0, 0, 0);
    vx_preview_params p = params(256, 256, 0, 0, 30);
    uint8_t *img = render(m, &p, NULL);
    double half = 15 * M_PI / 180, dist = VX_PREVIEW_MARGIN / sin(half), s = 1 / sqrt(3.0);
    double side = 256.0 * (s / (dist - s)) / tan(half);
    assert_centred_square(img, &p, side);
    free(img);
    vx_mesh_free(m);
}

static void test_quad_cube_matches(void **state)
{
    vx_mesh *t = cube(0, 1, 0, 0, 0), *q = cube(1, 1, 0, 0, 0);
    assert_non_null(q->face_start);
    vx_preview_params p = params(256, 256, 0, 0, 0);
    uint8_t *a = render(t, &p, NULL);
    assert_centred_square(a, &p, 256.0 / sqrt(3.0) / VX_PREVIEW_MARGIN);
    p.fov_deg = 30;
    free(a);
    a = render(t, &p, NULL);
    uint8_t *b = render(q, &p, NULL);
    /* Same faces, other diagonals: the same picture up to rounding. */
    int maxd = 0;
    for (size_t i = 0; i < 256 * 256 * 4; i++) {
        int d = abs((int)a[i] - (int)b[i]);
        if (d > maxd) maxd = d;
    }
    printf("  max difference triangles vs quads: %d\n", maxd);
    assert_true(maxd <= 2);
    free(a);
    free(b);
    vx_mesh_free(t);
    vx_mesh_free(q);
}

static void test_azimuth_widens(void **state)
{
    vx_mesh *m = cube(0, 1, 0, 0, 0);
    vx_preview_params p = params(256, 256, 0, 0, 0);
    uint8_t *a = render(m, &p, NULL);
    p.azimuth_deg = 45;
    uint8_t *b = render(m, &p, NULL);
    box ba = bounds(a, &p), bb = bounds(b, &p);
    int wa = ba.x1 - ba.x0 + 1, wb = bb.x1 - bb.x0 + 1;
    printf("  width az0 %d az45 %d (expected ratio %.3f)\n", wa, wb, sqrt(2.0));
    assert_true(wb > wa);
    assert_true(fabs((double)wb / wa - sqrt(2.0)) < 0.03);
    /* Same height: the camera turned around the vertical axis only. */
    assert_true(abs((ba.y1 - ba.y0) - (bb.y1 - bb.y0)) <= 1);
    free(a);
    free(b);
    vx_mesh_free(m);
}

/* Azimuth and elevation turn the right way: a mesh whose +X half is a
 * different height shows it on the right at azimuth 0 and on the left at
 * 180; elevation looks down on the top. */
static void test_orientation(void **state)
{
    /* A triangle in the XY plane: tall on +X, short on -X. */
    vx_mesh *m = vx_mesh_new();
    m->nverts = 3;
    m->pos = malloc(9 * sizeof(double));
    const double v[9] = {-1, -0.2, 0, 1, -1, 0, 1, 1, 0};
    memcpy(m->pos, v, sizeof v);
    m->nfaces = 1;
    m->face_idx = malloc(3 * sizeof(uint32_t));
    m->face_idx[0] = 0;
    m->face_idx[1] = 1;
    m->face_idx[2] = 2;
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);

    vx_preview_params p = params(128, 128, 0, 0, 0);
    uint8_t *a = render(m, &p, NULL);
    /* Tall column near the right edge is covered near the top and bottom. */
    box ba = bounds(a, &p);
    int rx = ba.x1 - 3, lx = ba.x0 + 3;
    int right = 0, left = 0;
    for (int y = 0; y < 128; y++) {
        right += !is_bg(pixel(a, &p, rx, y), &p);
        left += !is_bg(pixel(a, &p, lx, y), &p);
    }
    printf("  azimuth 0: right column %d px, left column %d px\n", right, left);
    assert_true(right > 2 * left);
    free(a);

    p.azimuth_deg = 180; /* seen from behind: the tall side is on the left,
                          * and the back face is lit all the same */
    a = render(m, &p, NULL);
    ba = bounds(a, &p);
    rx = ba.x1 - 3, lx = ba.x0 + 3;
    right = left = 0;
    for (int y = 0; y < 128; y++) {
        right += !is_bg(pixel(a, &p, rx, y), &p);
        left += !is_bg(pixel(a, &p, lx, y), &p);
    }
    printf("  azimuth 180: right column %d px, left column %d px\n", right, left);
    assert_true(left > 2 * right);
    uint8_t want[3];
    expected_front(&p, want);
    const uint8_t *c = pixel(a, &p, (ba.x0 + ba.x1) / 2 - 10, 64);
    printf("  back face %d,%d,%d expected %d,%d,%d\n", c[0], c[1], c[2], want[0], want[1], want[2]);
    for (int k = 0; k < 3; k++)
        assert_true(abs((int)c[k] - (int)want[k]) <= 2);
    free(a);
    vx_mesh_free(m);

    /* Elevation: a flat square in the XZ plane is a thin line from the
     * side and a filled shape from 60 degrees above. */
    vx_mesh *c2 = cube(0, 1, 0, 0, 0);
    for (size_t i = 0; i < c2->nverts; i++)
        c2->pos[3 * i + 1] *= 0.05;
    assert_int_equal(vx_mesh_analyze(c2, &err), 0);
    p = params(128, 128, 0, 0, 0);
    a = render(c2, &p, NULL);
    box side = bounds(a, &p);
    free(a);
    p.elevation_deg = 60;
    a = render(c2, &p, NULL);
    box top = bounds(a, &p);
    /* From above the top face (lit by a headlight) faces the camera more. */
    printf("  slab height from the side %d, from 60 deg %d\n", side.y1 - side.y0, top.y1 - top.y0);
    assert_true(top.y1 - top.y0 > 4 * (side.y1 - side.y0));
    free(a);
    vx_mesh_free(c2);
}

static void test_off_centre(void **state)
{
    vx_mesh *m = cube(0, 1, 0, 0, 0), *t = cube(0, 1, 100, 0, 0),
            *far = cube(0, 1e-3, 1e7, -5e6, 3);
    vx_preview_params p = params(256, 256, 30, 20, 30);
    uint8_t *a = render(m, &p, NULL), *b = render(t, &p, NULL), *c = render(far, &p, NULL);
    /* Normalised in double: the translated cube gives the very same image. */
    assert_memory_equal(a, b, 256 * 256 * 4);
    box ba = bounds(a, &p), bc = bounds(c, &p);
    printf("  far, tiny cube bbox [%d,%d]-[%d,%d] vs [%d,%d]-[%d,%d]\n", bc.x0, bc.y0, bc.x1, bc.y1,
           ba.x0, ba.y0, ba.x1, ba.y1);
    assert_true(abs(ba.x0 - bc.x0) <= 1 && abs(ba.x1 - bc.x1) <= 1);
    assert_true(abs(ba.y0 - bc.y0) <= 1 && abs(ba.y1 - bc.y1) <= 1);
    free(a);
    free(b);
    free(c);
    vx_mesh_free(m);
    vx_mesh_free(t);
    vx_mesh_free(far);
}

/* fov 0 is the limit of a narrowing perspective: the same framing (the
 * orthographic picture had no margin: a sphere touched the edges, where
 * fov 1e-6 left 5%). */
static void test_ortho_limit(void **state)
{
    vx_mesh *m = cube(0, 1, 0, 0, 0);
    vx_preview_params p = params(256, 256, 30, 20, 0), q = params(256, 256, 30, 20, 1e-7);
    uint8_t *a = render(m, &p, NULL), *b = render(m, &q, NULL);
    box ba = bounds(a, &p), bb = bounds(b, &q);
    printf("  fov 0 [%d,%d]-[%d,%d], fov 1e-7 [%d,%d]-[%d,%d]\n", ba.x0, ba.y0, ba.x1, ba.y1, bb.x0,
           bb.y0, bb.x1, bb.y1);
    assert_true(abs(ba.x0 - bb.x0) <= 1 && abs(ba.x1 - bb.x1) <= 1);
    assert_true(abs(ba.y0 - bb.y0) <= 1 && abs(ba.y1 - bb.y1) <= 1);
    free(a);
    free(b);
    vx_mesh_free(m);
}

static void test_aspect_and_background(void **state)
{
    vx_mesh *m = cube(0, 1, 0, 0, 0);
    for (int fov = 0; fov <= 60; fov += 60) {
        /* Wide and tall images: the sphere fits the smaller dimension. */
        vx_preview_params p = params(320, 160, 0, 0, fov);
        p.background[0] = 0.1f;
        p.background[1] = 0.2f;
        p.background[2] = 0.3f;
        p.background[3] = 0.5f;
        p.samples = 1;
        uint8_t *a = render(m, &p, NULL);
        box b = bounds(a, &p);
        printf("  320x160 fov %d: [%d,%d]-[%d,%d]\n", fov, b.x0, b.y0, b.x1, b.y1);
        assert_true(fabs(0.5 * (b.x0 + b.x1) - 159.5) <= 2 &&
                    fabs(0.5 * (b.y0 + b.y1) - 79.5) <= 2);
        assert_true(abs((b.x1 - b.x0) - (b.y1 - b.y0)) <= 2); /* square pixels */
        assert_true(b.y0 > 0 && b.y1 < 159);
        const uint8_t *bg = pixel(a, &p, 0, 0);
        assert_int_equal(bg[0], 26);
        assert_int_equal(bg[3], 128);
        /* Without MSAA every pixel is background or the solid colour. */
        const uint8_t *c = pixel(a, &p, 160, 80);
        assert_int_equal(c[3], 255);
        free(a);

        p.width = 160;
        p.height = 320;
        a = render(m, &p, NULL);
        b = bounds(a, &p);
        assert_true(fabs(0.5 * (b.x0 + b.x1) - 79.5) <= 2 &&
                    fabs(0.5 * (b.y0 + b.y1) - 159.5) <= 2);
        assert_true(b.x0 > 0 && b.x1 < 159);
        free(a);
    }
    vx_mesh_free(m);
}

static void test_empty_and_bad(void **state)
{
    vx_mesh *m = vx_mesh_new();
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    vx_preview_params p = params(64, 64, 0, 0, 30);
    vx_preview_stats st;
    uint8_t *a = render(m, &p, &st);
    assert_int_equal(st.pixels_covered, 0);
    free(a);
    vx_mesh_free(m);

    m = cube(0, 1, 0, 0, 0);
    uint8_t buf[64 * 64 * 4];
    p.width = 0;
    assert_int_equal(vx_preview_render(g_gl, m, &p, buf, &st, &err), -1);
    assert_string_equal(err.code, "invalid_params");
    p.width = 64;
    m->tri[5] = 8; /* one past the last vertex */
    assert_int_equal(vx_preview_render(g_gl, m, &p, buf, &st, &err), -1);
    assert_string_equal(err.code, "mesh_invalid");
    m->tri[5] = 1;
    assert_int_equal(vx_preview_render(g_gl, m, &p, buf, &st, &err), 0);
    vx_mesh_free(m);
    assert_int_equal(vx_gl_check(g_gl, "test.after_preview", &err), 0);
}

/* ---- pieces and stops (the job time limit) -------------------------------- */

typedef struct poller {
    int calls, stop_at; /* stop_at 0 = never */
    double last;
} poller;

static int count_polls(void *ud, double fraction, vx_err *err)
{
    poller *q = ud;
    q->calls++;
    assert_true(fraction >= q->last && fraction <= 1);
    q->last = fraction;
    if (q->stop_at && q->calls >= q->stop_at)
        return vx_err_set(err, VX_ETIMEOUT, "job_timeout", "the job ran longer than 2 s");
    return 0;
}

/* Bands of rows and draws of VX_PREVIEW_CHUNK_TRIS triangles give the
 * picture one piece does; a poll that says stop ends the render cleanly
 * and the next render is as before. */
static void test_bands_and_stop(void **state)
{
    vx_mesh *m = grid(1000, 600); /* 1.2M triangles: two draws per band */
    assert_true(m->ntris > VX_PREVIEW_CHUNK_TRIS);
    vx_preview_params p = params(301, 203, 30, 20, 30);
    p.band_rows = 203;
    vx_preview_stats sa, sb;
    uint8_t *a = render(m, &p, &sa);
    poller q = {0};
    p.band_rows = 16; /* 13 bands, the last of 11 rows */
    p.poll = count_polls;
    p.poll_ud = &q;
    uint8_t *b = render(m, &p, &sb);
    printf("  one band: %llu covered; 13 bands: %llu covered, %d polls\n",
           (unsigned long long)sa.pixels_covered, (unsigned long long)sb.pixels_covered, q.calls);
    assert_true(q.calls >= 13 * 3); /* per band: between the draws, before the resolve, after */
    size_t differ = 0, n = (size_t)p.width * (size_t)p.height;
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 4; k++)
            if (abs((int)a[4 * i + k] - (int)b[4 * i + k]) > 2) {
                differ++;
                break;
            }
    printf("  %zu of %zu pixels differ\n", differ, n);
    assert_true(differ <= n / 1000);
    assert_true(llabs((long long)sa.pixels_covered - (long long)sb.pixels_covered) <=
                (long long)n / 1000);

    /* Stopped at the 8th poll: the poll's error, a clean GL state. */
    uint8_t *c = malloc(n * 4);
    assert_non_null(c);
    poller stop = {.stop_at = 8};
    p.poll_ud = &stop;
    vx_err err = {0};
    vx_preview_stats sc;
    assert_int_equal(vx_preview_render(g_gl, m, &p, c, &sc, &err), -1);
    assert_string_equal(err.code, "job_timeout");
    assert_int_equal(stop.calls, 8);
    assert_int_equal(vx_gl_check(g_gl, "test.after_stop", &err), 0);
    /* The same render again gives the same picture. */
    q = (poller){0};
    p.poll_ud = &q;
    assert_int_equal(vx_preview_render(g_gl, m, &p, c, &sc, &err), 0);
    assert_memory_equal(b, c, n * 4);
    assert_int_equal(sc.pixels_covered, sb.pixels_covered);
    free(a);
    free(b);
    free(c);
    vx_mesh_free(m);
}

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

static void test_million_triangles(void **state)
{
    vx_mesh *m = grid(1000, 500);
    assert_int_equal(m->ntris, 1000000);
    vx_preview_params p = params(512, 512, 30, 20, 30);
    vx_preview_stats st;
    double t0 = now_ms();
    uint8_t *a = render(m, &p, &st);
    double ms = now_ms() - t0;
    printf("  1M triangles 512x512: total %.1f ms, gpu %.1f ms, upload %.1f ms, covered %llu\n", ms,
           st.gpu_ms, st.upload_ms, (unsigned long long)st.pixels_covered);
    box b = bounds(a, &p);
    assert_true(b.covered > 512 * 512 / 10);
    assert_int_equal(st.pixels_covered, b.covered);
    free(a);
    vx_mesh_free(m);
}

/* A field of view of a thousandth of a degree puts the eye 1e5 radii away.
 * The picture is then all but orthographic: it must match one at 0.05
 * degrees (eye 2,400 radii away) to a few pixels, not show the depth
 * fighting and shading noise of float coordinates that large (the old
 * camera: 4,683 of 65,536 pixels off by more than 40 levels on spot). */
static void test_tiny_fov(void **state)
{
    (void)state;
    vx_mesh *m = shape_load("spot_triangulated.obj");
    assert_non_null(m);
    vx_preview_params p = params(256, 256, 30, 20, 0.001), q = params(256, 256, 30, 20, 0.05);
    uint8_t *a = render(m, &p, NULL), *b = render(m, &q, NULL);
    size_t off = 0;
    for (size_t i = 0; i < 256 * 256; i++) {
        int d = 0;
        for (int k = 0; k < 3; k++)
            d = fmax(d, abs((int)a[4 * i + k] - (int)b[4 * i + k]));
        off += d > 40;
    }
    box bb = bounds(a, &p);
    printf("  fov 0.001 vs 0.05: %zu pixels differ by more than 40 levels (covered %llu)\n", off,
           (unsigned long long)bb.covered);
    assert_true(bb.covered > 256 * 256 / 10);
    assert_true(off < 64);
    free(a);
    free(b);
    vx_mesh_free(m);
}

/* Fields of view under VX_PREVIEW_MIN_FOV draw as that one: the same
 * picture, bit for bit (the eye 1.2e8 radii away is orthographic to float
 * precision). A fov of 1e-15 put the projection's depth out of range and
 * 1e-300 made it infinite: an empty picture. */
static void test_fov_under_min(void **state)
{
    (void)state;
    vx_mesh *m = grid(8, 8);
    vx_preview_params p = params(64, 64, 30, 20, VX_PREVIEW_MIN_FOV);
    uint8_t *a = render(m, &p, NULL);
    box ba = bounds(a, &p);
    assert_true(ba.covered > 64 * 64 / 10);
    const double tiny[] = {1e-9, 1e-15, 1e-40, 1e-300, 5e-324};
    for (size_t k = 0; k < sizeof tiny / sizeof tiny[0]; k++) {
        vx_preview_params q = params(64, 64, 30, 20, tiny[k]);
        uint8_t *b = render(m, &q, NULL);
        box bb = bounds(b, &q);
        printf("  fov %g: covered %llu (%g: %llu)\n", tiny[k], (unsigned long long)bb.covered,
               VX_PREVIEW_MIN_FOV, (unsigned long long)ba.covered);
        assert_int_equal(bb.covered, ba.covered);
        assert_memory_equal(a, b, 64 * 64 * 4);
        free(b);
    }
    free(a);
    vx_mesh_free(m);
}

/* ---- PNG ------------------------------------------------------------------ */

/* Reads a PNG with libpng's classic API, 16-bit samples in host order. */
static void *read_png(const char *path, int *w, int *h, int *channels, int *depth)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    assert_int_equal(setjmp(png_jmpbuf(png)), 0);
    png_init_io(png, f);
    png_read_info(png, info);
    *w = (int)png_get_image_width(png, info);
    *h = (int)png_get_image_height(png, info);
    *channels = png_get_channels(png, info);
    *depth = png_get_bit_depth(png, info);
    const uint16_t probe = 1;
    if (*depth == 16 && *(const uint8_t *)&probe == 1) png_set_swap(png);
    png_read_update_info(png, info);
    size_t stride = png_get_rowbytes(png, info);
    uint8_t *px = malloc(stride * (size_t)*h);
    for (int y = 0; y < *h; y++)
        png_read_row(png, px + (size_t)y * stride, NULL);
    png_read_end(png, NULL);
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    return px;
}

static void test_png_roundtrip(void **state)
{
    vx_mesh *m = cube(0, 1, 0, 0, 0);
    vx_preview_params p = params(200, 120, 30, 20, 30);
    uint8_t *img = render(m, &p, NULL);
    char path[] = "/tmp/vx_test_png_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    vx_err err = {0};
    assert_int_equal(vx_png_write_path(path, img, 200, 120, 4, 8, &err), 0);
    int w, h, c, d;
    uint8_t *back = read_png(path, &w, &h, &c, &d);
    assert_int_equal(w, 200);
    assert_int_equal(h, 120);
    assert_int_equal(c, 4);
    assert_int_equal(d, 8);
    assert_memory_equal(back, img, 200 * 120 * 4);
    free(back);

    /* 16-bit grey + alpha: host-order samples survive (byte order swapped
     * on the way in and out). */
    uint16_t s16[7 * 5 * 2];
    for (int i = 0; i < 7 * 5 * 2; i++)
        s16[i] = (uint16_t)(i * 1031 + 0x0102);
    assert_int_equal(vx_png_write_path(path, s16, 7, 5, 2, 16, &err), 0);
    uint16_t *b16 = read_png(path, &w, &h, &c, &d);
    assert_int_equal(c, 2);
    assert_int_equal(d, 16);
    assert_memory_equal(b16, s16, sizeof s16);
    free(b16);

    /* 8-bit grey and RGB. */
    uint8_t g8[3 * 4 * 3];
    for (int i = 0; i < 36; i++)
        g8[i] = (uint8_t)(i * 7);
    for (int ch = 1; ch <= 3; ch += 2) {
        assert_int_equal(vx_png_write_path(path, g8, ch == 1 ? 9 : 3, 4, ch, 8, &err), 0);
        uint8_t *b8 = read_png(path, &w, &h, &c, &d);
        assert_int_equal(c, ch);
        assert_memory_equal(b8, g8, 36);
        free(b8);
    }
    unlink(path);

    /* Failure: a directory that does not exist. */
    assert_int_equal(vx_png_write_path("/nonexistent/dir/x.png", img, 200, 120, 4, 8, &err), -1);
    assert_int_equal(err.kind, VX_EIO);
    /* the message names the file, not the server's directories */
    assert_non_null(strstr(err.message, "x.png"));
    assert_null(strstr(err.message, "/nonexistent"));
    /* Full disk surfaces as an error too, not as a truncated file. */
    if (access("/dev/full", W_OK) == 0) {
        assert_int_equal(vx_png_write_path("/dev/full", img, 200, 120, 4, 8, &err), -1);
        assert_int_equal(err.kind, VX_EIO);
        assert_string_equal(err.code, "io_error");
        /* errno's words, not libpng's "Write Error" */
        assert_non_null(strstr(err.message, "No space left on device"));
        printf("  /dev/full: %s\n", err.message);
    }
    free(img);
    vx_mesh_free(m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cube_ortho),        cmocka_unit_test(test_cube_perspective),
        cmocka_unit_test(test_quad_cube_matches), cmocka_unit_test(test_azimuth_widens),
        cmocka_unit_test(test_orientation),       cmocka_unit_test(test_off_centre),
        cmocka_unit_test(test_ortho_limit),       cmocka_unit_test(test_aspect_and_background),
        cmocka_unit_test(test_empty_and_bad),     cmocka_unit_test(test_million_triangles),
        cmocka_unit_test(test_tiny_fov),          cmocka_unit_test(test_fov_under_min),
        cmocka_unit_test(test_bands_and_stop),    cmocka_unit_test(test_png_roundtrip),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
