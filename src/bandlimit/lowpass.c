/* Algorithm I (seed 002 §5.1): the low-pass filtered N^3 spectrum of a
 * solid sampled at R^3, computed slab by slab with separable partial
 * transforms so that no R^3 array ever exists. Per z slab: real FFTs of
 * the rows (keep kx < N/2), FFTs of the kept columns along y (keep |ky| <
 * N/2); then, over all slabs, FFTs along z of the R * N * N/2 kept values
 * (keep |kz| < N/2) and the filter. */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "bandlimit/bandlimit.h"
#include "bandlimit/fft_int.h"

static pthread_mutex_t plan_mu = PTHREAD_MUTEX_INITIALIZER;
static pthread_once_t threads_once = PTHREAD_ONCE_INIT;
static void init_threads(void) { fftwf_init_threads(); }

void vx_bl_plan_lock(int nthreads)
{
    pthread_once(&threads_once, init_threads);
    pthread_mutex_lock(&plan_mu);
    fftwf_plan_with_nthreads(nthreads < 1 ? 1 : nthreads);
}
void vx_bl_plan_unlock(void) { pthread_mutex_unlock(&plan_mu); }
void vx_bl_destroy_plan(fftwf_plan p)
{
    if (!p) return;
    pthread_mutex_lock(&plan_mu);
    fftwf_destroy_plan(p);
    pthread_mutex_unlock(&plan_mu);
}

void vx_bl_free(void *p) { fftwf_free(p); }

size_t vx_bl_spectrum_len(int N) { return (size_t)N * (size_t)N * (size_t)(N / 2); }

uint64_t vx_bl_lowpass_bytes(int R, int N)
{
    uint64_t nh = (uint64_t)N / 2, r = (uint64_t)R;
    return r * N * nh * 8             /* Z: all slabs' kept values */
           + r * r * 4                /* one slab of samples */
           + r * (r / 2 + 1) * 8      /* its row spectra */
           + r * nh * 8               /* kept columns */
           + (uint64_t)N * N * nh * 8; /* the result */
}

static int check_sizes(int R, int N, vx_err *err)
{
    if (N < 2 || N % 2 || R < N || R % 2)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "band-limit sizes: need even N >= 2 and even R >= N (R=%d, N=%d)", R, N);
    return 0;
}

/* Writes the kept (jz, jy, kx) value: src * H(k) / R^3, zero on the
 * Nyquist planes. */
static void keep(float *dst, const fftwf_complex src, int jz, int jy, int kx, int N, int R,
                 const vx_bl_filter *flt)
{
    if (jz == N / 2 || jy == N / 2) {
        dst[0] = dst[1] = 0;
        return;
    }
    double kz = vx_bl_freq(jz, N), ky = vx_bl_freq(jy, N);
    double d = sqrt(kz * kz + ky * ky + (double)kx * kx);
    double h = flt->d0 > 0 ? exp(-pow(d / flt->d0, flt->n)) : 1.0;
    double s = h / ((double)R * R * R);
    dst[0] = (float)(src[0] * s);
    dst[1] = (float)(src[1] * s);
}

/* Source index in an R-point FFT of kept index j of N. */
static int src_index(int j, int N, int R) { return j < N / 2 ? j : R - N + j; }

float *vx_bl_lowpass(int R, int N, const vx_bl_filter *flt, vx_bl_sample_fn sample, void *ud,
                     int nthreads, vx_bl_lowpass_stats *st, vx_err *err)
{
    if (check_sizes(R, N, err)) return NULL;
    const int nh = N / 2, rh = R / 2 + 1;
    float *plane = fftwf_malloc(sizeof(float) * (size_t)R * R);
    fftwf_complex *rows = fftwf_malloc(sizeof(fftwf_complex) * (size_t)R * rh);
    fftwf_complex *cols = fftwf_malloc(sizeof(fftwf_complex) * (size_t)R * nh);
    fftwf_complex *Z = fftwf_malloc(sizeof(fftwf_complex) * (size_t)R * N * nh);
    float *out = fftwf_malloc(sizeof(float) * 2 * vx_bl_spectrum_len(N));
    fftwf_plan prow = NULL, pcol = NULL, pz = NULL;
    double t_sample = 0, t0 = vx_bl_now_ms();
    if (!plane || !rows || !cols || !Z || !out) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the low-pass (R=%d, N=%d)", R,
                   N);
        goto fail;
    }
    vx_bl_plan_lock(1);
    /* rows: R real FFTs of length R per slab */
    prow = fftwf_plan_many_dft_r2c(1, &R, R, plane, NULL, 1, R, rows, NULL, 1, rh, FFTW_ESTIMATE);
    /* columns: nh complex FFTs of length R (stride nh) */
    pcol = fftwf_plan_many_dft(1, &R, nh, cols, NULL, nh, 1, cols, NULL, nh, 1, FFTW_FORWARD,
                               FFTW_ESTIMATE);
    vx_bl_plan_unlock();
    vx_bl_plan_lock(nthreads);
    /* depth: N * nh complex FFTs of length R, in place over all slabs */
    int howmany = N * nh;
    pz = fftwf_plan_many_dft(1, &R, howmany, Z, NULL, howmany, 1, Z, NULL, howmany, 1, FFTW_FORWARD,
                             FFTW_ESTIMATE);
    vx_bl_plan_unlock();
    if (!prow || !pcol || !pz) {
        vx_err_set(err, VX_EINTERNAL, "fft_plan", "FFTW could not plan the low-pass");
        goto fail;
    }
    for (int k = 0; k < R; k++) {
        double ts = vx_bl_now_ms();
        if (sample(ud, k, plane, err)) goto fail;
        t_sample += vx_bl_now_ms() - ts;
        fftwf_execute(prow);
        for (int y = 0; y < R; y++)
            memcpy(cols + (size_t)y * nh, rows + (size_t)y * rh, sizeof(fftwf_complex) * nh);
        fftwf_execute(pcol);
        fftwf_complex *zk = Z + (size_t)k * howmany;
        for (int jy = 0; jy < N; jy++)
            memcpy(zk + (size_t)jy * nh, cols + (size_t)src_index(jy, N, R) * nh,
                   sizeof(fftwf_complex) * nh);
    }
    fftwf_execute(pz);
    for (int jz = 0; jz < N; jz++) {
        const fftwf_complex *zs = Z + (size_t)src_index(jz, N, R) * howmany;
        for (int jy = 0; jy < N; jy++)
            for (int kx = 0; kx < nh; kx++) {
                size_t o = ((size_t)jz * N + jy) * nh + kx;
                keep(out + 2 * o, zs[(size_t)jy * nh + kx], jz, jy, kx, N, R, flt);
            }
    }
    if (st) {
        st->peak_bytes = vx_bl_lowpass_bytes(R, N);
        st->sample_ms = t_sample;
        st->ms = vx_bl_now_ms() - t0 - t_sample;
    }
    vx_bl_destroy_plan(prow);
    vx_bl_destroy_plan(pcol);
    vx_bl_destroy_plan(pz);
    fftwf_free(plane);
    fftwf_free(rows);
    fftwf_free(cols);
    fftwf_free(Z);
    return out;
fail:
    vx_bl_destroy_plan(prow);
    vx_bl_destroy_plan(pcol);
    vx_bl_destroy_plan(pz);
    fftwf_free(plane);
    fftwf_free(rows);
    fftwf_free(cols);
    fftwf_free(Z);
    fftwf_free(out);
    return NULL;
}

float *vx_bl_lowpass_full(int R, int N, const vx_bl_filter *flt, vx_bl_sample_fn sample, void *ud,
                          int nthreads, vx_bl_lowpass_stats *st, vx_err *err)
{
    if (check_sizes(R, N, err)) return NULL;
    const int nh = N / 2, rh = R / 2 + 1;
    size_t rr = (size_t)R * R;
    float *vol = fftwf_malloc(sizeof(float) * rr * R);
    fftwf_complex *F = fftwf_malloc(sizeof(fftwf_complex) * rr * rh);
    float *out = fftwf_malloc(sizeof(float) * 2 * vx_bl_spectrum_len(N));
    fftwf_plan p = NULL;
    double t_sample = 0, t0 = vx_bl_now_ms();
    if (!vol || !F || !out) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the full FFT (R=%d)", R);
        goto fail;
    }
    vx_bl_plan_lock(nthreads);
    p = fftwf_plan_dft_r2c_3d(R, R, R, vol, F, FFTW_ESTIMATE);
    vx_bl_plan_unlock();
    if (!p) {
        vx_err_set(err, VX_EINTERNAL, "fft_plan", "FFTW could not plan the full FFT");
        goto fail;
    }
    for (int k = 0; k < R; k++) {
        double ts = vx_bl_now_ms();
        if (sample(ud, k, vol + (size_t)k * rr, err)) goto fail;
        t_sample += vx_bl_now_ms() - ts;
    }
    fftwf_execute(p);
    for (int jz = 0; jz < N; jz++)
        for (int jy = 0; jy < N; jy++)
            for (int kx = 0; kx < nh; kx++) {
                size_t o = ((size_t)jz * N + jy) * nh + kx;
                size_t s = ((size_t)src_index(jz, N, R) * R + src_index(jy, N, R)) * rh + kx;
                keep(out + 2 * o, F[s], jz, jy, kx, N, R, flt);
            }
    if (st) {
        st->peak_bytes = sizeof(float) * rr * R + sizeof(fftwf_complex) * rr * rh +
                         sizeof(float) * 2 * vx_bl_spectrum_len(N);
        st->sample_ms = t_sample;
        st->ms = vx_bl_now_ms() - t0 - t_sample;
    }
    vx_bl_destroy_plan(p);
    fftwf_free(vol);
    fftwf_free(F);
    return out;
fail:
    vx_bl_destroy_plan(p);
    fftwf_free(vol);
    fftwf_free(F);
    fftwf_free(out);
    return NULL;
}
