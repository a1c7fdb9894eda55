/* Gregory tessellation on the CPU threads (tess.h, engine cpu): the
 * formulas of shaders/gregory_tess.comp.glsl in float (rearranged so that
 * what depends on u or v alone is computed once a patch or a row), four
 * vertices of a row at once (GCC vector types: SSE on x86-64's baseline;
 * eight with AVX2 and FMA where the CPU has them), patches handed to
 * vx_par_for's threads.
 *
 * On a CPU rasterizer (llvmpipe) the compute pass runs this same work on the
 * same cores behind a driver, plus the invocations' overhead and the
 * read-back of the grid; here the grid is written in place. */
#include <math.h>
#include <stdatomic.h>
#include <string.h>
#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include "gregory/tess_int.h"
#include "util/clock.h"
#include "util/cpu.h"
#include "util/par.h"
#include "util/stop.h"

/* Patches per task: enough work to amortise the hand-out (N = 16: ~18k
 * vertices), few enough to balance two threads on small sets. */
#define TASK_PATCHES 64

typedef struct v3 {
    float x, y, z;
} v3;

static void bern(float t, float b[4], float d[4])
{
    float s = 1.0f - t;
    b[0] = s * s * s;
    b[1] = 3.0f * t * s * s;
    b[2] = 3.0f * t * t * s;
    b[3] = t * t * t;
    d[0] = -3.0f * s * s;
    d[1] = 3.0f * s * s - 6.0f * t * s;
    d[2] = 6.0f * t * s - 3.0f * t * t;
    d[3] = 3.0f * t * t;
}

/* eval_raw of the shader: position and derivatives at (u, v), scalar. */
static void eval_raw(const float *c, float u, float v, float pos[3], float du[3], float dv[3])
{
    float bu[4], dbu[4], bv[4], dbv[4];
    bern(u, bu, dbu);
    bern(v, bv, dbv);
    memset(pos, 0, 3 * sizeof *pos);
    memset(du, 0, 3 * sizeof *du);
    memset(dv, 0, 3 * sizeof *dv);
    for (int j = 0; j < 4; j++) {
        float row[3] = {0, 0, 0}, rowd[3] = {0, 0, 0};
        for (int i = 0; i < 4; i++)
            for (int a = 0; a < 3; a++) {
                row[a] += bu[i] * c[3 * (4 * j + i) + a];
                rowd[a] += dbu[i] * c[3 * (4 * j + i) + a];
            }
        for (int a = 0; a < 3; a++) {
            pos[a] += bv[j] * row[a];
            du[a] += bv[j] * rowd[a];
            dv[a] += dbv[j] * row[a];
        }
    }
    for (int k = 0; k < 4; k++) {
        int i = 1 + (k & 1), j = 1 + (k >> 1);
        const float *p0 = c + 3 * (4 * j + i), *p1 = c + 3 * (16 + k);
        float wu = i == 1 ? u : 1.0f - u, dwu = i == 1 ? 1.0f : -1.0f;
        float wv = j == 1 ? v : 1.0f - v, dwv = j == 1 ? 1.0f : -1.0f;
        float s = wu + wv, w = bu[i] * bv[j];
        for (int a = 0; a < 3; a++) {
            float q, qu, qv;
            if (s <= 0.0f) {
                q = 0.5f * (p0[a] + p1[a]);
                qu = qv = 0.0f;
            } else {
                q = (wu * p0[a] + wv * p1[a]) / s;
                qu = dwu * wv * (p0[a] - p1[a]) / (s * s);
                qv = dwv * wu * (p1[a] - p0[a]) / (s * s);
            }
            float dq = q - p0[a];
            pos[a] += w * dq;
            du[a] += dbu[i] * bv[j] * dq + w * qu;
            dv[a] += bu[i] * dbv[j] * dq + w * qv;
        }
    }
}

/* The sine of the angle between a and b; n = unit a x b (+z when 0). */
static float cross_unit(const float a[3], const float b[3], float n[3])
{
    float c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    float l = sqrtf(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    float la = sqrtf(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    float lb = sqrtf(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    for (int k = 0; k < 3; k++)
        n[k] = l > 0.0f ? c[k] / l : (k == 2 ? 1.0f : 0.0f);
    return la > 0.0f && lb > 0.0f ? l / (la * lb) : 0.0f;
}

/* The shader's fallback at a collapsed edge or corner: the normal found
 * approaching along the diagonal towards the centre (c: the control points
 * at the patch's scale, as the row evaluates them). */
static void degenerate_normal(const float *c, float u, float v, float n[3])
{
    for (float t = 1e-4f; t < 0.1f; t *= 10.0f) {
        float p[3], du[3], dv[3];
        eval_raw(c, u + (0.5f - u) * t, v + (0.5f - v) * t, p, du, dv);
        if (cross_unit(du, dv, n) > 1e-5f) return;
    }
    n[0] = n[1] = 0.0f;
    n[2] = 1.0f;
}

/* Lane vectors (GCC's vector extension) and the stores of a chunk's
 * vertices: 6 lane vectors (x y z nx ny nz) transposed to 6 floats a
 * vertex; a partial chunk (the row's last) lane by lane. */
typedef float vf4 __attribute__((vector_size(16)));
typedef int vi4 __attribute__((vector_size(16)));
typedef float vf8 __attribute__((vector_size(32)));
typedef int vi8 __attribute__((vector_size(32)));
#define STORE_LANES(o, t, m)                                                                       \
    for (uint32_t k_ = 0; k_ < (m); k_++)                                                          \
        for (int a_ = 0; a_ < 6; a_++)                                                             \
    (o)[6 * k_ + a_] = (t)[a_][k_]
#if defined(__x86_64__)
/* x0..3 y z nx ny nz as 4 vertices [x y z nx] + [ny nz] */
#define STORE4_HALVES(o, x, y, z, nx, ny, nz)                                                      \
    do {                                                                                           \
        __m128 a0_ = _mm_unpacklo_ps(x, y), a1_ = _mm_unpackhi_ps(x, y);                           \
        __m128 b0_ = _mm_unpacklo_ps(z, nx), b1_ = _mm_unpackhi_ps(z, nx);                         \
        __m128 c0_ = _mm_unpacklo_ps(ny, nz), c1_ = _mm_unpackhi_ps(ny, nz);                       \
        _mm_storeu_ps((o), _mm_movelh_ps(a0_, b0_));                                               \
        _mm_storel_pi((__m64 *)((o) + 4), c0_);                                                    \
        _mm_storeu_ps((o) + 6, _mm_movehl_ps(b0_, a0_));                                           \
        _mm_storeh_pi((__m64 *)((o) + 10), c0_);                                                   \
        _mm_storeu_ps((o) + 12, _mm_movelh_ps(a1_, b1_));                                          \
        _mm_storel_pi((__m64 *)((o) + 16), c1_);                                                   \
        _mm_storeu_ps((o) + 18, _mm_movehl_ps(b1_, a1_));                                          \
        _mm_storeh_pi((__m64 *)((o) + 22), c1_);                                                   \
    } while (0)

static inline void store4(float *o, const vf4 *t)
{
    STORE4_HALVES(o, (__m128)t[0], (__m128)t[1], (__m128)t[2], (__m128)t[3], (__m128)t[4],
                  (__m128)t[5]);
}

__attribute__((target("avx2,fma"))) static inline void store8(float *o, const vf8 *t)
{
#define HALF(k, h) _mm256_extractf128_ps((__m256)t[k], h)
    STORE4_HALVES(o, HALF(0, 0), HALF(1, 0), HALF(2, 0), HALF(3, 0), HALF(4, 0), HALF(5, 0));
    STORE4_HALVES(o + 24, HALF(0, 1), HALF(1, 1), HALF(2, 1), HALF(3, 1), HALF(4, 1), HALF(5, 1));
#undef HALF
}
#define STORE4(o, t, m) ((m) == 4 ? store4(o, t) : ({ STORE_LANES(o, t, m); }))
#define STORE8(o, t, m) ((m) == 8 ? store8(o, t) : ({ STORE_LANES(o, t, m); }))
#else
#define STORE4(o, t, m) STORE_LANES(o, t, m)
#endif

/* The patch kernel, for SSE (x86-64's baseline: 4 lanes) and, chosen at
 * run time, AVX2 with FMA (8 lanes). */
#define ROW_LANES 4
#define ROW_NAME patch4
#define ROW_ATTR
#define ROW_STORE STORE4
#include "gregory/tess_cpu_row.inc"
#if defined(__x86_64__)
#define ROW_LANES 8
#define ROW_NAME patch8
#define ROW_ATTR __attribute__((target("avx2,fma")))
#define ROW_STORE STORE8
#include "gregory/tess_cpu_row.inc"
#endif

typedef void (*patch_fn)(const float *c, uint32_t n, float *out);

static patch_fn pick_kernel(int lanes)
{
#if defined(__x86_64__)
    if (lanes != 4 && vx_cpu_avx2_fma()) return patch8;
#endif
    return patch4;
}

typedef struct tctx {
    patch_fn patch;
    const vx_gtess_layout *l;
    const vx_gpatch_set *s;
    const double *origin;
    float *grid;
    vx_err *err; /* the calling thread's */
} tctx;

static int task(int item, int t, void *ud)
{
    tctx *c = ud;
    if (t == 0 && vx_stop_poll(c->err)) return 1;
    size_t p0 = (size_t)item * TASK_PATCHES, p1 = p0 + TASK_PATCHES;
    if (p1 > c->l->npatches) p1 = c->l->npatches;
    float f[VX_GTESS_CP_FLOATS];
    for (size_t p = p0; p < p1; p++) {
        vx_gtess_pack(c->s, p, c->origin, f);
        c->patch(f, c->l->ndiv[p], c->grid + 6 * c->l->voff[p]);
    }
    return 0;
}

int vx_gtess_cpu_run(const vx_gtess_layout *l, const vx_gpatch_set *s, const double origin[3],
                     float *grid, int lanes, double *ms, vx_err *err)
{
    double t0 = vx_mono_ms();
    tctx c = {
        .patch = pick_kernel(lanes), .l = l, .s = s, .origin = origin, .grid = grid, .err = err};
    size_t items = (l->npatches + TASK_PATCHES - 1) / TASK_PATCHES;
    int rc = items ? vx_par_for((int)items, vx_par_cpus(), task, &c) : 0;
    *ms = vx_mono_ms() - t0;
    return rc ? -1 : 0;
}
