/* The ray caster (seed 002 §4): each pixel's ray walks the sample grid in
 * steps of one grid spacing, the first sample at or above the iso value
 * and the one before it bracket the surface, and the bracket is refined on
 * the trilinear field (bisection, then one secant step) to well under a
 * sample. Blocks of 8^3 cells whose maximum is below the iso value are
 * crossed in one step. Shading is Lambert + ambient. CPU, nthreads
 * threads over interleaved rows. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bandlimit/bandlimit.h"
#include "util/par.h"
#include "util/stop.h"
#include "util/vec3.h"

void vx_bl_camera_ray(const vx_bl_camera *c, int width, int height, double px, double py,
                      double o[3], double d[3])
{
    double u = (px + 0.5) / width * 2 - 1, v = 1 - (py + 0.5) / height * 2;
    double aspect = (double)width / height;
    if (c->ortho) {
        double hh = c->ortho_height / 2, hw = hh * aspect;
        for (int a = 0; a < 3; a++) {
            o[a] = c->eye[a] + c->right[a] * u * hw + c->up[a] * v * hh;
            d[a] = c->fwd[a];
        }
        return;
    }
    double t = tan(c->fov_deg * M_PI / 360), n = 0;
    for (int a = 0; a < 3; a++) {
        o[a] = c->eye[a];
        d[a] = c->fwd[a] + c->right[a] * u * t * aspect + c->up[a] * v * t;
        n += d[a] * d[a];
    }
    n = sqrt(n);
    for (int a = 0; a < 3; a++)
        d[a] /= n;
}

int vx_bl_hits_alloc(vx_bl_hits *h, int width, int height, vx_err *err)
{
    size_t n = (size_t)width * height;
    memset(h, 0, sizeof *h);
    h->width = width;
    h->height = height;
    h->pos = malloc(sizeof(float) * 3 * n);
    h->nrm = malloc(sizeof(float) * 3 * n);
    h->depth = malloc(sizeof(float) * n);
    if (!h->pos || !h->nrm || !h->depth) {
        vx_bl_hits_free(h);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a %dx%d image", width,
                          height);
    }
    return 0;
}

void vx_bl_hits_free(vx_bl_hits *h)
{
    if (!h) return;
    free(h->pos);
    free(h->nrm);
    free(h->depth);
    memset(h, 0, sizeof *h);
}

/* Trilinear f at world o + t d: the caster's inner loop, so in grid
 * units without the general sampler's gradient and checks (the walk stays
 * inside the grid, clamped for rounding only). */
static inline double sample_at(const vx_bl_volume *v, const double o[3], const double d[3],
                               double t)
{
    const int M = v->M;
    const double ih = 1 / v->h;
    int i[3];
    double fr[3];
    for (int a = 0; a < 3; a++) {
        double u = (o[a] + t * d[a] - v->origin[a]) * ih;
        u = u > 0 ? (u < M - 1 ? u : M - 1) : 0; /* NaN: 0, never an index off the grid */
        int k = (int)u;
        k = k > M - 2 ? M - 2 : k;
        i[a] = k;
        fr[a] = u - k;
    }
    const float *p = v->f + ((size_t)i[2] * M + i[1]) * M + i[0];
    const size_t sy = (size_t)M, sz = (size_t)M * M;
    double c00 = p[0] + fr[0] * (p[1] - p[0]);
    double c10 = p[sy] + fr[0] * (p[sy + 1] - p[sy]);
    double c01 = p[sz] + fr[0] * (p[sz + 1] - p[sz]);
    double c11 = p[sz + sy] + fr[0] * (p[sz + sy + 1] - p[sz + sy]);
    double c0 = c00 + fr[1] * (c10 - c00), c1 = c01 + fr[1] * (c11 - c01);
    return c0 + fr[2] * (c1 - c0);
}

/* Ray parameter interval inside [lo, hi]; 0 when the ray misses. */
static int clip_box(const double o[3], const double d[3], const double lo[3], const double hi[3],
                    double *t0, double *t1)
{
    double a = -INFINITY, b = INFINITY;
    for (int k = 0; k < 3; k++) {
        if (fabs(d[k]) < 1e-300) {
            if (o[k] < lo[k] || o[k] > hi[k]) return 0;
            continue;
        }
        double ta = (lo[k] - o[k]) / d[k], tb = (hi[k] - o[k]) / d[k];
        if (ta > tb) {
            double s = ta;
            ta = tb;
            tb = s;
        }
        if (ta > a) a = ta;
        if (tb < b) b = tb;
    }
    if (a < 0) a = 0;
    *t0 = a;
    *t1 = b;
    return a <= b;
}

/* skip[b]: for a block below iso, its Chebyshev distance (in blocks, at
 * most 255) to the nearest block that is not, so that the cube of blocks
 * within skip - 1 of it is empty and can be crossed in one step; 0 for
 * blocks that may hold the surface. Separable: distance along x, then
 * min over y of max(|dy|, that), then the same over z. */
static uint8_t *empty_distance(const vx_bl_volume *v, double iso)
{
    const int nb = v->nb;
    size_t n = (size_t)nb * nb * nb;
    uint8_t *a = malloc(n), *b = malloc(n);
    if (!a || !b) {
        free(a);
        free(b);
        return NULL;
    }
    for (size_t i = 0; i < n; i++)
        a[i] = v->bmax[i] < iso ? 255 : 0;
    /* pass 0 along x (1-D distance), then y and z (min-max) */
    for (int axis = 0; axis < 3; axis++) {
        size_t st = axis == 0 ? 1 : axis == 1 ? (size_t)nb : (size_t)nb * nb;
        for (int p = 0; p < nb; p++)
            for (int q = 0; q < nb; q++) {
                size_t base = axis == 0   ? ((size_t)p * nb + q) * nb
                              : axis == 1 ? (size_t)p * nb * nb + q
                                          : (size_t)p * nb + q;
                for (int i = 0; i < nb; i++) {
                    int best = 255;
                    for (int j = 0; j < nb; j++) {
                        int dd = abs(i - j), val = a[base + j * st];
                        int m = axis == 0 ? (val == 0 ? dd : 255) : (dd > val ? dd : val);
                        if (m < best) best = m;
                    }
                    b[base + i * st] = (uint8_t)best;
                }
            }
        uint8_t *t = a;
        a = b;
        b = t;
    }
    free(b);
    return a;
}

/* The first crossing of iso along o + t d, t in [0, t1] (o in the box):
 * t, or NaN. Every step moves t on (a step below t's precision ends the
 * ray: no hit). */
static double march(const vx_bl_volume *v, const uint8_t *skip, double iso, const double o[3],
                    const double d[3], double t1)
{
    const int nb = v->nb;
    const double dt = v->h, eps = 1e-4 * v->h;
    double t = 0, f = sample_at(v, o, d, t);
    if (f >= iso) return t;
    while (t < t1) {
        /* the block the current point is in: skip it whole when empty */
        int b[3];
        for (int a = 0; a < 3; a++) {
            double u = (o[a] + t * d[a] - v->origin[a]) / v->h;
            int i = (int)floor(u / 8);
            b[a] = i < 0 ? 0 : i >= nb ? nb - 1 : i;
        }
        int r = skip[((size_t)b[2] * nb + b[1]) * nb + b[0]];
        if (r > 0) {
            double te = INFINITY;
            for (int a = 0; a < 3; a++) {
                if (fabs(d[a]) < 1e-300) continue;
                double edge =
                    v->origin[a] + (d[a] > 0 ? (b[a] + r) * 8 : (b[a] - r + 1) * 8) * v->h;
                double ta = (edge - o[a]) / d[a];
                if (ta < te) te = ta;
            }
            double tn = te + eps;
            if (tn <= t) tn = t + eps;
            if (tn > t1 || !(tn > t)) return NAN;
            t = tn;
            f = sample_at(v, o, d, t);
            if (f >= iso) return t; /* only on a block corner, within eps */
            continue;
        }
        /* no crossing closer than (iso - f) / bound: step that far, up to
         * just past the block's exit (the next block has its own bound) */
        double tn = t + dt, lip = v->blip[((size_t)b[2] * nb + b[1]) * nb + b[0]];
        double safe = lip > 0 ? (iso - f) / lip : INFINITY;
        if (safe > dt) {
            double te = INFINITY;
            for (int a = 0; a < 3; a++) {
                if (fabs(d[a]) < 1e-300) continue;
                double edge = v->origin[a] + (d[a] > 0 ? b[a] * 8 + 8 : b[a] * 8) * v->h;
                double ta = (edge - o[a]) / d[a];
                if (ta < te) te = ta;
            }
            tn = t + fmin(safe, fmax(dt, te - t + eps));
        }
        if (tn > t1) tn = t1;
        if (!(tn > t)) break;
        double fn = sample_at(v, o, d, tn);
        if (fn >= iso) {
            double ta = t, fa = f, tb = tn, fb = fn;
            for (int it = 0; it < 8; it++) {
                double tm = 0.5 * (ta + tb), fm = sample_at(v, o, d, tm);
                if (fm >= iso) {
                    tb = tm;
                    fb = fm;
                } else {
                    ta = tm;
                    fa = fm;
                }
            }
            return fb > fa ? ta + (iso - fa) / (fb - fa) * (tb - ta) : tb;
        }
        if (tn >= t1) break;
        t = tn;
        f = fn;
    }
    return NAN;
}

/* The surface along the ray eye + t d: t of the hit (its point in hit), or
 * NaN. */
static double cast_ray(const vx_bl_volume *v, const uint8_t *skip, double iso, const double eye[3],
                       const double d[3], double hit[3])
{
    const int M = v->M;
    double lo[3], hi[3], t0, t1, o[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = v->origin[a];
        hi[a] = v->origin[a] + (M - 1) * v->h;
    }
    if (!clip_box(eye, d, lo, hi, &t0, &t1)) return NAN;
    /* Marched from where the ray enters the box, t from 0: a camera far
     * away (t0 of 1e12 box sizes) would leave steps of 1e-4 voxels below
     * the precision of t, and the march would never end. */
    for (int a = 0; a < 3; a++)
        o[a] = eye[a] + t0 * d[a];
    t1 -= t0;
    /* a ray from no finite point (an eye past the doubles' range) sees
     * nothing */
    if (!(isfinite(o[0]) && isfinite(o[1]) && isfinite(o[2]) && isfinite(t1))) return NAN;
    double th = march(v, skip, iso, o, d, t1);
    if (isnan(th)) return NAN;
    for (int a = 0; a < 3; a++)
        hit[a] = o[a] + th * d[a];
    return t0 + th;
}

/* Pixels go out in 16x16 tiles (neighbouring rays touch the same cache
 * lines of the grid), handed out in order to whichever thread is free. */
#define TILE 16
typedef struct cast_ctx {
    const vx_bl_volume *v;
    double iso;
    const vx_bl_camera *cam;
    vx_bl_hits *h;
    const uint8_t *skip;
    int ntx, ntiles;
    int stop; /* set when the caller's stop hook (util/stop.h) said stop */
    vx_err err;
} cast_ctx;

static void cast_pixel(const cast_ctx *c, int px, int py)
{
    const vx_bl_hits *h = c->h;
    size_t i = (size_t)py * h->width + px;
    double o[3], d[3];
    vx_bl_camera_ray(c->cam, h->width, h->height, px, py, o, d);
    double p[3], g[3], dep = 0;
    double t = cast_ray(c->v, c->skip, c->iso, o, d, p);
    for (int a = 0; a < 3; a++)
        h->pos[3 * i + a] = h->nrm[3 * i + a] = NAN;
    h->depth[i] = NAN;
    if (isnan(t)) return;
    for (int a = 0; a < 3; a++) {
        h->pos[3 * i + a] = (float)p[a];
        dep += (p[a] - c->cam->eye[a]) * c->cam->fwd[a];
    }
    h->depth[i] = (float)(dep + c->cam->depth_add);
    if (!c->v->g[0]) return;
    vx_bl_volume_sample(c->v, p, g);
    double n = vx_v3_norm(g);
    /* a flat field (a tiny D0 keeps only the mean) has no gradient: the
     * hit faces the camera, as the screen-space methods take it (a NaN
     * normal said "missed" on a pixel that hit) */
    for (int a = 0; a < 3; a++)
        h->nrm[3 * i + a] = (float)(n > 0 ? -g[a] / n : -c->cam->fwd[a]);
}

/* Tile k (vx_par_for). The calling thread (t = 0) polls its stop hook
 * before each tile (the helper threads have none: theirs always says go
 * on) and stops them all. */
static int cast_tile(int k, int t, void *arg)
{
    cast_ctx *c = arg;
    vx_err e;
    if (t == 0 && vx_stop_poll(&e)) {
        c->stop = 1;
        c->err = e;
        return 1;
    }
    int x0 = (k % c->ntx) * TILE, y0 = (k / c->ntx) * TILE;
    for (int py = y0; py < y0 + TILE && py < c->h->height; py++)
        for (int px = x0; px < x0 + TILE && px < c->h->width; px++)
            cast_pixel(c, px, py);
    return 0;
}

int vx_bl_cast(const vx_bl_volume *v, double iso, const vx_bl_camera *cam, int nthreads,
               vx_bl_hits *h, vx_err *err)
{
    if (!v->bmax || !v->blip || v->M < 2)
        return vx_err_set(err, VX_EINTERNAL, "internal", "cast: volume without blocks");
    cast_ctx c = {.v = v, .iso = iso, .cam = cam, .h = h, .ntx = (h->width + TILE - 1) / TILE};
    c.ntiles = c.ntx * ((h->height + TILE - 1) / TILE);
    uint8_t *skip = empty_distance(v, iso);
    if (!skip) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the caster");
    c.skip = skip;
    vx_par_for(c.ntiles, nthreads, cast_tile, &c);
    free(skip);
    if (c.stop) {
        if (err) *err = c.err;
        return -1;
    }
    return 0;
}

int vx_bl_shade(const vx_bl_hits *h, const vx_bl_shade_desc *d, float *rgb, vx_err *err)
{
    size_t n = (size_t)h->width * h->height;
    double dmin = INFINITY, dmax = -INFINITY;
    if (d->depth_only)
        for (size_t i = 0; i < n; i++)
            if (!isnan(h->depth[i])) {
                if (h->depth[i] < dmin) dmin = h->depth[i];
                if (h->depth[i] > dmax) dmax = h->depth[i];
            }
    for (size_t i = 0; i < n; i++) {
        if ((i & 0xffff) == 0 && vx_stop_poll(err)) return -1;
        float *o = rgb + 3 * i;
        if (isnan(h->depth[i])) {
            for (int a = 0; a < 3; a++)
                o[a] = (float)d->background[a];
            continue;
        }
        double light[3] = {d->ambient, d->ambient, d->ambient};
        if (d->depth_only) {
            double s = dmax > dmin ? 1 - (h->depth[i] - dmin) / (dmax - dmin) : 1;
            for (int a = 0; a < 3; a++)
                light[a] += (1 - d->ambient) * (0.15 + 0.85 * s);
        } else if (!isnan(h->nrm[3 * i])) {
            for (int l = 0; l < d->nlights; l++) {
                double c = 0;
                for (int a = 0; a < 3; a++)
                    c += h->nrm[3 * i + a] * d->lights[l].dir[a];
                if (c > 0)
                    for (int a = 0; a < 3; a++)
                        light[a] += c * d->lights[l].color[a];
            }
        }
        for (int a = 0; a < 3; a++) {
            double x = d->color[a] * light[a];
            o[a] = (float)(x < 0 ? 0 : x > 1 ? 1 : x);
        }
    }
    return 0;
}
