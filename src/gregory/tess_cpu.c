/* Gregory tessellation on the CPU threads (tess.h, engine cpu): the
 * formulas of shaders/gregory_tess.comp.glsl in float, a grid row at a
 * time, four vertices of a row at once (GCC vector types: SSE on x86-64's
 * baseline), patches handed to vx_par_for's threads.
 *
 * On a CPU rasterizer (llvmpipe) the compute pass runs this same work on the
 * same cores behind a driver, plus the invocations' overhead and the
 * read-back of the grid; here the grid is written in place. */
#include <math.h>
#include <stdatomic.h>
#include <string.h>

#include "gregory/tess_int.h"
#include "util/clock.h"
#include "util/par.h"
#include "util/stop.h"

#define LANES 4
typedef float vf __attribute__((vector_size(LANES * sizeof(float))));
typedef int vi __attribute__((vector_size(LANES * sizeof(int))));

/* Patches per task: enough work to amortise the hand-out (N = 16: ~18k
 * vertices), few enough to balance two threads on small sets. */
#define TASK_PATCHES 64

static vf splat(float x)
{
    return (vf){x, x, x, x};
}

typedef struct v3 {
    float x, y, z;
} v3;

static v3 cp(const float *c, int slot)
{
    return (v3){c[3 * slot], c[3 * slot + 1], c[3 * slot + 2]};
}

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
 * approaching along the diagonal towards the centre. */
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

typedef struct vv3 {
    vf x, y, z;
} vv3;

static void vacc(vv3 *r, vf w, v3 p) /* r += w p */
{
    r->x += w * splat(p.x);
    r->y += w * splat(p.y);
    r->z += w * splat(p.z);
}

/* Row j of patch c (its 64 floats) with n divisions into out (6 floats a
 * vertex, n + 1 vertices). */
static void row(const float *c, uint32_t n, uint32_t j, float *out)
{
    const uint32_t w = n + 1;
    float v = (float)j / (float)n, bv[4], dbv[4];
    bern(v, bv, dbv);
    /* the v-only sums, interior points left out */
    v3 A[4], Av[4];
    for (int i = 0; i < 4; i++) {
        int mid = i == 1 || i == 2;
        v3 p0 = cp(c, i), p1 = cp(c, 4 + i), p2 = cp(c, 8 + i), p3 = cp(c, 12 + i);
        float m1 = mid ? 0.0f : bv[1], m2 = mid ? 0.0f : bv[2];
        float d1 = mid ? 0.0f : dbv[1], d2 = mid ? 0.0f : dbv[2];
        A[i] = (v3){bv[0] * p0.x + bv[3] * p3.x + (m1 * p1.x + m2 * p2.x),
                    bv[0] * p0.y + bv[3] * p3.y + (m1 * p1.y + m2 * p2.y),
                    bv[0] * p0.z + bv[3] * p3.z + (m1 * p1.z + m2 * p2.z)};
        Av[i] = (v3){dbv[0] * p0.x + dbv[3] * p3.x + (d1 * p1.x + d2 * p2.x),
                     dbv[0] * p0.y + dbv[3] * p3.y + (d1 * p1.y + d2 * p2.y),
                     dbv[0] * p0.z + dbv[3] * p3.z + (d1 * p1.z + d2 * p2.z)};
    }
    v3 p0s[4], p1s[4], dps[4];
    for (int q = 0; q < 4; q++) {
        int i = 1 + (q & 1), jj = 1 + (q >> 1);
        p0s[q] = cp(c, 4 * jj + i);
        p1s[q] = cp(c, 16 + q);
        dps[q] = (v3){p0s[q].x - p1s[q].x, p0s[q].y - p1s[q].y, p0s[q].z - p1s[q].z};
    }
    const v3 org = cp(c, 20);
    const vf lane = {0, 1, 2, 3}, fn = splat((float)n);
    for (uint32_t i0 = 0; i0 < w; i0 += LANES) {
        vf u = (splat((float)i0) + lane) / fn;
        vf s = splat(1.0f) - u;
        vf bu[4] = {s * s * s, 3.0f * u * s * s, 3.0f * u * u * s, u * u * u};
        vf dbu[4] = {-3.0f * s * s, 3.0f * s * s - 6.0f * u * s, 6.0f * u * s - 3.0f * u * u,
                     3.0f * u * u};
        vv3 pos = {0}, du = {0}, dv = {0};
        for (int i = 0; i < 4; i++) {
            vacc(&pos, bu[i], A[i]);
            vacc(&du, dbu[i], A[i]);
            vacc(&dv, bu[i], Av[i]);
        }
        for (int q = 0; q < 4; q++) {
            int ii = 1 + (q & 1), jj = 1 + (q >> 1);
            vf wu = ii == 1 ? u : splat(1.0f) - u;
            float dwu = ii == 1 ? 1.0f : -1.0f;
            float wv = jj == 1 ? v : 1.0f - v, dwv = jj == 1 ? 1.0f : -1.0f;
            /* s is 0 only at the corner this point belongs to, where its
             * weights vanish: clamping keeps the terms finite (the shader's
             * max) */
            vf sum = wu + wv;
            vi big = sum > splat(1e-6f);
            sum = (vf)((big & (vi)sum) | (~big & (vi)splat(1e-6f)));
            vf is = splat(1.0f) / sum;
            vv3 qq = {(wu * p0s[q].x + wv * p1s[q].x) * is, (wu * p0s[q].y + wv * p1s[q].y) * is,
                      (wu * p0s[q].z + wv * p1s[q].z) * is};
            vf is2 = is * is, cu = (dwu * wv) * is2, cv = -(dwv * wu) * is2;
            vf bi = ii == 1 ? bu[1] : bu[2], dbi = ii == 1 ? dbu[1] : dbu[2];
            float bj = jj == 1 ? bv[1] : bv[2], dbj = jj == 1 ? dbv[1] : dbv[2];
            vf bb = bi * bj, db = dbi * bj, bd = bi * dbj;
            pos.x += bb * qq.x;
            pos.y += bb * qq.y;
            pos.z += bb * qq.z;
            du.x += db * qq.x + bb * cu * dps[q].x;
            du.y += db * qq.y + bb * cu * dps[q].y;
            du.z += db * qq.z + bb * cu * dps[q].z;
            dv.x += bd * qq.x + bb * cv * dps[q].x;
            dv.y += bd * qq.y + bb * cv * dps[q].y;
            dv.z += bd * qq.z + bb * cv * dps[q].z;
        }
        vv3 nr = {du.y * dv.z - du.z * dv.y, du.z * dv.x - du.x * dv.z, du.x * dv.y - du.y * dv.x};
        vf l2 = nr.x * nr.x + nr.y * nr.y + nr.z * nr.z;
        vf dd = (du.x * du.x + du.y * du.y + du.z * du.z) * (dv.x * dv.x + dv.y * dv.y + dv.z * dv.z);
        vi ok = l2 > splat(1e-10f) * dd;
        uint32_t m = w - i0 < LANES ? w - i0 : LANES;
        float *o = out + 6 * (size_t)i0;
        for (uint32_t k = 0; k < m; k++, o += 6) {
            float nn[3];
            if (ok[k]) {
                float inv = 1.0f / sqrtf(l2[k]);
                nn[0] = nr.x[k] * inv;
                nn[1] = nr.y[k] * inv;
                nn[2] = nr.z[k] * inv;
            } else {
                degenerate_normal(c, u[k], v, nn);
            }
            o[0] = pos.x[k] + org.x;
            o[1] = pos.y[k] + org.y;
            o[2] = pos.z[k] + org.z;
            o[3] = nn[0];
            o[4] = nn[1];
            o[5] = nn[2];
        }
    }
}

typedef struct tctx {
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
        uint32_t n = c->l->ndiv[p];
        float *out = c->grid + 6 * c->l->voff[p];
        for (uint32_t j = 0; j <= n; j++)
            row(f, n, j, out + 6 * (size_t)j * (n + 1));
    }
    return 0;
}

int vx_gtess_cpu_run(const vx_gtess_layout *l, const vx_gpatch_set *s, const double origin[3],
                     float *grid, double *ms, vx_err *err)
{
    double t0 = vx_mono_ms();
    tctx c = {.l = l, .s = s, .origin = origin, .grid = grid, .err = err};
    size_t items = (l->npatches + TASK_PATCHES - 1) / TASK_PATCHES;
    int rc = items ? vx_par_for((int)items, vx_par_cpus(), task, &c) : 0;
    *ms = vx_mono_ms() - t0;
    return rc ? -1 : 0;
}
