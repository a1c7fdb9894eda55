/* The winding-number tree (winding_int.h): a bounding-volume hierarchy of
 * triangles split at the median centroid along the widest axis, each node
 * carrying the first two moments of its dipole field. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "util/cpu.h"
#include "voxel/winding_int.h"

#if defined(__x86_64__)
#include <immintrin.h>
#define VX_WTREE_AVX2 1 /* eval4 and bound4's lanes (else one point at a time) */
#endif

#define LEAF 8
#define LEAF_CORNERS 64 /* a leaf with more distinct corners goes triangle by triangle */
#define STACK 128
#define TB 10 /* doubles of tb a triangle */

/* atan2 to about 1e-5 radians (Abramowitz & Stegun 4.4.47 on [0, 1],
 * then the octant), a few times faster than libm's. */
static double atan2_fast(double y, double x)
{
    double ax = fabs(x), ay = fabs(y), mx = ax > ay ? ax : ay, mn = ax > ay ? ay : ax;
    if (mx == 0) return 0;
    double a = mn / mx, s = a * a;
    double r =
        a * (0.9998660 + s * (-0.3302995 + s * (0.1801410 + s * (-0.0851330 + s * 0.0208351))));
    if (ay > ax) r = M_PI_2 - r;
    if (x < 0) r = M_PI - r;
    return y < 0 ? -r : r;
}

/* tan(omega / 2) of the triangle seen along unit vectors u0..2, from the
 * pair (i, j) whose sum s = ui + uj is shortest, k the third: det(u0, u1,
 * u2) = s . (uj x uk) and 1 + u0.u1 + u1.u2 + u2.u0 = |s|^2 / 2 + s . uk,
 * exactly, both from s itself (see tri_units). */
static double tri_near_edge(const double *const u[3])
{
    int best = 0;
    double s[3][3], ss[3];
    for (int p = 0; p < 3; p++) {
        for (int k = 0; k < 3; k++)
            s[p][k] = u[p][k] + u[(p + 1) % 3][k];
        ss[p] = s[p][0] * s[p][0] + s[p][1] * s[p][1] + s[p][2] * s[p][2];
        if (ss[p] < ss[best]) best = p;
    }
    const double *t = s[best], *uj = u[(best + 1) % 3], *uk = u[(best + 2) % 3];
    double det = t[0] * (uj[1] * uk[2] - uj[2] * uk[1]) - t[1] * (uj[0] * uk[2] - uj[2] * uk[0]) +
                 t[2] * (uj[0] * uk[1] - uj[1] * uk[0]);
    double den = 0.5 * ss[best] + t[0] * uk[0] + t[1] * uk[1] + t[2] * uk[2];
    return atan2_fast(det, den) / (2 * M_PI);
}

/* The triangle seen along unit vectors a, b, c (Van Oosterom & Strackee):
 * tan(omega / 2) = *det / *den, w = omega / (4 pi). 1 when that pair
 * carries the angle; 0 when it is too small to (under 1e-6: det and den
 * carry rounding of about 1e-16, which seen from near a long edge, where
 * the unit vectors of its ends nearly cancel, is every digit; a triangle
 * 1e8 long seen from 0.1 away gave w off by 1/2): then tri_near_edge.
 * Inlined always: leaf_eval's loop ran 10% slower with it called. */
static inline __attribute__((always_inline)) int
tri_half_angle(const double *a, const double *b, const double *c, double *det, double *den)
{
    *det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
           a[2] * (b[0] * c[1] - b[1] * c[0]);
    *den = 1 + (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) +
           (b[0] * c[0] + b[1] * c[1] + b[2] * c[2]) + (c[0] * a[0] + c[1] * a[1] + c[2] * a[2]);
    return *det * *det + *den * *den > 1e-12;
}

/* w of the triangle seen along unit vectors a, b, c. */
static double tri_units(const double *a, const double *b, const double *c)
{
    double det, den;
    if (tri_half_angle(a, b, c, &det, &den)) return atan2_fast(det, den) / (2 * M_PI);
    return tri_near_edge((const double *const[3]){a, b, c});
}

/* *u = the unit vector from q to v; 0, or -1 where v is q. Divided, not
 * multiplied by 1 / l: a coordinate that is the whole length then gives
 * exactly +-1, which tri_near_edge's cancelling sums need (with 1 / l a
 * sliver 1e8 long gave w off by 1 seen from 0.3 away). */
static int unit_from(const double *v, const double q[3], double u[3])
{
    double d[3] = {v[0] - q[0], v[1] - q[1], v[2] - q[2]};
    double l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (l == 0) return -1;
    for (int k = 0; k < 3; k++)
        u[k] = d[k] / l;
    return 0;
}

double vx_wtree_tri(const double *v, const double q[3])
{
    double u[3][3];
    for (int i = 0; i < 3; i++)
        if (unit_from(v + 3 * i, q, u[i])) return 0; /* at a corner */
    return tri_units(u[0], u[1], u[2]);
}

typedef struct build {
    vx_wtree *t;
    const double *src; /* input triangles */
    int *idx;          /* triangle order, permuted in place */
    double *cen;       /* 3 per input triangle */
    int cap;
} build;

/* Moves the idx[lo..hi) with the k-th smallest centroid coordinate along
 * axis to position k, smaller ones before it (quickselect). */
static void select_k(build *b, int lo, int hi, int k, int axis)
{
    while (hi - lo > 1) {
        int mid = lo + (hi - lo) / 2;
        double pv = b->cen[3 * b->idx[mid] + axis];
        int i = lo, j = hi - 1;
        while (i <= j) {
            while (b->cen[3 * b->idx[i] + axis] < pv)
                i++;
            while (b->cen[3 * b->idx[j] + axis] > pv)
                j--;
            if (i <= j) {
                int s = b->idx[i];
                b->idx[i++] = b->idx[j];
                b->idx[j--] = s;
            }
        }
        if (k <= j)
            hi = j + 1;
        else if (k >= i)
            lo = i;
        else
            return;
    }
}

/* The node's moments and radius from its triangles idx[lo..hi). */
/* Triangle v (9 doubles)'s area vector: half the cross product of its edges. */
static void area_vector(const double *v, double n[3])
{
    double e1[3] = {v[3] - v[0], v[4] - v[1], v[5] - v[2]};
    double e2[3] = {v[6] - v[0], v[7] - v[1], v[8] - v[2]};
    n[0] = .5 * (e1[1] * e2[2] - e1[2] * e2[1]);
    n[1] = .5 * (e1[2] * e2[0] - e1[0] * e2[2]);
    n[2] = .5 * (e1[0] * e2[1] - e1[1] * e2[0]);
}

static void moments(build *b, vx_wtree_node *nd, int lo, int hi)
{
    double area = 0, p[3] = {0, 0, 0};
    memset(nd->a, 0, sizeof nd->a);
    memset(nd->m, 0, sizeof nd->m);
    for (int i = lo; i < hi; i++) {
        const double *v = b->src + 9 * (size_t)b->idx[i], *c = b->cen + 3 * b->idx[i];
        double n[3];
        area_vector(v, n);
        double s = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        area += s;
        for (int k = 0; k < 3; k++) {
            p[k] += s * c[k];
            nd->a[k] += n[k];
        }
    }
    for (int k = 0; k < 3; k++)
        nd->p[k] = area > 0 ? p[k] / area : b->cen[3 * b->idx[lo] + k];
    double r2 = 0;
    for (int k = 0; k < 3; k++) {
        nd->lo[k] = HUGE_VAL;
        nd->hi[k] = -HUGE_VAL;
    }
    for (int i = lo; i < hi; i++) {
        const double *v = b->src + 9 * (size_t)b->idx[i], *c = b->cen + 3 * b->idx[i];
        double n[3];
        area_vector(v, n);
        for (int r = 0; r < 3; r++)
            for (int s = 0; s < 3; s++)
                nd->m[3 * r + s] += (c[r] - nd->p[r]) * n[s];
        for (int q = 0; q < 3; q++) {
            double d2 = 0;
            for (int k = 0; k < 3; k++) {
                double x = v[3 * q + k];
                d2 += (x - nd->p[k]) * (x - nd->p[k]);
                nd->lo[k] = x < nd->lo[k] ? x : nd->lo[k];
                nd->hi[k] = x > nd->hi[k] ? x : nd->hi[k];
            }
            if (d2 > r2) r2 = d2;
        }
    }
    nd->far2 = VX_WTREE_BETA * VX_WTREE_BETA * r2;
    nd->area = area / (4 * M_PI);
}

/* Node over idx[lo..hi); returns its index. The tree has at most
 * 2 * ntris / LEAF * 2 + 1 nodes (cap, allocated up front). */
static int node_build(build *b, int lo, int hi, int depth)
{
    vx_wtree *t = b->t;
    int id = t->nnodes++;
    vx_wtree_node *nd = &t->node[id];
    moments(b, nd, lo, hi);
    nd->kid[0] = nd->kid[1] = -1;
    nd->first = lo;
    nd->n = hi - lo;
    if (hi - lo <= LEAF || depth >= STACK / 2 - 2 || t->nnodes + 2 > b->cap) return id;
    double mn[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, mx[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    for (int i = lo; i < hi; i++)
        for (int k = 0; k < 3; k++) {
            double c = b->cen[3 * b->idx[i] + k];
            mn[k] = c < mn[k] ? c : mn[k];
            mx[k] = c > mx[k] ? c : mx[k];
        }
    int axis = 0;
    for (int k = 1; k < 3; k++)
        if (mx[k] - mn[k] > mx[axis] - mn[axis]) axis = k;
    int mid = lo + (hi - lo) / 2;
    select_k(b, lo, hi, mid, axis);
    int l = node_build(b, lo, mid, depth + 1);
    int r = node_build(b, mid, hi, depth + 1);
    t->node[id].kid[0] = l;
    t->node[id].kid[1] = r;
    return id;
}

/* Each leaf's distinct corners into t->lv, each triangle's places among
 * them into t->corner (a leaf with over LEAF_CORNERS keeps nv 0). */
static int leaf_corners(vx_wtree *t)
{
    t->lv = malloc(9 * t->ntris * sizeof *t->lv + 1);
    t->corner = malloc(3 * t->ntris + 1);
    if (!t->lv || !t->corner) return -1;
    int nlv = 0;
    for (int id = 0; id < t->nnodes; id++) {
        vx_wtree_node *nd = &t->node[id];
        nd->vfirst = nlv;
        nd->nv = 0;
        if (nd->kid[0] >= 0) continue;
        int nv = 0;
        for (int i = nd->first; i < nd->first + nd->n && nv >= 0; i++)
            for (int q = 0; q < 3; q++) {
                const double *v = t->tv + 9 * (size_t)i + 3 * q;
                int at = 0;
                while (at < nv && memcmp(t->lv + 3 * (size_t)(nlv + at), v, 3 * sizeof *v))
                    at++;
                if (at == nv) {
                    if (nv == LEAF_CORNERS) {
                        nv = -1;
                        break;
                    }
                    memcpy(t->lv + 3 * (size_t)(nlv + nv++), v, 3 * sizeof *v);
                }
                t->corner[3 * (size_t)i + q] = (uint8_t)at;
            }
        if (nv > 0) { /* found as x y z per corner; kept as nv x, nv y, nv z */
            double tmp[3 * LEAF_CORNERS], *blk = t->lv + 3 * (size_t)nlv;
            memcpy(tmp, blk, 3 * (size_t)nv * sizeof *tmp);
            for (int v = 0; v < nv; v++)
                for (int k = 0; k < 3; k++)
                    blk[k * nv + v] = tmp[3 * v + k];
            nd->nv = nv;
            nlv += nv;
        }
    }
    return 0;
}

int vx_wtree_build(vx_wtree *t, size_t ntris, const double *tv, vx_err *err)
{
    memset(t, 0, sizeof *t);
    if (ntris == 0) return 0;
    if (ntris > (size_t)INT32_MAX / 4)
        return vx_err_set(err, VX_ETOOBIG, "job_memory_limit", "too many boundary triangles");
    build b = {.t = t, .src = tv, .cap = (int)(4 * (ntris / LEAF + 1) + 1)};
    b.idx = malloc(ntris * sizeof *b.idx);
    b.cen = malloc(3 * ntris * sizeof *b.cen);
    t->tv = malloc(9 * ntris * sizeof *t->tv);
    t->tb = malloc(TB * ntris * sizeof *t->tb);
    t->node = malloc((size_t)b.cap * sizeof *t->node);
    if (!b.idx || !b.cen || !t->tv || !t->tb || !t->node) {
        free(b.idx);
        free(b.cen);
        vx_wtree_free(t);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the winding tree");
    }
    for (size_t i = 0; i < ntris; i++) {
        b.idx[i] = (int)i;
        for (int k = 0; k < 3; k++)
            b.cen[3 * i + k] = (tv[9 * i + k] + tv[9 * i + 3 + k] + tv[9 * i + 6 + k]) / 3;
    }
    node_build(&b, 0, (int)ntris, 0);
    for (size_t i = 0; i < ntris; i++)
        memcpy(t->tv + 9 * i, tv + 9 * (size_t)b.idx[i], 9 * sizeof *tv);
    t->ntris = ntris;
    for (size_t i = 0; i < ntris; i++) {
        const double *v = t->tv + 9 * i;
        double *d = t->tb + TB * i;
        area_vector(v, d);
        d[3] = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / (4 * M_PI);
        for (int k = 0; k < 3; k++) {
            d[4 + k] = fmin(fmin(v[k], v[3 + k]), v[6 + k]);
            d[7 + k] = fmax(fmax(v[k], v[3 + k]), v[6 + k]);
        }
    }
    free(b.idx);
    free(b.cen);
    if (leaf_corners(t)) {
        vx_wtree_free(t);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the winding tree");
    }
    return 0;
}

/* The expansion of a far node's field at q (times 4 pi). */
static double far_field(const vx_wtree_node *nd, const double q[3])
{
    double r[3] = {nd->p[0] - q[0], nd->p[1] - q[1], nd->p[2] - q[2]};
    double r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    double inv = 1 / sqrt(r2), inv3 = inv * inv * inv, inv5 = inv3 * inv * inv;
    double first = (r[0] * nd->a[0] + r[1] * nd->a[1] + r[2] * nd->a[2]) * inv3;
    const double *m = nd->m;
    double tr = m[0] + m[4] + m[8], rmr = 0;
    for (int i = 0; i < 3; i++)
        rmr += r[i] * (m[3 * i] * r[0] + m[3 * i + 1] * r[1] + m[3 * i + 2] * r[2]);
    return first + tr * inv3 - 3 * rmr * inv5;
}

/* A leaf's triangles at q (a triangle with a corner at q counts 0, as
 * vx_wtree_tri). Each distinct corner's unit vector is made once, by a
 * multiplication by 1 / l: its last-bit error moves tan(omega / 2) =
 * det / den by about 1e-16, nothing against |(den, det)| > 1e-6. Below
 * that (seen from near a long edge) the triangle goes through
 * vx_wtree_tri, whose divided unit vectors tri_near_edge needs. The
 * half-angles are summed as the argument of the product of the
 * (den, det), one atan2 a leaf: a factor and the product so far both in
 * the upper (lower) half-plane whose product falls in the other half
 * went past pi (-pi) once more. Each factor's half-angle is in (-pi, pi],
 * so no sum goes past twice; at most 8 factors of modulus in (1e-6,
 * 4.1] neither overflow nor underflow. */
static double leaf_eval(const vx_wtree *t, const vx_wtree_node *nd, const double q[3])
{
    double u[3][LEAF_CORNERS], l2[LEAF_CORNERS];
    const int nv = nd->nv;
    const double *p = t->lv + 3 * (size_t)nd->vfirst; /* nv x, nv y, nv z */
    for (int v = 0; v < nv; v++) {
        double d0 = p[v] - q[0], d1 = p[nv + v] - q[1], d2 = p[2 * nv + v] - q[2];
        l2[v] = d0 * d0 + d1 * d1 + d2 * d2;
        double inv = 1 / sqrt(l2[v] + (l2[v] == 0)); /* its triangles are skipped */
        u[0][v] = d0 * inv;
        u[1][v] = d1 * inv;
        u[2][v] = d2 * inv;
    }
    uint64_t at_q = 0; /* corners at q */
    for (int v = 0; v < nv; v++)
        if (l2[v] == 0) at_q |= (uint64_t)1 << v;
    double w = 0, re = 1, im = 0;
    int turns = 0;
    for (int i = nd->first; i < nd->first + nd->n; i++) {
        const uint8_t *c = t->corner + 3 * (size_t)i;
        if (at_q && (at_q >> c[0] & 1 || at_q >> c[1] & 1 || at_q >> c[2] & 1)) continue;
        const double a[3] = {u[0][c[0]], u[1][c[0]], u[2][c[0]]},
                     b[3] = {u[0][c[1]], u[1][c[1]], u[2][c[1]]},
                     e[3] = {u[0][c[2]], u[1][c[2]], u[2][c[2]]};
        double det, den;
        if (!tri_half_angle(a, b, e, &det, &den)) {
            w += vx_wtree_tri(t->tv + 9 * (size_t)i, q);
            continue;
        }
        double r2 = re * den - im * det, i2 = re * det + im * den;
        if (im >= 0 && det >= 0 && i2 < 0) turns++;
        if (im < 0 && det < 0 && i2 >= 0) turns--;
        re = r2;
        im = i2;
    }
    return w + turns + atan2_fast(im, re) / (2 * M_PI);
}

double vx_wtree_eval(const vx_wtree *t, const double q[3])
{
    if (!t->nnodes) return 0;
    int stack[STACK], sp = 0;
    double w = 0, far = 0;
    stack[sp++] = 0;
    while (sp) {
        const vx_wtree_node *nd = &t->node[stack[--sp]];
        double d2 = 0;
        for (int k = 0; k < 3; k++)
            d2 += (q[k] - nd->p[k]) * (q[k] - nd->p[k]);
        if (d2 > nd->far2 && nd->far2 > 0) {
            far += far_field(nd, q);
        } else if (nd->kid[0] < 0 && nd->nv) {
            w += leaf_eval(t, nd, q);
        } else if (nd->kid[0] < 0) {
            for (int i = nd->first; i < nd->first + nd->n; i++)
                w += vx_wtree_tri(t->tv + 9 * (size_t)i, q);
        } else {
            stack[sp++] = nd->kid[0];
            stack[sp++] = nd->kid[1];
        }
    }
    return w + far / (4 * M_PI);
}

/* ---- four points at once (AVX2) -----------------------------------------
 * The same operations as vx_wtree_eval, in the same order, each lane one
 * point: the tree walked once for all four (a node opened where any lane
 * is near it, the others masked), each lane's terms summed in its own
 * walk's order. No fused multiply-adds (the target is avx2 alone), and
 * sqrt and the division are IEEE's in both: every lane gives the bits
 * vx_wtree_eval gives. A lane that meets a corner at its point or a
 * triangle seen edge-on (tri_half_angle's fallback) has that leaf
 * summed by leaf_eval itself. */

#if defined(VX_WTREE_AVX2)
typedef double v4d __attribute__((vector_size(32)));
typedef long long v4m __attribute__((vector_size(32))); /* a lane's all ones or zero */

#define V4_ATTR __attribute__((target("avx2"), always_inline)) static inline

V4_ATTR v4d v4_splat(double x)
{
    return (v4d){x, x, x, x};
}
V4_ATTR v4d v4_sel(v4m m, v4d a, v4d b) /* m ? a : b */
{
    return (v4d)(((v4m)a & m) | ((v4m)b & ~m));
}
V4_ATTR int v4_bits(v4m m)
{
    return _mm256_movemask_pd((__m256d)m);
}
V4_ATTR v4m v4_from_bits(int b)
{
    return (v4m){-(long long)(b & 1), -(long long)(b >> 1 & 1), -(long long)(b >> 2 & 1),
                 -(long long)(b >> 3 & 1)};
}

/* atan2_fast, lane by lane. */
V4_ATTR v4d atan2_fast4(v4d y, v4d x)
{
    const v4m sign = (v4m)v4_splat(-0.0);
    v4d ax = (v4d)((v4m)x & ~sign), ay = (v4d)((v4m)y & ~sign);
    v4m xbig = ax > ay;
    v4d mx = v4_sel(xbig, ax, ay), mn = v4_sel(xbig, ay, ax);
    v4d a = mn / mx, s = a * a;
    v4d r = a * (v4_splat(0.9998660) +
                 s * (v4_splat(-0.3302995) +
                      s * (v4_splat(0.1801410) + s * (v4_splat(-0.0851330) + s * 0.0208351))));
    r = v4_sel(ay > ax, v4_splat(M_PI_2) - r, r);
    r = v4_sel(x < 0, v4_splat(M_PI) - r, r);
    r = v4_sel(y < 0, -r, r);
    return v4_sel(mx == 0, v4_splat(0), r);
}

/* far_field, lane by lane. */
V4_ATTR v4d far_field4(const vx_wtree_node *nd, v4d qx, v4d qy, v4d qz)
{
    v4d r0 = nd->p[0] - qx, r1 = nd->p[1] - qy, r2 = nd->p[2] - qz;
    v4d rr = r0 * r0 + r1 * r1 + r2 * r2;
    v4d inv = 1 / (v4d)_mm256_sqrt_pd((__m256d)rr), inv3 = inv * inv * inv, inv5 = inv3 * inv * inv;
    v4d first = (r0 * nd->a[0] + r1 * nd->a[1] + r2 * nd->a[2]) * inv3;
    const double *m = nd->m;
    double tr = m[0] + m[4] + m[8];
    v4d rmr = r0 * (m[0] * r0 + m[1] * r1 + m[2] * r2);
    rmr += r1 * (m[3] * r0 + m[4] * r1 + m[5] * r2);
    rmr += r2 * (m[6] * r0 + m[7] * r1 + m[8] * r2);
    return first + tr * inv3 - 3 * rmr * inv5;
}

/* leaf_eval for the lanes of live (bits); returns the lanes that need
 * leaf_eval itself (a corner at the point, a triangle edge-on). */
V4_ATTR int leaf_eval4(const vx_wtree *t, const vx_wtree_node *nd, v4d qx, v4d qy, v4d qz, int live,
                       v4d *w)
{
    v4d u[3][LEAF_CORNERS];
    const int nv = nd->nv;
    const double *p = t->lv + 3 * (size_t)nd->vfirst;
    v4m at_q = {0, 0, 0, 0};
    for (int v = 0; v < nv; v++) {
        v4d d0 = p[v] - qx, d1 = p[nv + v] - qy, d2 = p[2 * nv + v] - qz;
        v4d l2 = d0 * d0 + d1 * d1 + d2 * d2;
        v4m zero = l2 == 0;
        at_q |= zero;
        v4d inv = 1 / (v4d)_mm256_sqrt_pd((__m256d)(l2 + (v4d)(zero & (v4m)v4_splat(1))));
        u[0][v] = d0 * inv;
        u[1][v] = d1 * inv;
        u[2][v] = d2 * inv;
    }
    v4m edge = {0, 0, 0, 0};
    v4d re = v4_splat(1), im = v4_splat(0), turns = v4_splat(0);
    for (int i = nd->first; i < nd->first + nd->n; i++) {
        const uint8_t *c = t->corner + 3 * (size_t)i;
        const v4d a0 = u[0][c[0]], a1 = u[1][c[0]], a2 = u[2][c[0]];
        const v4d b0 = u[0][c[1]], b1 = u[1][c[1]], b2 = u[2][c[1]];
        const v4d e0 = u[0][c[2]], e1 = u[1][c[2]], e2 = u[2][c[2]];
        v4d det = a0 * (b1 * e2 - b2 * e1) - a1 * (b0 * e2 - b2 * e0) + a2 * (b0 * e1 - b1 * e0);
        v4d den = 1 + (a0 * b0 + a1 * b1 + a2 * b2) + (b0 * e0 + b1 * e1 + b2 * e2) +
                  (e0 * a0 + e1 * a1 + e2 * a2);
        edge |= ~(det * det + den * den > 1e-12);
        v4d r2 = re * den - im * det, i2 = re * det + im * den;
        v4m up = (im >= 0) & (det >= 0) & (i2 < 0), down = (im < 0) & (det < 0) & (i2 >= 0);
        turns += (v4d)(up & (v4m)v4_splat(1)) - (v4d)(down & (v4m)v4_splat(1));
        re = r2;
        im = i2;
    }
    int own = live & ~v4_bits(at_q | edge);
    v4d leaf = v4_splat(0) + turns + atan2_fast4(im, re) / (2 * M_PI);
    *w = v4_sel(v4_from_bits(own), *w + leaf, *w);
    return live & ~own;
}

__attribute__((target("avx2"))) static void eval4_avx2(const vx_wtree *t, const double (*q)[3],
                                                       int n, double *out)
{
    v4d qx, qy, qz;
    for (int l = 0; l < 4; l++) {
        const double *p = q[l < n ? l : 0]; /* lanes past n repeat the first */
        qx[l] = p[0];
        qy[l] = p[1];
        qz[l] = p[2];
    }
    v4d w = v4_splat(0), far = v4_splat(0);
    int stack[STACK], lanes[STACK], sp = 0;
    stack[sp] = 0;
    lanes[sp++] = (1 << n) - 1;
    while (sp) {
        sp--;
        const vx_wtree_node *nd = &t->node[stack[sp]];
        int live = lanes[sp];
        v4d d0 = qx - nd->p[0], d1 = qy - nd->p[1], d2 = qz - nd->p[2];
        v4d dd = d0 * d0 + d1 * d1 + d2 * d2;
        int fl = nd->far2 > 0 ? live & v4_bits(dd > nd->far2) : 0;
        if (fl) far = v4_sel(v4_from_bits(fl), far + far_field4(nd, qx, qy, qz), far);
        live &= ~fl;
        if (!live) continue;
        if (nd->kid[0] >= 0) {
            stack[sp] = nd->kid[0];
            lanes[sp++] = live;
            stack[sp] = nd->kid[1];
            lanes[sp++] = live;
            continue;
        }
        int own = nd->nv ? leaf_eval4(t, nd, qx, qy, qz, live, &w) : live;
        for (int l = 0; l < 4; l++) {
            if (!(own >> l & 1)) continue;
            const double p[3] = {qx[l], qy[l], qz[l]};
            if (nd->nv) {
                w[l] += leaf_eval(t, nd, p);
            } else {
                for (int i = nd->first; i < nd->first + nd->n; i++)
                    w[l] += vx_wtree_tri(t->tv + 9 * (size_t)i, p);
            }
        }
    }
    for (int l = 0; l < n; l++)
        out[l] = w[l] + far[l] / (4 * M_PI);
}

#endif

void vx_wtree_eval4(const vx_wtree *t, const double (*q)[3], int n, double *w)
{
#if defined(VX_WTREE_AVX2)
    if (n > 1 && t->nnodes && vx_cpu_avx2()) return eval4_avx2(t, q, n, w);
#endif
    for (int l = 0; l < n; l++)
        w[l] = vx_wtree_eval(t, q[l]);
}

/* Squared distance between the boxes lo..hi and a..b. */
static double boxes_dist2(const double lo[3], const double hi[3], const double a[3],
                          const double b[3])
{
    double r2 = 0;
    for (int k = 0; k < 3; k++) {
        double g = a[k] > hi[k] ? a[k] - hi[k] : lo[k] > b[k] ? lo[k] - b[k] : 0;
        r2 += g * g;
    }
    return r2;
}

/* A leaf's part of the bound (side as vx_wtree_bound) on the box lo..hi,
 * triangle by triangle: a triangle's winding number has the sign of
 * (corner - q) . normal, so one whose plane the box does not cut and whose
 * sign is not `side` adds nothing; another adds its area over 4 pi times
 * the squared distance between the box and its own bounding box (HUGE_VAL
 * where they touch). */
static double leaf_bound(const vx_wtree *t, const vx_wtree_node *nd, const double lo[3],
                         const double hi[3], int side)
{
    double c[3], e[3], sum = 0;
    for (int k = 0; k < 3; k++) {
        c[k] = (lo[k] + hi[k]) / 2;
        e[k] = (hi[k] - lo[k]) / 2;
    }
    for (int i = nd->first; i < nd->first + nd->n; i++) {
        const double *v = t->tv + 9 * (size_t)i, *n = t->tb + TB * (size_t)i;
        double proj = (v[0] - c[0]) * n[0] + (v[1] - c[1]) * n[1] + (v[2] - c[2]) * n[2];
        double rad = fabs(n[0]) * e[0] + fabs(n[1]) * e[1] + fabs(n[2]) * e[2];
        if ((side > 0 && proj < -rad) || (side < 0 && proj > rad)) continue;
        double g2 = boxes_dist2(lo, hi, n + 4, n + 7);
        if (g2 <= 0) return HUGE_VAL;
        sum += n[3] / g2;
    }
    return sum;
}

double vx_wtree_bound(const vx_wtree *t, const double lo[3], const double hi[3], double limit,
                      int side)
{
    if (!t->nnodes) return 0;
    int stack[STACK], sp = 0;
    double sum = 0;
    stack[sp++] = 0;
    while (sp) {
        const vx_wtree_node *nd = &t->node[stack[--sp]];
        /* the gap between the boxes, no square root: the distance to the
         * ball of radius r about p was tighter for some nodes, but its
         * square root at every node visited cost more (6-8% of the bunny's
         * and suzanne's time at 1024^3) than it saved */
        double g2 = boxes_dist2(lo, hi, nd->lo, nd->hi);
        /* its part, area / g2 (the area over 4 pi), is added where it fits
         * under the limit; with a side, a node worth an eighth of the
         * limit is opened (its leaves' triangles may add nothing).
         * Compared without a division: most nodes visited are opened. */
        double room = side && limit / 8 < limit - sum ? limit / 8 : limit - sum;
        if (nd->area < room * g2) {
            sum += nd->area / g2;
        } else if (nd->kid[0] < 0) {
            double part = g2 > 0 ? nd->area / g2 : HUGE_VAL;
            sum += fmin(part, leaf_bound(t, nd, lo, hi, side));
        } else {
            stack[sp++] = nd->kid[0];
            stack[sp++] = nd->kid[1];
        }
        if (sum >= limit) return sum;
    }
    return sum;
}

#if defined(VX_WTREE_AVX2)
/* ---- four boxes at once (AVX2): vx_wtree_bound's operations, in its
 * order, each lane one box with its own limit and side; a lane stops where
 * vx_wtree_bound returns. Every lane gives vx_wtree_bound's bits. */

/* boxes_dist2 of the lanes' boxes lo..hi and the box a..b. */
V4_ATTR v4d boxes_dist2_4(const v4d lo[3], const v4d hi[3], const double a[3], const double b[3])
{
    v4d r2 = v4_splat(0);
    for (int k = 0; k < 3; k++) {
        v4d g = v4_sel(a[k] > hi[k], a[k] - hi[k], v4_sel(lo[k] > b[k], lo[k] - b[k], v4_splat(0)));
        r2 += g * g;
    }
    return r2;
}

/* leaf_bound, lane by lane (pos, neg: the lanes whose side is +1, -1). */
V4_ATTR v4d leaf_bound4(const vx_wtree *t, const vx_wtree_node *nd, const v4d lo[3],
                        const v4d hi[3], v4m pos, v4m neg)
{
    v4d c[3], e[3], sum = v4_splat(0);
    v4m touch = {0, 0, 0, 0};
    for (int k = 0; k < 3; k++) {
        c[k] = (lo[k] + hi[k]) / 2;
        e[k] = (hi[k] - lo[k]) / 2;
    }
    for (int i = nd->first; i < nd->first + nd->n; i++) {
        const double *v = t->tv + 9 * (size_t)i, *n = t->tb + TB * (size_t)i;
        v4d proj = (v[0] - c[0]) * n[0] + (v[1] - c[1]) * n[1] + (v[2] - c[2]) * n[2];
        v4d rad = fabs(n[0]) * e[0] + fabs(n[1]) * e[1] + fabs(n[2]) * e[2];
        v4m skip = (pos & (proj < -rad)) | (neg & (proj > rad));
        v4d g2 = boxes_dist2_4(lo, hi, n + 4, n + 7);
        v4m add = ~skip & ~touch, zero = g2 <= 0;
        touch |= add & zero;
        sum = v4_sel(add & ~zero, sum + n[3] / g2, sum);
    }
    return v4_sel(touch, v4_splat(HUGE_VAL), sum);
}

__attribute__((target("avx2"))) static void bound4_avx2(const vx_wtree *t, const double (*blo)[3],
                                                        const double (*bhi)[3], const double *limit,
                                                        const int *side, int n, double *out)
{
    v4d lo[3], hi[3], lim, sum = v4_splat(0);
    v4m pos, neg, sided;
    for (int l = 0; l < 4; l++) {
        const int s = l < n ? l : 0; /* lanes past n repeat the first */
        for (int k = 0; k < 3; k++) {
            lo[k][l] = blo[s][k];
            hi[k][l] = bhi[s][k];
        }
        lim[l] = limit[s];
        pos[l] = -(long long)(side[s] > 0);
        neg[l] = -(long long)(side[s] < 0);
    }
    sided = pos | neg;
    const v4d eighth = lim / 8;
    int stack[STACK], lanes[STACK], sp = 0, done = 0;
    stack[sp] = 0;
    lanes[sp++] = (1 << n) - 1;
    while (sp) {
        sp--;
        const vx_wtree_node *nd = &t->node[stack[sp]];
        const int live = lanes[sp] & ~done;
        if (!live) continue;
        v4d g2 = boxes_dist2_4(lo, hi, nd->lo, nd->hi);
        v4d room = v4_sel(sided & (eighth < lim - sum), eighth, lim - sum);
        int fl = live & v4_bits(nd->area < room * g2);
        if (fl) sum = v4_sel(v4_from_bits(fl), sum + nd->area / g2, sum);
        int rest = live & ~fl;
        if (rest && nd->kid[0] < 0) {
            v4d part = v4_sel(g2 > 0, nd->area / g2, v4_splat(HUGE_VAL));
            v4d lb = leaf_bound4(t, nd, lo, hi, pos, neg);
            sum = v4_sel(v4_from_bits(rest), sum + v4_sel(lb < part, lb, part), sum);
        } else if (rest) {
            stack[sp] = nd->kid[0];
            lanes[sp++] = rest;
            stack[sp] = nd->kid[1];
            lanes[sp++] = rest;
        }
        done |= live & v4_bits(sum >= lim);
    }
    for (int l = 0; l < n; l++)
        out[l] = sum[l];
}

#endif

void vx_wtree_bound4(const vx_wtree *t, const double (*lo)[3], const double (*hi)[3],
                     const double *limit, const int *side, int n, double *out)
{
#if defined(VX_WTREE_AVX2)
    if (n > 1 && t->nnodes && vx_cpu_avx2()) return bound4_avx2(t, lo, hi, limit, side, n, out);
#endif
    for (int l = 0; l < n; l++)
        out[l] = vx_wtree_bound(t, lo[l], hi[l], limit[l], side[l]);
}

void vx_wtree_free(vx_wtree *t)
{
    if (!t) return;
    free(t->tv);
    free(t->tb);
    free(t->node);
    free(t->lv);
    free(t->corner);
    memset(t, 0, sizeof *t);
}
