/* Gregory patch sets and their exact CPU evaluation (gregory.h). The GPU
 * tessellator evaluates the same formulas in shaders/; this is the
 * reference its tests and the constructions compare against. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "gregory/gregory.h"
#include "util/vec3.h"

vx_gpatch_set *vx_gpatch_set_new(size_t n)
{
    vx_gpatch_set *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->npatches = n;
    s->cp = calloc(n * VX_GPATCH_POINTS * 3 + 1, sizeof *s->cp);
    s->corner_key = calloc(n * 4 + 1, sizeof *s->corner_key);
    s->face = calloc(n + 1, sizeof *s->face);
    if (!s->cp || !s->corner_key || !s->face) {
        vx_gpatch_set_free(s);
        return NULL;
    }
    return s;
}

void vx_gpatch_set_free(vx_gpatch_set *s)
{
    if (!s) return;
    free(s->cp);
    free(s->corner_key);
    free(s->face);
    free(s);
}

static void bernstein(double t, double b[4], double d[4])
{
    double s = 1 - t;
    b[0] = s * s * s;
    b[1] = 3 * t * s * s;
    b[2] = 3 * t * t * s;
    b[3] = t * t * t;
    d[0] = -3 * s * s;
    d[1] = 3 * s * s - 6 * t * s;
    d[2] = 6 * t * s - 3 * t * t;
    d[3] = 3 * t * t;
}

/* Slot of the k = 1 point of interior (i, j). */
static int k1_slot(int i, int j)
{
    return 16 + (i - 1) + 2 * (j - 1);
}

/* Q_ij(u, v) and its partial derivatives. */
static void blend(const double *cp, int i, int j, double u, double v, double q[3], double qu[3],
                  double qv[3])
{
    const double *p0 = cp + 3 * (4 * j + i);
    int interior = i >= 1 && i <= 2 && j >= 1 && j <= 2;
    if (!interior) {
        for (int c = 0; c < 3; c++) {
            q[c] = p0[c];
            qu[c] = qv[c] = 0;
        }
        return;
    }
    const double *p1 = cp + 3 * k1_slot(i, j);
    double wu = i == 1 ? u : 1 - u, dwu = i == 1 ? 1 : -1;
    double wv = j == 1 ? v : 1 - v, dwv = j == 1 ? 1 : -1;
    double s = wu + wv;
    if (s <= 0) { /* the corner itself: its Bernstein weight is zero there */
        for (int c = 0; c < 3; c++) {
            q[c] = 0.5 * (p0[c] + p1[c]);
            qu[c] = qv[c] = 0;
        }
        return;
    }
    for (int c = 0; c < 3; c++) {
        q[c] = (wu * p0[c] + wv * p1[c]) / s;
        qu[c] = dwu * wv * (p0[c] - p1[c]) / (s * s);
        qv[c] = dwv * wu * (p1[c] - p0[c]) / (s * s);
    }
}

static void eval_raw(const double *cp, double u, double v, double pos[3], double du[3],
                     double dv[3])
{
    double bu[4], du_b[4], bv[4], dv_b[4];
    bernstein(u, bu, du_b);
    bernstein(v, bv, dv_b);
    for (int c = 0; c < 3; c++)
        pos[c] = du[c] = dv[c] = 0;
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++) {
            double q[3], qu[3], qv[3];
            blend(cp, i, j, u, v, q, qu, qv);
            double w = bu[i] * bv[j];
            for (int c = 0; c < 3; c++) {
                pos[c] += w * q[c];
                du[c] += du_b[i] * bv[j] * q[c] + w * qu[c];
                dv[c] += bu[i] * dv_b[j] * q[c] + w * qv[c];
            }
        }
}

static double cross_unit(const double a[3], const double b[3], double n[3])
{
    vx_v3_cross(a, b, n);
    double l = vx_v3_norm(n), da = vx_v3_norm(a), db = vx_v3_norm(b);
    if (l > 0)
        for (int c = 0; c < 3; c++)
            n[c] /= l;
    return da > 0 && db > 0 ? l / (da * db) : 0; /* sine of the angle between them */
}

/* Whether the tangents span a plane: neither is rounding noise (a
 * collapsed edge's derivative sums equal points with weights summing to 0,
 * leaving ~1e-16 of the coordinates, in a random direction) and the sine
 * of their angle exceeds min_sine. */
static int spans(const double du[3], const double dv[3], double noise, double min_sine,
                 double nrm[3])
{
    double su = fabs(du[0]) + fabs(du[1]) + fabs(du[2]);
    double sv = fabs(dv[0]) + fabs(dv[1]) + fabs(dv[2]);
    return cross_unit(du, dv, nrm) > min_sine && su > noise && sv > noise;
}

void vx_gpatch_eval(const double *cp0, double u, double v, double pos[3], double nrm[3])
{
    /* In coordinates relative to the patch's first point: the derivatives'
     * rounding noise, and the bound below that tells it from a tangent,
     * scale with the patch, not with its distance from the origin (a unit
     * cube at 1e12 had every tangent under the bound 1e-12 x 1e12: normals
     * of (0, 0, 1), and folded_patches counted the face looking down).
     * Equal points stay equal, so a collapsed edge stays collapsed. */
    double cp[3 * VX_GPATCH_POINTS];
    for (int k = 0; k < 3 * VX_GPATCH_POINTS; k++)
        cp[k] = cp0[k] - cp0[k % 3];
    double du[3], dv[3];
    eval_raw(cp, u, v, pos, du, dv);
    for (int c = 0; c < 3; c++)
        pos[c] += cp0[c];
    if (!nrm) return;
    double scale = 0;
    for (int k = 0; k < 3 * VX_GPATCH_POINTS; k++)
        scale = fmax(scale, fabs(cp[k]));
    const double noise = 1e-12 * scale;
    if (spans(du, dv, noise, 1e-9, nrm)) return;
    /* A collapsed edge or corner (the teapot's lid): approach the point
     * along the diagonal towards the patch centre until the tangents span a
     * plane; the normal there converges to the limit. */
    for (double t = 1e-7; t < 0.1; t *= 10) {
        double p[3];
        eval_raw(cp, u + (0.5 - u) * t, v + (0.5 - v) * t, p, du, dv);
        if (spans(du, dv, noise, 1e-6, nrm)) return;
    }
    nrm[0] = nrm[1] = 0;
    nrm[2] = 1; /* a patch collapsed to a curve or point has no normal */
}

/* The Newell normal of input face f (unnormalised), frame-0 positions,
 * relative to its first vertex: the sums p + q of positions far from the
 * origin for their size cancelled to noise (a unit quad at 1e15). */
static void face_normal(const vx_mesh *m, size_t f, double n[3])
{
    size_t a = m->face_start ? m->face_start[f] : 3 * f;
    size_t b = m->face_start ? m->face_start[f + 1] : 3 * f + 3;
    const double *o = m->pos + 3 * (size_t)m->face_idx[a];
    n[0] = n[1] = n[2] = 0;
    for (size_t k = a; k < b; k++) {
        const double *P = m->pos + 3 * (size_t)m->face_idx[k];
        const double *Q = m->pos + 3 * (size_t)m->face_idx[k + 1 < b ? k + 1 : a];
        double p[3] = {P[0] - o[0], P[1] - o[1], P[2] - o[2]};
        double q[3] = {Q[0] - o[0], Q[1] - o[1], Q[2] - o[2]};
        n[0] += (p[1] - q[1]) * (p[2] + q[2]);
        n[1] += (p[2] - q[2]) * (p[0] + q[0]);
        n[2] += (p[0] - q[0]) * (p[1] + q[1]);
    }
}

size_t vx_gpatch_folded(const vx_gpatch_set *s, const vx_mesh *m)
{
    size_t folded = 0, last = SIZE_MAX;
    double fn[3] = {0, 0, 0};
    for (size_t p = 0; p < s->npatches; p++) {
        const double *cp = s->cp + p * VX_GPATCH_POINTS * 3;
        double pos[3], nrm[3];
        if (m->npatches || s->face[p] >= m->nfaces) { /* a Bézier patch: its corner quad */
            const double *c0 = cp, *c1 = cp + 9, *c2 = cp + 45, *c3 = cp + 36;
            double d[3] = {c2[0] - c0[0], c2[1] - c0[1], c2[2] - c0[2]},
                   e[3] = {c3[0] - c1[0], c3[1] - c1[1], c3[2] - c1[2]};
            fn[0] = d[1] * e[2] - d[2] * e[1];
            fn[1] = d[2] * e[0] - d[0] * e[2];
            fn[2] = d[0] * e[1] - d[1] * e[0];
            last = SIZE_MAX;
        } else if (s->face[p] != last) { /* an n-gon's n patches come together: once */
            face_normal(m, s->face[p], fn);
            last = s->face[p];
        }
        vx_gpatch_eval(cp, 0.5, 0.5, pos, nrm);
        if (nrm[0] * fn[0] + nrm[1] * fn[1] + nrm[2] * fn[2] < 0) folded++;
    }
    return folded;
}
