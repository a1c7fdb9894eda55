/* The band-limit module (seed 002) against independent answers: Algorithm
 * I against one full 3-D FFT of the same samples; the mean kept; the peak
 * memory at R = 512, N = 128 measured (VmHWM) as well as reported; the
 * zero-padded interpolation and spectral gradient against closed-form
 * trigonometric fields and against exact evaluation; trilinear lookups at
 * L = 4 within 2% of exact evaluation; the caster's hits and normals on a
 * band-limited ball against the analytic sphere, and the older methods
 * worse than the spectral one. No GL: the solids are sampled analytically. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "bandlimit/bandlimit.h"

/* An off-centre ellipsoid plus a box: no symmetry the FFTs could hide
 * errors behind. Coordinates in samples of an R grid. */
typedef struct solid {
    int R;
    double c[3], ax[3]; /* ellipsoid centre and semi-axes (fractions of R) */
    int no_box;
} solid;

static int inside(const solid *s, double x, double y, double z)
{
    double u = (x - s->c[0]) / s->ax[0], v = (y - s->c[1]) / s->ax[1], w = (z - s->c[2]) / s->ax[2];
    if (u * u + v * v + w * w <= 1) return 1;
    return !s->no_box && x > 0.15 && x < 0.4 && y > 0.55 && y < 0.8 && z > 0.2 && z < 0.7;
}

static int sample_solid(void *ud, int k, float *plane, vx_err *err)
{
    const solid *s = ud;
    const int R = s->R;
    for (int j = 0; j < R; j++)
        for (int i = 0; i < R; i++)
            plane[(size_t)j * R + i] =
                (float)inside(s, (i + 0.5) / R, (j + 0.5) / R, (k + 0.5) / R);
    return 0;
}

static long vm_hwm_kb(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long kb = -1;
    while (f && fgets(line, sizeof line, f))
        if (sscanf(line, "VmHWM: %ld kB", &kb) == 1) break;
    if (f) fclose(f);
    return kb;
}

/* First in the group, so the process peak is this test's. */
static void test_peak_memory_512_128(void **st)
{
    solid s = {512, {0.45, 0.5, 0.52}, {0.3, 0.25, 0.2}, 0};
    vx_bl_filter flt = {128 / 4.0, 2};
    vx_bl_lowpass_stats ls;
    vx_err err = {0};
    long before = vm_hwm_kb();
    float *spec = vx_bl_lowpass(512, 128, &flt, sample_solid, &s, 2, &ls, &err);
    assert_non_null(spec);
    long after = vm_hwm_kb();
    print_message("R=512 N=128: reported %.1f MB, VmHWM %ld -> %ld kB, fft %.0f ms\n",
                  ls.peak_bytes / 1048576.0, before, after, ls.ms);
    assert_true(ls.peak_bytes < 128ull << 20);
    assert_true(after > 0 && after < 128 * 1024);
    /* an R^3 float array alone would be 512 MB */
    assert_true(ls.peak_bytes < 512ull * 512 * 512 * 4 / 8);
    vx_bl_free(spec);
}

static void compare_full(int R, int N, double d0, double n)
{
    solid s = {R, {0.45, 0.5, 0.52}, {0.3, 0.25, 0.2}, 0};
    vx_bl_filter flt = {d0, n};
    vx_err err = {0};
    float *a = vx_bl_lowpass(R, N, &flt, sample_solid, &s, 2, NULL, &err);
    float *b = vx_bl_lowpass_full(R, N, &flt, sample_solid, &s, 2, NULL, &err);
    assert_non_null(a);
    assert_non_null(b);
    double maxd = 0, maxv = 0;
    for (size_t i = 0; i < 2 * vx_bl_spectrum_len(N); i++) {
        double d = fabs((double)a[i] - b[i]);
        if (d > maxd) maxd = d;
        if (fabs(b[i]) > maxv) maxv = fabs(b[i]);
    }
    print_message("R=%d N=%d: max |partial - full| = %.3g (max |c| %.3g)\n", R, N, maxd, maxv);
    assert_true(maxv > 0.01);
    assert_true(maxd <= 1e-5);
    /* the mean: c_0 = the average of the samples (H(0) = 1) */
    float *plane = malloc(sizeof(float) * (size_t)R * R);
    double sum = 0;
    for (int k = 0; k < R; k++) {
        sample_solid(&s, k, plane, &err);
        for (size_t i = 0; i < (size_t)R * R; i++)
            sum += plane[i];
    }
    double mean = sum / ((double)R * R * R);
    assert_true(mean > 0.01);
    assert_true(fabs(a[0] - mean) <= 1e-6);
    assert_true(fabs(a[1]) <= 1e-6);
    free(plane);
    vx_bl_free(a);
    vx_bl_free(b);
}

/* Both FFT paths against a direct double-precision DFT (small sizes). */
static void test_algorithm1_equals_direct_dft(void **st)
{
    const int R = 16, N = 6;
    solid s = {R, {0.45, 0.5, 0.52}, {0.3, 0.25, 0.2}, 0};
    vx_bl_filter flt = {2.5, 2};
    vx_err err = {0};
    float *a = vx_bl_lowpass(R, N, &flt, sample_solid, &s, 1, NULL, &err);
    assert_non_null(a);
    float *vol = malloc(sizeof(float) * R * R * R);
    for (int k = 0; k < R; k++)
        sample_solid(&s, k, vol + (size_t)k * R * R, &err);
    double maxd = 0;
    for (int jz = 0; jz < N; jz++)
        for (int jy = 0; jy < N; jy++)
            for (int kx = 0; kx < N / 2; kx++) {
                int kz = jz < N / 2 ? jz : jz - N, ky = jy < N / 2 ? jy : jy - N;
                double re = 0, im = 0;
                if (jz != N / 2 && jy != N / 2) {
                    for (int z = 0; z < R; z++)
                        for (int y = 0; y < R; y++)
                            for (int x = 0; x < R; x++) {
                                double th = -2 * M_PI * ((double)kx * x + ky * y + kz * z) / R;
                                double f = vol[((size_t)z * R + y) * R + x];
                                re += f * cos(th);
                                im += f * sin(th);
                            }
                    double hh = exp(-(kx * kx + ky * ky + kz * kz) / (2.5 * 2.5)) / (R * R * R);
                    re *= hh;
                    im *= hh;
                }
                size_t o = ((size_t)jz * N + jy) * (N / 2) + kx;
                maxd = fmax(maxd, fmax(fabs(re - a[2 * o]), fabs(im - a[2 * o + 1])));
            }
    print_message("R=%d N=%d: max |partial - direct DFT| = %.3g\n", R, N, maxd);
    assert_true(maxd <= 1e-6);
    free(vol);
    vx_bl_free(a);
}

static void test_algorithm1_equals_full_fft(void **st)
{
    compare_full(32, 8, 2, 2);
    compare_full(48, 12, 3, 2);
    compare_full(64, 16, 1e6, 2); /* no filter: a pure box cut */
    compare_full(40, 40, 10, 4);  /* N = R */
}

static void test_bad_sizes(void **st)
{
    solid s = {32, {0.5, 0.5, 0.5}, {0.3, 0.3, 0.3}, 0};
    vx_bl_filter flt = {2, 2};
    vx_err err = {0};
    assert_null(vx_bl_lowpass(16, 32, &flt, sample_solid, &s, 1, NULL, &err));
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_null(vx_bl_lowpass(32, 7, &flt, sample_solid, &s, 1, NULL, &err));
}

/* A spectrum with a few set coefficients; its field is a sum of cosines. */
typedef struct wave {
    int k[3];
    double re, im;
} wave;

static float *make_spec(int N, const wave *w, int nw)
{
    float *s = calloc(2 * vx_bl_spectrum_len(N), sizeof(float));
    for (int i = 0; i < nw; i++) {
        int jy = w[i].k[1] < 0 ? w[i].k[1] + N : w[i].k[1],
            jz = w[i].k[2] < 0 ? w[i].k[2] + N : w[i].k[2];
        size_t o = ((size_t)jz * N + jy) * (N / 2) + w[i].k[0];
        s[2 * o] = (float)w[i].re;
        s[2 * o + 1] = (float)w[i].im;
    }
    return s;
}

/* f(x) = sum over waves of m Re(c e^{j w k.(x - x0)}), m = 2 for kx > 0 */
static double wave_field(const wave *w, int nw, double P, const double x0[3], const double x[3],
                         double g[3])
{
    double f = 0, om = 2 * M_PI / P;
    g[0] = g[1] = g[2] = 0;
    for (int i = 0; i < nw; i++) {
        double th = 0;
        for (int a = 0; a < 3; a++)
            th += om * w[i].k[a] * (x[a] - x0[a]);
        double m = w[i].k[0] ? 2 : 1;
        f += m * (w[i].re * cos(th) - w[i].im * sin(th));
        for (int a = 0; a < 3; a++)
            g[a] += m * -(w[i].re * sin(th) + w[i].im * cos(th)) * om * w[i].k[a];
    }
    return f;
}

static void test_interp_closed_form(void **st)
{
    const int N = 8, M = 24;
    const double P = 3.0, x0[3] = {-1.2, 0.3, 2.0};
    wave w[] = {{{0, 0, 0}, 0.25, 0},
                {{1, 2, -3}, 0.1, -0.05},
                {{3, -1, 0}, 0.02, 0.07},
                {{0, 3, 1}, -0.04, 0.01}};
    int nw = 4;
    /* kx = 0 entries need their conjugate partner to stay real */
    float *spec = make_spec(N, w, nw);
    {
        int jy = N - 3, jz = N - 1; /* (0, -3, -1) = conj of (0, 3, 1) */
        size_t o = ((size_t)jz * N + jy) * (N / 2);
        spec[2 * o] = -0.04f;
        spec[2 * o + 1] = -0.01f;
    }
    wave w2[5];
    memcpy(w2, w, sizeof w);
    w2[4] = (wave){{0, -3, -1}, -0.04, -0.01};
    /* the kx = 0 pair counts once each (m = 1) */
    vx_bl_volume v;
    vx_err err = {0};
    assert_int_equal(vx_bl_interp(spec, N, M, x0, P, 1, 2, &v, &err), 0);
    double maxf = 0, maxg = 0, maxe = 0;
    for (int z = 0; z < M; z += 3)
        for (int y = 0; y < M; y += 2)
            for (int x = 0; x < M; x++) {
                double p[3] = {x0[0] + x * P / M, x0[1] + y * P / M, x0[2] + z * P / M}, g[3],
                       ge[3];
                double f = wave_field(w2, 5, P, x0, p, g);
                size_t i = ((size_t)z * M + y) * M + x;
                maxf = fmax(maxf, fabs(f - v.f[i]));
                for (int a = 0; a < 3; a++)
                    maxg = fmax(maxg, fabs(g[a] - v.g[a][i]));
                double fe = vx_bl_eval(spec, N, x0, P, p, ge);
                maxe = fmax(maxe, fabs(fe - f));
                for (int a = 0; a < 3; a++)
                    maxe = fmax(maxe, fabs(ge[a] - g[a]));
            }
    print_message("closed form: max err f %.2g, grad %.2g, eval %.2g\n", maxf, maxg, maxe);
    assert_true(maxf < 1e-5);
    assert_true(maxg < 1e-4);
    assert_true(maxe < 1e-6);
    vx_bl_volume_free(&v);
    free(spec);
}

/* A band-limited ball: radius 0.3 of a unit box, centre off the grid. */
static float *ball(int R, int N, double d0, solid *s)
{
    *s = (solid){R, {0.503, 0.497, 0.51}, {0.3, 0.3, 0.3}, 1};
    vx_bl_filter flt = {d0, 2};
    vx_err err = {0};
    float *spec = vx_bl_lowpass(R, N, &flt, sample_solid, s, 2, NULL, &err);
    assert_non_null(spec);
    return spec;
}

static void test_trilinear_l4_within_2_percent(void **st)
{
    const int N = 32, R = 256;
    solid s;
    float *spec = ball(R, N, N / 4.0, &s);
    double x0[3] = {0.5 / R, 0.5 / R, 0.5 / R};
    vx_bl_volume v;
    vx_err err = {0};
    assert_int_equal(vx_bl_interp(spec, N, 4 * N, x0, 1.0, 1, 2, &v, &err), 0);
    /* points near the surface, where the render samples */
    double maxf = 0, maxang = 0, fmaxv = 0;
    unsigned seed = 7;
    for (int i = 0; i < 400; i++) {
        double d[3], n = 0;
        for (int a = 0; a < 3; a++) {
            d[a] = rand_r(&seed) / (double)RAND_MAX - 0.5;
            n += d[a] * d[a];
        }
        n = sqrt(n);
        double r = 0.3 + 0.02 * (rand_r(&seed) / (double)RAND_MAX - 0.5), p[3], ge[3], gt[3];
        for (int a = 0; a < 3; a++)
            p[a] = s.c[a] + r * d[a] / n;
        double fe = vx_bl_eval(spec, N, x0, 1.0, p, ge);
        double ft = vx_bl_volume_sample(&v, p, gt);
        maxf = fmax(maxf, fabs(fe - ft));
        fmaxv = fmax(fmaxv, fe);
        double dot = 0, ne = 0, nt = 0;
        for (int a = 0; a < 3; a++) {
            dot += ge[a] * gt[a];
            ne += ge[a] * ge[a];
            nt += gt[a] * gt[a];
        }
        double ang = acos(fmin(1, dot / sqrt(ne * nt))) * 180 / M_PI;
        maxang = fmax(maxang, ang);
    }
    print_message("L=4 trilinear vs exact: max |df| %.3g (max f %.3g), max normal angle %.3g deg\n",
                  maxf, fmaxv, maxang);
    assert_true(maxf <= 0.02 * 1.0); /* 2% of the solid's density */
    vx_bl_volume_free(&v);
    vx_bl_free(spec);
}

/* Mean angle between rendered and analytic sphere normals. */
static double sphere_error(const vx_bl_hits *h, const double c[3], double *maxr, double *minr,
                           size_t *nhit)
{
    double sum = 0;
    size_t n = 0;
    *maxr = 0;
    *minr = 1e9;
    for (size_t i = 0; i < (size_t)h->width * h->height; i++) {
        if (isnan(h->depth[i])) continue;
        double d[3], r = 0, dot = 0;
        for (int a = 0; a < 3; a++) {
            d[a] = h->pos[3 * i + a] - c[a];
            r += d[a] * d[a];
        }
        r = sqrt(r);
        for (int a = 0; a < 3; a++)
            dot += h->nrm[3 * i + a] * d[a] / r;
        sum += acos(fmin(1, dot)) * 180 / M_PI;
        *maxr = fmax(*maxr, r);
        *minr = fmin(*minr, r);
        n++;
    }
    *nhit = n;
    return n ? sum / n : 1e9;
}

static void test_cast_ball_and_methods(void **st)
{
    const int N = 32, R = 256, W = 96;
    solid s;
    float *spec = ball(R, N, N / 4.0, &s);
    double x0[3] = {0.5 / R, 0.5 / R, 0.5 / R};
    vx_bl_volume vm, vn;
    vx_err err = {0};
    assert_int_equal(vx_bl_interp(spec, N, 4 * N, x0, 1.0, 1, 2, &vm, &err), 0);
    assert_int_equal(vx_bl_volume_blocks(&vm, &err), 0);
    assert_int_equal(vx_bl_interp(spec, N, N, x0, 1.0, 0, 2, &vn, &err), 0);
    assert_int_equal(vx_bl_volume_blocks(&vn, &err), 0);
    assert_int_equal(vx_bl_voxel_gradient(&vn, VX_BL_CENTRAL, &err), 0);
    vx_bl_camera cam = {.eye = {0.5, 0.5, 3},
                        .fwd = {0, 0, -1},
                        .right = {1, 0, 0},
                        .up = {0, 1, 0},
                        .ortho = 1,
                        .ortho_height = 0.8};
    vx_bl_hits h;
    assert_int_equal(vx_bl_hits_alloc(&h, W, W, &err), 0);
    assert_int_equal(vx_bl_cast(&vm, 0.5, &cam, 2, &h, &err), 0);
    double maxr, minr, spectral, cd, cross, sob2;
    size_t n;
    spectral = sphere_error(&h, s.c, &maxr, &minr, &n);
    print_message("spectral: mean %.4f deg, r in [%.4f, %.4f], %zu hits\n", spectral, minr, maxr,
                  n);
    /* the disc of radius 0.3 in a 0.8-wide view: pi 0.3^2 / 0.64 of the pixels */
    double want = M_PI * 0.09 / 0.64 * W * W;
    assert_true(fabs(n - want) < 0.03 * want);
    assert_true(fabs(maxr - 0.3) < 0.01 && fabs(minr - 0.3) < 0.01);
    assert_true(spectral < 0.3);
    /* perspective camera sees the same ball */
    vx_bl_camera pc = cam;
    pc.ortho = 0;
    pc.fov_deg = 20;
    assert_int_equal(vx_bl_cast(&vm, 0.5, &pc, 2, &h, &err), 0);
    double sp2 = sphere_error(&h, s.c, &maxr, &minr, &n);
    assert_true(n > 100 && sp2 < 0.3 && fabs(maxr - 0.3) < 0.01);
    /* the older methods on the N voxels */
    assert_int_equal(vx_bl_cast(&vn, 0.5, &cam, 2, &h, &err), 0);
    cd = sphere_error(&h, s.c, &maxr, &minr, &n);
    vx_bl_screen_normals(&h, &cam, VX_BL_CROSS_MASK);
    cross = sphere_error(&h, s.c, &maxr, &minr, &n);
    vx_bl_screen_normals(&h, &cam, VX_BL_SOBEL2D);
    sob2 = sphere_error(&h, s.c, &maxr, &minr, &n);
    print_message("central %.3f, cross-mask %.3f, sobel2d %.3f deg\n", cd, cross, sob2);
    assert_true(cd > 3 * spectral);
    assert_true(cross > spectral && sob2 > spectral);
    vx_bl_screen_normals(&h, &cam, VX_BL_DEPTH_ONLY);
    for (size_t i = 0; i < (size_t)W * W; i++)
        if (!isnan(h.depth[i])) assert_true(h.nrm[3 * i + 2] == 1.0f);
    vx_bl_hits_free(&h);
    vx_bl_volume_free(&vm);
    vx_bl_volume_free(&vn);
    vx_bl_free(spec);
}

/* A camera whose eye is not a finite point (a fitted eye for a fov of
 * 1e-300 on a mesh of 1e30 was at infinity, NaN across the view axis):
 * every ray misses. Its NaN positions were read as grid indices off the
 * volume (SIGSEGV). */
static void test_cast_eye_not_finite(void **st)
{
    (void)st;
    const int N = 8, R = 64, W = 8;
    solid s;
    float *spec = ball(R, N, N / 4.0, &s);
    double x0[3] = {0.5 / R, 0.5 / R, 0.5 / R};
    vx_bl_volume vm;
    vx_err err = {0};
    assert_int_equal(vx_bl_interp(spec, N, 4 * N, x0, 1.0, 1, 2, &vm, &err), 0);
    assert_int_equal(vx_bl_volume_blocks(&vm, &err), 0);
    const double eyes[][3] = {
        {NAN, NAN, INFINITY}, {0.5, 0.5, INFINITY}, {INFINITY, 0.5, 0.5}, {NAN, 0.5, 0.5}};
    vx_bl_hits h;
    assert_int_equal(vx_bl_hits_alloc(&h, W, W, &err), 0);
    for (size_t k = 0; k < sizeof eyes / sizeof eyes[0]; k++)
        for (int ortho = 0; ortho < 2; ortho++) {
            vx_bl_camera cam = {.eye = {eyes[k][0], eyes[k][1], eyes[k][2]},
                                .fwd = {0, 0, -1},
                                .right = {1, 0, 0},
                                .up = {0, 1, 0},
                                .ortho = ortho,
                                .ortho_height = 0.8,
                                .fov_deg = 1e-300};
            assert_int_equal(vx_bl_cast(&vm, 0.5, &cam, 2, &h, &err), 0);
            for (size_t i = 0; i < (size_t)W * W; i++)
                assert_true(isnan(h.depth[i]));
        }
    vx_bl_hits_free(&h);
    vx_bl_volume_free(&vm);
    vx_bl_free(spec);
}

static void test_sobel3d_and_label(void **st)
{
    /* a linear ramp f = 2 x: both operators give (2, 0, 0) away from the wrap */
    vx_bl_volume v = {.M = 8, .h = 0.5};
    v.f = malloc(sizeof(float) * 512);
    for (int i = 0; i < 512; i++)
        v.f[i] = (float)(2 * (i % 8) * 0.5);
    vx_err err = {0};
    for (int m = 0; m < 2; m++) {
        assert_int_equal(vx_bl_voxel_gradient(&v, m ? VX_BL_SOBEL3D : VX_BL_CENTRAL, &err), 0);
        size_t i = (3 * 8 + 4) * 8 + 3;
        assert_float_equal(v.g[0][i], 2, 1e-6);
        assert_float_equal(v.g[1][i], 0, 1e-6);
        assert_float_equal(v.g[2][i], 0, 1e-6);
    }
    vx_bl_volume_free(&v);
    float img[3 * 64 * 16] = {0}, c[3] = {1, 1, 1};
    vx_bl_label(img, 64, 16, 1, 1, 1, "sobel3d", c);
    int lit = 0;
    for (int i = 0; i < 3 * 64 * 16; i++)
        lit += img[i] > 0;
    assert_true(lit > 3 * 40);
    assert_string_equal(vx_bl_normals_names[VX_BL_SOBEL3D], "sobel3d");
}

/* Bit grids as samples: two solids sum; bits past R in a row's last word
 * (padding) are ignored. */
static void test_sample_bits(void **st)
{
    const int R = 40;
    vx_grid gr = {.origin = {0, 0, 0}, .h = 1, .dims = {R, R, R}};
    vx_bitgrid g[2];
    vx_err err = {0};
    for (int m = 0; m < 2; m++)
        assert_int_equal(vx_bitgrid_alloc(&g[m], &gr, 0, &err), 0);
    size_t words = g[0].wx * R * R;
    for (size_t i = 0; i < words; i++) {
        g[0].bits[i] = 0xffffffffu; /* padding bits set too */
        g[1].bits[i] = (i % g[1].wx) == 0 ? 0x1u : 0;
    }
    vx_bl_bits bits = {g, 2, NULL, NULL};
    float *plane = malloc(sizeof(float) * R * R);
    assert_int_equal(vx_bl_sample_bits(&bits, 7, plane, &err), 0);
    for (int y = 0; y < R; y++)
        for (int x = 0; x < R; x++)
            assert_float_equal(plane[y * R + x], x == 0 ? 2 : 1, 0);
    free(plane);
    for (int m = 0; m < 2; m++)
        vx_bitgrid_free(&g[m]);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_peak_memory_512_128),
        cmocka_unit_test(test_algorithm1_equals_full_fft),
        cmocka_unit_test(test_algorithm1_equals_direct_dft),
        cmocka_unit_test(test_bad_sizes),
        cmocka_unit_test(test_interp_closed_form),
        cmocka_unit_test(test_trilinear_l4_within_2_percent),
        cmocka_unit_test(test_cast_ball_and_methods),
        cmocka_unit_test(test_cast_eye_not_finite),
        cmocka_unit_test(test_sobel3d_and_label),
        cmocka_unit_test(test_sample_bits),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
