/* Band-limited interpolation by zero padding (seed 002 appendix), plane by
 * plane: the N^3 half spectrum is padded along z to M and transformed back
 * along z (M * N * N/2 complex values, the only 3-D complex array); then
 * each output plane is padded along y, transformed along y, and brought to
 * M^2 real samples by one complex-to-real FFT per row. The gradient comes
 * from the same transforms of the spectrum times j 2 pi k / P: x after the
 * y transform (kx is still per column), y and z before theirs. */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "bandlimit/bandlimit.h"
#include "bandlimit/fft_int.h"
#include "util/par.h"
#include "util/stop.h"

uint64_t vx_bl_volume_bytes(int M, int with_grad)
{
    uint64_t m3 = (uint64_t)M * M * M;
    return m3 * 4 * (with_grad ? 4 : 1);
}

void vx_bl_volume_free(vx_bl_volume *v)
{
    if (!v) return;
    free(v->f);
    for (int a = 0; a < 3; a++)
        free(v->g[a]);
    free(v->bmax);
    free(v->blip);
    memset(v, 0, sizeof *v);
}

typedef struct interp_ctx {
    int N, M, nh, mh, with_grad;
    double w;                     /* 2 pi / P */
    const fftwf_complex *A, *Agz; /* [M][N][nh] after the z transform */
    fftwf_plan py, prow;
    vx_bl_volume *v;
    int next; /* next plane to do (under mu) */
    pthread_mutex_t mu;
    int failed;
    int stop; /* the calling thread's stop hook (util/stop.h) said stop */
    vx_err err;
} interp_ctx;

/* Y (M x mh, zeroed) <- plane (N x nh) padded along y, times j w ky when
 * mul_ky. */
static void pad_y(const interp_ctx *c, const fftwf_complex *plane, int mul_ky, fftwf_complex *Y)
{
    memset(Y, 0, sizeof(fftwf_complex) * (size_t)c->M * c->mh);
    for (int jy = 0; jy < c->N; jy++) {
        if (jy == c->N / 2) continue;
        int ky = vx_bl_freq(jy, c->N), my = ky >= 0 ? ky : c->M + ky;
        const fftwf_complex *s = plane + (size_t)jy * c->nh;
        fftwf_complex *d = Y + (size_t)my * c->mh;
        for (int kx = 0; kx < c->nh; kx++) {
            if (mul_ky) {
                double f = c->w * ky;
                d[kx][0] = (float)(-s[kx][1] * f);
                d[kx][1] = (float)(s[kx][0] * f);
            } else {
                d[kx][0] = s[kx][0];
                d[kx][1] = s[kx][1];
            }
        }
    }
}

/* rows of Y -> M x M reals at dst (through the aligned scratch out). */
static void rows_to(const interp_ctx *c, fftwf_complex *Y, float *out, float *dst)
{
    fftwf_execute_dft_c2r(c->prow, Y, out);
    memcpy(dst, out, sizeof(float) * (size_t)c->M * c->M);
}

static void *interp_worker(void *arg)
{
    interp_ctx *c = arg;
    size_t ysz = (size_t)c->M * c->mh, m2 = (size_t)c->M * c->M;
    fftwf_complex *Yf = fftwf_malloc(sizeof(fftwf_complex) * ysz);
    fftwf_complex *W = fftwf_malloc(sizeof(fftwf_complex) * ysz);
    float *out = fftwf_malloc(sizeof(float) * m2);
    if (!Yf || !W || !out) {
        pthread_mutex_lock(&c->mu);
        c->failed = 1;
        pthread_mutex_unlock(&c->mu);
        goto done;
    }
    for (;;) {
        /* Only the calling thread has a hook; it stops the helpers too. */
        vx_err e;
        int stop = vx_stop_poll(&e);
        pthread_mutex_lock(&c->mu);
        if (stop && !c->stop) {
            c->stop = 1;
            c->err = e;
        }
        int m = c->failed || c->stop ? c->M : c->next++;
        pthread_mutex_unlock(&c->mu);
        if (m >= c->M) break;
        size_t pl = (size_t)c->N * c->nh;
        const fftwf_complex *a = c->A + (size_t)m * pl;
        pad_y(c, a, 0, Yf);
        fftwf_execute_dft(c->py, Yf, Yf);
        if (c->with_grad) {
            /* x: j w kx per column of the y-transformed plane */
            memset(W, 0, sizeof(fftwf_complex) * ysz);
            for (int y = 0; y < c->M; y++)
                for (int kx = 1; kx < c->nh; kx++) {
                    const float *s = Yf[(size_t)y * c->mh + kx];
                    double f = c->w * kx;
                    W[(size_t)y * c->mh + kx][0] = (float)(-s[1] * f);
                    W[(size_t)y * c->mh + kx][1] = (float)(s[0] * f);
                }
            rows_to(c, W, out, c->v->g[0] + (size_t)m * m2);
            pad_y(c, a, 1, W);
            fftwf_execute_dft(c->py, W, W);
            rows_to(c, W, out, c->v->g[1] + (size_t)m * m2);
            pad_y(c, c->Agz + (size_t)m * pl, 0, W);
            fftwf_execute_dft(c->py, W, W);
            rows_to(c, W, out, c->v->g[2] + (size_t)m * m2);
        }
        rows_to(c, Yf, out, c->v->f + (size_t)m * m2);
    }
done:
    fftwf_free(Yf);
    fftwf_free(W);
    fftwf_free(out);
    return NULL;
}

int vx_bl_interp(const float *spec, int N, int M, const double x0[3], double P, int with_grad,
                 int nthreads, vx_bl_volume *v, vx_err *err)
{
    memset(v, 0, sizeof *v);
    if (N < 2 || N % 2 || M < N || M % 2 || !(P > 0))
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "interpolation: need even N >= 2, even M >= N (N=%d, M=%d)", N, M);
    const int nh = N / 2, mh = M / 2 + 1, howmany = N * nh;
    size_t m3 = (size_t)M * M * M, acount = (size_t)M * howmany;
    interp_ctx c = {
        .N = N, .M = M, .nh = nh, .mh = mh, .with_grad = with_grad, .w = 2 * M_PI / P, .v = v};
    pthread_mutex_init(&c.mu, NULL);
    fftwf_complex *A = fftwf_malloc(sizeof(fftwf_complex) * acount);
    fftwf_complex *Agz = with_grad ? fftwf_malloc(sizeof(fftwf_complex) * acount) : NULL;
    fftwf_complex *Y = fftwf_malloc(sizeof(fftwf_complex) * (size_t)M * mh);
    float *out = fftwf_malloc(sizeof(float) * (size_t)M * M);
    fftwf_plan pz = NULL;
    int rc = -1;
    v->M = M;
    v->h = P / M;
    for (int a = 0; a < 3; a++)
        v->origin[a] = x0[a];
    v->f = malloc(sizeof(float) * m3);
    for (int a = 0; with_grad && a < 3; a++)
        v->g[a] = malloc(sizeof(float) * m3);
    if (!A || (with_grad && !Agz) || !Y || !out || !v->f ||
        (with_grad && (!v->g[0] || !v->g[1] || !v->g[2]))) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to interpolate to M=%d", M);
        goto out;
    }
    /* Planned before A is filled: measuring scribbles on it. */
    vx_bl_plan_lock(nthreads);
    pz = fftwf_plan_many_dft(1, &M, howmany, A, NULL, howmany, 1, A, NULL, howmany, 1,
                             FFTW_BACKWARD, vx_bl_plan_flags());
    vx_bl_plan_unlock();
    vx_bl_plan_lock(1);
    c.py = fftwf_plan_many_dft(1, &M, nh, Y, NULL, mh, 1, Y, NULL, mh, 1, FFTW_BACKWARD,
                               vx_bl_plan_flags());
    c.prow = fftwf_plan_many_dft_c2r(1, &M, M, Y, NULL, 1, mh, out, NULL, 1, M, vx_bl_plan_flags());
    vx_bl_plan_unlock();
    if (!pz || !c.py || !c.prow) {
        vx_err_set(err, VX_EINTERNAL, "fft_plan", "FFTW could not plan the interpolation");
        goto out;
    }
    /* pad along z (and the z derivative) */
    memset(A, 0, sizeof(fftwf_complex) * acount);
    if (Agz) memset(Agz, 0, sizeof(fftwf_complex) * acount);
    const fftwf_complex *S = (const fftwf_complex *)spec;
    for (int jz = 0; jz < N; jz++) {
        if (jz == N / 2) continue;
        int kz = vx_bl_freq(jz, N), mz = kz >= 0 ? kz : M + kz;
        for (int i = 0; i < howmany; i++) {
            const float *s = S[(size_t)jz * howmany + i];
            float *d = A[(size_t)mz * howmany + i];
            d[0] = s[0];
            d[1] = s[1];
            if (Agz) {
                double f = c.w * kz;
                float *g = Agz[(size_t)mz * howmany + i];
                g[0] = (float)(-s[1] * f);
                g[1] = (float)(s[0] * f);
            }
        }
    }
    fftwf_execute_dft(pz, A, A);
    if (Agz) fftwf_execute_dft(pz, Agz, Agz);
    c.A = A;
    c.Agz = Agz;
    vx_par_run(nthreads, interp_worker, &c);
    if (c.failed) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for interpolation planes");
        goto out;
    }
    if (c.stop) {
        if (err) *err = c.err;
        goto out;
    }
    rc = 0;
out:
    vx_bl_destroy_plan(pz);
    vx_bl_destroy_plan(c.py);
    vx_bl_destroy_plan(c.prow);
    fftwf_free(A);
    fftwf_free(Agz);
    fftwf_free(Y);
    fftwf_free(out);
    pthread_mutex_destroy(&c.mu);
    if (rc) vx_bl_volume_free(v);
    return rc;
}

double vx_bl_eval(const float *spec, int N, const double x0[3], double P, const double x[3],
                  double grad[3])
{
    const int nh = N / 2;
    double w = 2 * M_PI / P, t[3], f = 0, g[3] = {0, 0, 0};
    for (int a = 0; a < 3; a++)
        t[a] = (x[a] - x0[a]) * w;
    for (int jz = 0; jz < N; jz++)
        for (int jy = 0; jy < N; jy++)
            for (int kx = 0; kx < nh; kx++) {
                size_t o = ((size_t)jz * N + jy) * nh + kx;
                double re = spec[2 * o], im = spec[2 * o + 1];
                if (re == 0 && im == 0) continue;
                int k[3] = {kx, vx_bl_freq(jy, N), vx_bl_freq(jz, N)};
                double th = k[0] * t[0] + k[1] * t[1] + k[2] * t[2];
                double c = cos(th), s = sin(th), mult = kx ? 2 : 1;
                /* Re(c e^{j th}) and Re(c j w k e^{j th}) */
                double vr = re * c - im * s, vi = re * s + im * c;
                f += mult * vr;
                for (int a = 0; a < 3; a++)
                    g[a] += mult * (-vi) * w * k[a];
            }
    if (grad)
        for (int a = 0; a < 3; a++)
            grad[a] = g[a];
    return f;
}

/* Inside one cell the trilinear interpolant's partial derivative along an
 * axis is a blend of that axis's four edge differences, so sqrt(3) times
 * the largest |edge difference| / h over the block's cells bounds its
 * gradient there. */
int vx_bl_volume_blocks(vx_bl_volume *v, vx_err *err)
{
    const int M = v->M, nb = (M - 1 + 7) / 8;
    free(v->bmax);
    free(v->blip);
    size_t nblk = (size_t)nb * nb * nb;
    v->bmax = malloc(sizeof(float) * nblk);
    v->blip = malloc(sizeof(float) * nblk);
    if (!v->bmax || !v->blip)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for blocks");
    v->nb = nb;
    for (int bz = 0; bz < nb; bz++) {
        if (vx_stop_poll(err)) return -1;
        for (int by = 0; by < nb; by++)
            for (int bx = 0; bx < nb; bx++) {
                float mx = -INFINITY, md = 0;
                int z1 = bz * 8 + 8 < M ? bz * 8 + 8 : M - 1,
                    y1 = by * 8 + 8 < M ? by * 8 + 8 : M - 1,
                    x1 = bx * 8 + 8 < M ? bx * 8 + 8 : M - 1;
                for (int z = bz * 8; z <= z1; z++)
                    for (int y = by * 8; y <= y1; y++) {
                        const float *row = v->f + ((size_t)z * M + y) * M;
                        for (int x = bx * 8; x <= x1; x++) {
                            if (row[x] > mx) mx = row[x];
                            if (x < x1) md = fmaxf(md, fabsf(row[x + 1] - row[x]));
                            if (y < y1) md = fmaxf(md, fabsf(row[x + M] - row[x]));
                            if (z < z1) md = fmaxf(md, fabsf(row[x + (size_t)M * M] - row[x]));
                        }
                    }
                size_t b = ((size_t)bz * nb + by) * nb + bx;
                v->bmax[b] = mx;
                v->blip[b] = (float)(sqrt(3.0) * md / v->h);
            }
    }
    return 0;
}

double vx_bl_volume_sample(const vx_bl_volume *v, const double x[3], double grad[3])
{
    const int M = v->M;
    int i0[3];
    double fr[3];
    for (int a = 0; a < 3; a++) {
        double u = (x[a] - v->origin[a]) / v->h;
        if (u < 0) u = 0;
        if (u > M - 1) u = M - 1;
        int i = (int)u;
        if (i > M - 2) i = M - 2;
        i0[a] = i;
        fr[a] = u - i;
    }
    size_t base = ((size_t)i0[2] * M + i0[1]) * M + i0[0];
    size_t off[8];
    double w[8];
    for (int c = 0; c < 8; c++) {
        int dx = c & 1, dy = (c >> 1) & 1, dz = c >> 2;
        off[c] = base + ((size_t)dz * M + dy) * M + dx;
        w[c] = (dx ? fr[0] : 1 - fr[0]) * (dy ? fr[1] : 1 - fr[1]) * (dz ? fr[2] : 1 - fr[2]);
    }
    double f = 0;
    for (int c = 0; c < 8; c++)
        f += w[c] * v->f[off[c]];
    if (grad && v->g[0])
        for (int a = 0; a < 3; a++) {
            double s = 0;
            for (int c = 0; c < 8; c++)
                s += w[c] * v->g[a][off[c]];
            grad[a] = s;
        }
    return f;
}
