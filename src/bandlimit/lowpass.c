/* Algorithm I (seed 002 §5.1): the low-pass filtered N^3 spectrum of a
 * solid sampled at R^3, computed slab by slab with separable partial
 * transforms so that no R^3 array ever exists. Per z slab: real FFTs of
 * the rows (keep kx < N/2), FFTs of the kept columns along y (keep |ky| <
 * N/2); then, over all slabs, FFTs along z of the R * N * N/2 kept values
 * (keep |kz| < N/2) and the filter. */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bandlimit/bandlimit.h"
#include "bandlimit/fft_int.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/par.h"

static pthread_mutex_t plan_mu = PTHREAD_MUTEX_INITIALIZER;
static pthread_once_t threads_once = PTHREAD_ONCE_INIT;
static void init_threads(void)
{
    fftwf_init_threads();
}

/* Wisdom kept in a file (vx_bl_wisdom_dir); all under plan_mu. */
static char wisdom_path[1100];
static char *wisdom_saved; /* what the file holds, to save only news */

void vx_bl_wisdom_dir(const char *dir)
{
    pthread_once(&threads_once, init_threads);
    pthread_mutex_lock(&plan_mu);
    char path[sizeof wisdom_path] = "";
    if (dir && dir[0]) snprintf(path, sizeof path, "%s/fftw3f.wisdom", dir);
    if (strcmp(path, wisdom_path) != 0) {
        snprintf(wisdom_path, sizeof wisdom_path, "%s", path);
        free(wisdom_saved);
        wisdom_saved = NULL;
        /* A missing or unreadable file is no wisdom yet; FFTW checks the
         * rest (it rejects wisdom from another FFTW build). */
        if (path[0] && fftwf_import_wisdom_from_filename(path))
            wisdom_saved = fftwf_export_wisdom_to_string();
    }
    pthread_mutex_unlock(&plan_mu);
}

static _Thread_local double plan_seconds; /* 0: no limit */

void vx_bl_plan_time_limit(double seconds)
{
    plan_seconds = seconds > 0 ? seconds : 0;
}

unsigned vx_bl_plan_flags(void)
{
    fftwf_set_timelimit(plan_seconds > 0 ? plan_seconds : FFTW_NO_TIMELIMIT);
    return wisdom_path[0] ? FFTW_MEASURE : FFTW_ESTIMATE;
}

/* Writes the wisdom when it changed: to a temporary file, renamed over the
 * old one, so a crash leaves the old or the new file, never half of one. */
static void save_wisdom(void)
{
    if (!wisdom_path[0]) return;
    char *now = fftwf_export_wisdom_to_string();
    if (!now || (wisdom_saved && strcmp(now, wisdom_saved) == 0)) {
        free(now);
        return;
    }
    char tmp[sizeof wisdom_path + 16];
    snprintf(tmp, sizeof tmp, "%s.tmp", wisdom_path);
    FILE *f = fopen(tmp, "w");
    int ok = f && fputs(now, f) >= 0;
    if (f && fclose(f)) ok = 0;
    if (ok && rename(tmp, wisdom_path) == 0) {
        free(wisdom_saved);
        wisdom_saved = now;
        VX_INFO("fftw.wisdom_saved", "path=%s bytes=%zu", VX_Q(wisdom_path), strlen(now));
        return;
    }
    unlink(tmp);
    VX_WARN("fftw.wisdom_not_saved", "path=%s", VX_Q(wisdom_path));
    free(now);
}

void vx_bl_plan_lock(int nthreads)
{
    pthread_once(&threads_once, init_threads);
    pthread_mutex_lock(&plan_mu);
    fftwf_plan_with_nthreads(nthreads < 1 ? 1 : nthreads);
}
void vx_bl_plan_unlock(void)
{
    save_wisdom();
    pthread_mutex_unlock(&plan_mu);
}
void vx_bl_destroy_plan(fftwf_plan p)
{
    if (!p) return;
    pthread_mutex_lock(&plan_mu);
    fftwf_destroy_plan(p);
    pthread_mutex_unlock(&plan_mu);
}

void vx_bl_free(void *p)
{
    fftwf_free(p);
}

size_t vx_bl_spectrum_len(int N)
{
    return (size_t)N * (size_t)N * (size_t)(N / 2);
}

uint64_t vx_bl_lowpass_bytes(int R, int N)
{
    uint64_t nh = (uint64_t)N / 2, r = (uint64_t)R;
    return r * N * nh * 8              /* Z: all slabs' kept values */
           + r * r * 4                 /* one slab of samples (per worker) */
           + (r / 2 + 1) * 8           /* a row spectrum */
           + r * nh * 8                /* kept columns (per worker) */
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
static int src_index(int j, int N, int R)
{
    return j < N / 2 ? j : R - N + j;
}

/* One slab worker: samples slab k (sampling is serialised: the callback
 * need not be reentrant), transforms its non-empty rows and the kept
 * columns, and stores the kept values into Z[k]. Slabs are handed out in
 * order; empty rows and slabs (the padding) cost no FFT. */
typedef struct slab_ctx {
    int R, N;
    vx_bl_sample_fn sample;
    void *ud;
    fftwf_plan prow, pcol; /* one row (unaligned), the nh columns */
    fftwf_complex *Z;
    pthread_mutex_t mu;
    int next, failed;
    vx_err err;
    double sample_ms;
} slab_ctx;

static void *slab_worker(void *arg)
{
    slab_ctx *c = arg;
    const int R = c->R, N = c->N, nh = N / 2, rh = R / 2 + 1;
    float *plane = fftwf_malloc(sizeof(float) * (size_t)R * R);
    fftwf_complex *rows = fftwf_malloc(sizeof(fftwf_complex) * rh);
    fftwf_complex *cols = fftwf_malloc(sizeof(fftwf_complex) * (size_t)R * nh);
    for (;;) {
        pthread_mutex_lock(&c->mu);
        int k = c->failed ? R : c->next++;
        if (k < R && (!plane || !rows || !cols)) {
            c->failed = 1;
            vx_err_set(&c->err, VX_EINTERNAL, "out_of_memory", "no memory for a slab");
            k = R;
        }
        if (k < R) {
            double t = vx_mono_ms();
            if (c->sample(c->ud, k, plane, &c->err)) {
                c->failed = 1;
                k = R;
            }
            c->sample_ms += vx_mono_ms() - t;
        }
        pthread_mutex_unlock(&c->mu);
        if (k >= R) break;
        int any = 0;
        for (int y = 0; y < R; y++) {
            const float *row = plane + (size_t)y * R;
            int nz = 0;
            for (int x = 0; x < R && !nz; x++)
                nz = row[x] != 0;
            if (!nz) {
                memset(cols + (size_t)y * nh, 0, sizeof(fftwf_complex) * nh);
                continue;
            }
            any = 1;
            fftwf_execute_dft_r2c(c->prow, (float *)row, rows);
            memcpy(cols + (size_t)y * nh, rows, sizeof(fftwf_complex) * nh);
        }
        fftwf_complex *zk = c->Z + (size_t)k * N * nh;
        if (!any) {
            memset(zk, 0, sizeof(fftwf_complex) * (size_t)N * nh);
            continue;
        }
        fftwf_execute_dft(c->pcol, cols, cols);
        for (int jy = 0; jy < N; jy++)
            memcpy(zk + (size_t)jy * nh, cols + (size_t)src_index(jy, N, R) * nh,
                   sizeof(fftwf_complex) * nh);
    }
    fftwf_free(plane);
    fftwf_free(rows);
    fftwf_free(cols);
    return NULL;
}

/* The depth pass: blocks of ZB columns (jy, kx) are gathered from Z into
 * contiguous rows, transformed along z, and only their N kept outputs are
 * filtered into the result (no R-long write-back, contiguous FFTs). */
#define ZB 16
typedef struct zpass_ctx {
    int R, N;
    const vx_bl_filter *flt;
    const fftwf_complex *Z;
    float *out;
    fftwf_plan p; /* ZB contiguous FFTs of length R */
    pthread_mutex_t mu;
    int next, nblocks, failed;
} zpass_ctx;

static void *zpass_worker(void *arg)
{
    zpass_ctx *c = arg;
    const int R = c->R, N = c->N, nh = N / 2, cols = N * nh;
    fftwf_complex *buf = fftwf_malloc(sizeof(fftwf_complex) * (size_t)ZB * R);
    for (;;) {
        pthread_mutex_lock(&c->mu);
        int blk = buf && !c->failed ? c->next++ : c->nblocks;
        if (!buf) c->failed = 1;
        pthread_mutex_unlock(&c->mu);
        if (blk >= c->nblocks) break;
        int c0 = blk * ZB, nb = cols - c0 < ZB ? cols - c0 : ZB;
        memset(buf, 0, sizeof(fftwf_complex) * (size_t)ZB * R);
        for (int k = 0; k < R; k++) {
            const fftwf_complex *zr = c->Z + (size_t)k * cols + c0;
            for (int b = 0; b < nb; b++) {
                buf[(size_t)b * R + k][0] = zr[b][0];
                buf[(size_t)b * R + k][1] = zr[b][1];
            }
        }
        fftwf_execute_dft(c->p, buf, buf);
        for (int b = 0; b < nb; b++) {
            int col = c0 + b, jy = col / nh, kx = col % nh;
            for (int jz = 0; jz < N; jz++) {
                size_t o = ((size_t)jz * N + jy) * nh + kx;
                keep(c->out + 2 * o, buf[(size_t)b * R + src_index(jz, N, R)], jz, jy, kx, N, R,
                     c->flt);
            }
        }
    }
    fftwf_free(buf);
    return NULL;
}

float *vx_bl_lowpass(int R, int N, const vx_bl_filter *flt, vx_bl_sample_fn sample, void *ud,
                     int nthreads, vx_bl_lowpass_stats *st, vx_err *err)
{
    if (check_sizes(R, N, err)) return NULL;
    const int nh = N / 2, rh = R / 2 + 1, howmany = N * nh;
    const int nt = nthreads < 1 ? 1 : nthreads > 16 ? 16 : nthreads;
    slab_ctx c = {.R = R, .N = N, .sample = sample, .ud = ud};
    pthread_mutex_init(&c.mu, NULL);
    /* scratch for planning only (workers bring their own) */
    float *plane = fftwf_malloc(sizeof(float) * R);
    fftwf_complex *rows = fftwf_malloc(sizeof(fftwf_complex) * rh);
    fftwf_complex *cols = fftwf_malloc(sizeof(fftwf_complex) * (size_t)R * nh);
    c.Z = fftwf_malloc(sizeof(fftwf_complex) * (size_t)R * howmany);
    float *out = fftwf_malloc(sizeof(float) * 2 * vx_bl_spectrum_len(N));
    fftwf_plan pz = NULL;
    fftwf_complex *zbuf = NULL;
    int ok = 0;
    double t0 = vx_mono_ms();
    if (!plane || !rows || !cols || !c.Z || !out) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the low-pass (R=%d, N=%d)", R,
                   N);
        goto fail;
    }
    vx_bl_plan_lock(1);
    /* rows start at any float of the plane: an unaligned plan */
    c.prow = fftwf_plan_dft_r2c_1d(R, plane, rows, vx_bl_plan_flags() | FFTW_UNALIGNED);
    c.pcol = fftwf_plan_many_dft(1, &R, nh, cols, NULL, nh, 1, cols, NULL, nh, 1, FFTW_FORWARD,
                                 vx_bl_plan_flags());
    vx_bl_plan_unlock();
    zbuf = fftwf_malloc(sizeof(fftwf_complex) * (size_t)ZB * R);
    vx_bl_plan_lock(1);
    /* depth: ZB contiguous complex FFTs of length R per block */
    if (zbuf)
        pz = fftwf_plan_many_dft(1, &R, ZB, zbuf, NULL, 1, R, zbuf, NULL, 1, R, FFTW_FORWARD,
                                 vx_bl_plan_flags());
    vx_bl_plan_unlock();
    if (!c.prow || !c.pcol || !pz) {
        vx_err_set(err, VX_EINTERNAL, "fft_plan", "FFTW could not plan the low-pass");
        goto fail;
    }
    vx_par_run(nt, slab_worker, &c);
    if (c.failed) {
        if (err) *err = c.err;
        goto fail;
    }
    zpass_ctx zc = {.R = R,
                    .N = N,
                    .flt = flt,
                    .Z = c.Z,
                    .out = out,
                    .p = pz,
                    .nblocks = (howmany + ZB - 1) / ZB};
    pthread_mutex_init(&zc.mu, NULL);
    vx_par_run(nt, zpass_worker, &zc);
    pthread_mutex_destroy(&zc.mu);
    if (zc.failed) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the depth pass");
        goto fail;
    }
    if (st) {
        st->peak_bytes = vx_bl_lowpass_bytes(R, N) +
                         (uint64_t)(nt - 1) * ((uint64_t)R * R * 4 + (uint64_t)R * nh * 8) +
                         (uint64_t)(nt + 1) * ZB * R * 8;
        st->sample_ms = c.sample_ms;
        st->ms = vx_mono_ms() - t0 - c.sample_ms;
    }
    ok = 1;
fail:
    vx_bl_destroy_plan(c.prow);
    vx_bl_destroy_plan(c.pcol);
    vx_bl_destroy_plan(pz);
    fftwf_free(zbuf);
    fftwf_free(plane);
    fftwf_free(rows);
    fftwf_free(cols);
    fftwf_free(c.Z);
    if (!ok) {
        fftwf_free(out);
        out = NULL;
    }
    pthread_mutex_destroy(&c.mu);
    return out;
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
    double t_sample = 0, t0 = vx_mono_ms();
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
        double ts = vx_mono_ms();
        if (sample(ud, k, vol + (size_t)k * rr, err)) goto fail;
        t_sample += vx_mono_ms() - ts;
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
        st->ms = vx_mono_ms() - t0 - t_sample;
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

int vx_bl_sample_bits(void *bits, int k, float *plane, vx_err *err)
{
    const vx_bl_bits *b = bits;
    const int R = b->grids[0].grid.dims[0];
    memset(plane, 0, sizeof(float) * (size_t)R * R);
    for (int m = 0; m < b->n; m++) {
        const vx_bitgrid *g = &b->grids[m];
        for (int y = 0; y < R; y++) {
            const uint32_t *w = g->bits + ((size_t)k * R + y) * g->wx;
            float *row = plane + (size_t)y * R;
            for (size_t x = 0; x < g->wx; x++) {
                uint32_t v = w[x];
                if (x * 32 + 32 > (size_t)R) v &= (1u << (R - x * 32)) - 1; /* row padding */
                for (; v; v &= v - 1)
                    row[x * 32 + (size_t)__builtin_ctz(v)] += 1.0f;
            }
        }
    }
    if ((k & 31) == 0 && b->progress) return b->progress(b->ud, (double)k / R, err);
    return 0;
}
