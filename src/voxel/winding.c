/* inside "winding" (voxel.h): voxel centres where the generalized winding
 * number of the mesh (Jacobson et al. 2013) is at least 1/2, on the CPU.
 *
 * The winding number w of the mesh S at q is split in two. The boundary
 * of S (its directed edges not cancelled by an opposite twin, vertices
 * welded by position) is closed by cones K of triangles, one apex per
 * connected part of the boundary (a hole), so that S + K has no boundary.
 * Then w_S(q) = w_{S+K}(q) - w_K(q), where w_{S+K}(q) is an integer: the
 * signed crossings of S + K along the z ray above q (front +1 where the
 * surface faces +z), counted exactly per voxel column by a CPU rasterizer
 * with watertight edge tests. w_K is smooth between K's crossings. On a
 * run of centres between two crossings, when a bound of |w_K| (area over
 * squared distance per tree node) stays under the crossing count's margin
 * to 1/2, the count decides alone; else w_K is evaluated with a tree over
 * K (wtree.c, Barill et al. 2018) at both ends of the run (and its middle
 * when it is over 8 voxels), and where they disagree about w >= 1/2 the
 * run is halved until the change is found. A closed mesh has no cone:
 * then w is the crossing count and nothing is evaluated. Centres outside
 * the mesh's bounding box are outside (|w| < 1/2 outside its convex hull).
 *
 * The approximation: a run whose sampled centres agree is filled as they
 * say, so a dip of w across 1/2 and back between two samples is missed
 * (a column that grazes a hole's rim, where w varies fastest); far nodes
 * of the tree carry an error of about (1/beta)^3 of their field. */
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "util/clock.h"
#include "util/par.h"
#include "voxel/voxel.h"
#include "voxel/winding_int.h"

#define BAND 8 /* column rows per raster task */

typedef struct wctx {
    const vx_mesh *m;
    const vx_voxelize_desc *d;
    double *cone; /* 9 doubles per cone triangle */
    size_t ncone, ntot;
    int nx, ny, nz, nbands;
    double o[3], h;
    double ix[3];    /* grid.index_offset: centre i of axis a is o + (ix + i + 1/2) h */
    size_t *bin_off; /* nbands + 1 */
    uint32_t *bin;   /* triangle ids per band */
    uint32_t *cnt;   /* crossings per column (pass 1), then fill cursor */
    size_t *off;     /* ncols + 1 */
    double *z;       /* crossing heights in voxel units (voxel k's centre at k) */
    int8_t *sg;      /* +1 front (facing +z), -1 back */
    int pass;        /* 0 count, 1 fill */
    vx_wtree tree;
    int lo[3], hi[3], open; /* centres that can be inside (the bbox for an open mesh) */
    vx_bitgrid *out;
    atomic_int stop, done;
    int total;
    double p0, p1, last; /* progress span, last report */
    vx_err err;
} wctx;

static void tri_of(const wctx *c, size_t t, double v[9])
{
    if (t < c->m->ntris) {
        for (int q = 0; q < 3; q++)
            memcpy(v + 3 * q, c->m->pos + 3 * (size_t)c->m->tri[3 * t + q], 3 * sizeof *v);
    } else {
        memcpy(v, c->cone + 9 * (t - c->m->ntris), 9 * sizeof *v);
    }
}

/* ---- crossings per column --------------------------------------------- */

/* Column range [*lo, *hi] whose centres o + (i + 1/2) h may fall in
 * [a, b] (one more each side against rounding; the exact test decides). */
static void col_range(double a, double b, double o, double ix, double h, int n, int *lo, int *hi)
{
    double fa = floor((a - o) / h - ix - 0.5), fb = ceil((b - o) / h - ix - 0.5);
    int l = fa < 0 ? 0 : fa > n ? n : (int)fa, u = fb < -1 ? -1 : fb > n - 1 ? n - 1 : (int)fb;
    /* then exactly the centres in [a, b], computed as the tests compute them
     * (one outside cannot be in the triangle, even perturbed) */
    while (l <= u && o + (ix + l + 0.5) * h < a)
        l++;
    while (u >= l && o + (ix + u + 0.5) * h > b)
        u--;
    *lo = l;
    *hi = u;
}

#define MIN3(a, b, c) ((a) < (b) ? ((a) < (c) ? (a) : (c)) : ((b) < (c) ? (b) : (c)))
#define MAX3(a, b, c) ((a) > (b) ? ((a) > (c) ? (a) : (c)) : ((b) > (c) ? (b) : (c)))

/* One edge of a triangle, evaluated identically for both triangles that
 * share it: from its lexicographically smaller end point, with a
 * perturbation of the query point by (eps, eps^2) when it lies on it. */
typedef struct edge {
    double lx, ly, dx, dy;
    int flip, tie; /* tie: the side of a point exactly on the edge */
} edge;

static int lex_less(const double *p, const double *q)
{
    for (int k = 0; k < 3; k++)
        if (p[k] != q[k]) return p[k] < q[k];
    return 0;
}

static void edge_set(edge *e, const double *a, const double *b)
{
    e->flip = lex_less(b, a);
    const double *l = e->flip ? b : a, *u = e->flip ? a : b;
    e->lx = l[0];
    e->ly = l[1];
    e->dx = u[0] - l[0];
    e->dy = u[1] - l[1];
    /* d/d eps of dx (qy + eps^2 - ly) - dy (qx + eps - lx) */
    e->tie = e->dy != 0 ? (e->dy < 0 ? 1 : -1) : e->dx > 0 ? 1 : e->dx < 0 ? -1 : 0;
}

/* Signed edge function of q (sign = side, 0 only for a point edge). */
static double edge_eval(const edge *e, double qx, double qy, int *side)
{
    double v = e->dx * (qy - e->ly) - e->dy * (qx - e->lx);
    int s = v > 0 ? 1 : v < 0 ? -1 : e->tie;
    *side = e->flip ? -s : s;
    return e->flip ? -v : v;
}

static void add_crossing(wctx *c, size_t col, double z, int s)
{
    if (c->pass == 0) {
        c->cnt[col]++;
        return;
    }
    size_t at = c->off[col] + c->cnt[col]++;
    c->z[at] = (z - c->o[2]) / c->h - c->ix[2] - 0.5;
    c->sg[at] = (int8_t)s;
}

/* Triangle t's crossings of the columns of rows [j0, j1). */
static void raster_tri(wctx *c, size_t t, int j0, int j1)
{
    double v[9];
    tri_of(c, t, v);
    double x0 = MIN3(v[0], v[3], v[6]), x1 = MAX3(v[0], v[3], v[6]);
    double y0 = MIN3(v[1], v[4], v[7]), y1 = MAX3(v[1], v[4], v[7]);
    int ilo, ihi, jlo, jhi;
    col_range(x0, x1, c->o[0], c->ix[0], c->h, c->nx, &ilo, &ihi);
    col_range(y0, y1, c->o[1], c->ix[1], c->h, c->ny, &jlo, &jhi);
    if (jlo < j0) jlo = j0;
    if (jhi > j1 - 1) jhi = j1 - 1;
    edge e[3]; /* e[q] is the edge opposite vertex q */
    for (int q = 0; q < 3; q++)
        edge_set(&e[q], v + 3 * ((q + 1) % 3), v + 3 * ((q + 2) % 3));
    for (int j = jlo; j <= jhi; j++) {
        double qy = c->o[1] + (c->ix[1] + j + 0.5) * c->h;
        for (int i = ilo; i <= ihi; i++) {
            double qx = c->o[0] + (c->ix[0] + i + 0.5) * c->h, f[3];
            int s[3];
            for (int q = 0; q < 3; q++)
                f[q] = edge_eval(&e[q], qx, qy, &s[q]);
            if (s[0] == 0 || s[0] != s[1] || s[1] != s[2]) continue;
            double sum = f[0] + f[1] + f[2];
            double z = sum != 0 ? (f[0] * v[2] + f[1] * v[5] + f[2] * v[8]) / sum
                                : (v[2] + v[5] + v[8]) / 3;
            add_crossing(c, (size_t)j * c->nx + i, z, s[0]);
        }
    }
}

/* Progress and the stop check from the calling thread (t = 0); every
 * thread stops once it said stop. */
static int poll(wctx *c, int t)
{
    if (atomic_load(&c->stop)) return 1;
    if (t != 0 || !c->d->progress) return 0;
    double now = vx_mono();
    if (now - c->last < 0.01) return 0;
    c->last = now;
    double f = c->p0 + (c->p1 - c->p0) * atomic_load(&c->done) / (c->total ? c->total : 1);
    if (c->d->progress(c->d->ud, f, &c->err)) {
        atomic_store(&c->stop, 1);
        return 1;
    }
    return 0;
}

static int raster_band(int b, int t, void *ud)
{
    wctx *c = ud;
    if (poll(c, t)) return 1;
    int j0 = b * BAND, j1 = j0 + BAND < c->ny ? j0 + BAND : c->ny;
    /* a band of a triangle soup can hold 10^5 large triangles: the stop
     * check comes every 64 of them, not only between bands */
    for (size_t k = c->bin_off[b]; k < c->bin_off[b + 1]; k++) {
        if ((k & 63) == 63 && poll(c, t)) return 1;
        raster_tri(c, c->bin[k], j0, j1);
    }
    atomic_fetch_add(&c->done, 1);
    return 0;
}

/* Triangles by the bands of rows their columns may fall in. */
static int bin_tris(wctx *c, vx_err *err)
{
    c->bin_off = calloc((size_t)c->nbands + 2, sizeof *c->bin_off);
    if (!c->bin_off) goto oom;
    for (int pass = 0; pass < 2; pass++) {
        for (size_t t = 0; t < c->ntot; t++) {
            double v[9];
            tri_of(c, t, v);
            int lo, hi, ilo, ihi;
            col_range(MIN3(v[1], v[4], v[7]), MAX3(v[1], v[4], v[7]), c->o[1], c->ix[1], c->h,
                      c->ny, &lo, &hi);
            col_range(MIN3(v[0], v[3], v[6]), MAX3(v[0], v[3], v[6]), c->o[0], c->ix[0], c->h,
                      c->nx, &ilo, &ihi);
            if (lo > hi || ilo > ihi) continue;
            for (int b = lo / BAND; b <= hi / BAND; b++) {
                if (pass == 0)
                    c->bin_off[b + 1]++;
                else
                    c->bin[c->bin_off[b]++] = (uint32_t)t;
            }
        }
        if (pass == 0) {
            for (int b = 0; b < c->nbands; b++)
                c->bin_off[b + 1] += c->bin_off[b];
            c->bin = malloc(c->bin_off[c->nbands] * sizeof *c->bin + 1);
            if (!c->bin) goto oom;
        } else {
            memmove(c->bin_off + 1, c->bin_off, (size_t)c->nbands * sizeof *c->bin_off);
            c->bin_off[0] = 0;
        }
    }
    return 0;
oom:
    return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the triangle bins");
}

/* ---- inside per column ------------------------------------------------ */

static void set_bit(wctx *c, int i, int j, int k)
{
    vx_bitgrid *g = c->out;
    g->bits[((size_t)k * (size_t)c->ny + (size_t)j) * g->wx + (size_t)(i >> 5)] |= 1u << (i & 31);
}

/* w >= 1/2 at centre k of column (i, j), whose crossing count above is n. */
static int inside_at(const wctx *c, int i, int j, int k, int n)
{
    double q[3] = {c->o[0] + (c->ix[0] + i + 0.5) * c->h, c->o[1] + (c->ix[1] + j + 0.5) * c->h,
                   c->o[2] + (c->ix[2] + k + 0.5) * c->h};
    return n - vx_wtree_eval(&c->tree, q) >= 0.5;
}

/* 1 when the cone's |w| stays under |n - 1/2| on centres ka..kb of column
 * (i, j): there w >= 1/2 exactly where n >= 1, with nothing evaluated. */
static int far_run(const wctx *c, int i, int j, int ka, int kb, int n)
{
    double a[3] = {c->o[0] + (c->ix[0] + i + 0.5) * c->h, c->o[1] + (c->ix[1] + j + 0.5) * c->h,
                   c->o[2] + (c->ix[2] + ka + 0.5) * c->h};
    double b[3] = {a[0], a[1], c->o[2] + (c->ix[2] + kb + 0.5) * c->h};
    double limit = fabs(n - 0.5);
    return vx_wtree_bound(&c->tree, a, b, limit) < limit;
}

/* Centres ka..kb of one run between crossings: ends known (da, db). */
static void fill_run(wctx *c, int i, int j, int ka, int kb, int da, int db, int n)
{
    if (da == db) {
        if (da)
            for (int k = ka; k <= kb; k++)
                set_bit(c, i, j, k);
        return;
    }
    if (kb - ka <= 1) {
        if (da) set_bit(c, i, j, ka);
        if (db) set_bit(c, i, j, kb);
        return;
    }
    int km = ka + (kb - ka) / 2, dm = inside_at(c, i, j, km, n);
    fill_run(c, i, j, ka, km, da, dm, n);
    fill_run(c, i, j, km + 1, kb, inside_at(c, i, j, km + 1, n), db, n);
}

typedef struct zs {
    double z;
    int s;
} zs;

static int zs_cmp(const void *a, const void *b)
{
    double x = ((const zs *)a)->z, y = ((const zs *)b)->z;
    return x < y ? -1 : x > y;
}

static void sort_column(double *z, int8_t *s, size_t n)
{
    zs *t = n > 64 ? malloc(n * sizeof *t) : NULL;
    if (t) { /* long columns; without memory, the insertion sort below */
        for (size_t a = 0; a < n; a++)
            t[a] = (zs){z[a], s[a]};
        qsort(t, n, sizeof *t, zs_cmp);
        for (size_t a = 0; a < n; a++) {
            z[a] = t[a].z;
            s[a] = (int8_t)t[a].s;
        }
        free(t);
        return;
    }
    for (size_t a = 1; a < n; a++) {
        double zv = z[a];
        int8_t sv = s[a];
        size_t b = a;
        for (; b > 0 && z[b - 1] > zv; b--) {
            z[b] = z[b - 1];
            s[b] = s[b - 1];
        }
        z[b] = zv;
        s[b] = sv;
    }
}

static void column(wctx *c, int i, int j)
{
    size_t col = (size_t)j * c->nx + i, n = c->off[col + 1] - c->off[col];
    double *z = c->z + c->off[col];
    int8_t *s = c->sg + c->off[col];
    sort_column(z, s, n);
    int cnt = 0;
    for (size_t a = 0; a < n; a++)
        cnt += s[a];
    for (size_t r = 0; r <= n; r++) {
        /* run r: centres k with z[r-1] <= k < z[r] have cnt crossings above */
        double lo = r ? ceil(z[r - 1]) : -HUGE_VAL, hi = r < n ? ceil(z[r]) - 1 : HUGE_VAL;
        int ka = lo < c->lo[2] ? c->lo[2] : (int)fmin(lo, INT32_MAX / 2);
        int kb = hi > c->hi[2] ? c->hi[2] : (int)fmax(hi, -1.0);
        if (ka <= kb) {
            if (!c->open || far_run(c, i, j, ka, kb, cnt)) {
                fill_run(c, i, j, ka, kb, cnt >= 1, cnt >= 1, cnt);
            } else {
                int da = inside_at(c, i, j, ka, cnt),
                    db = ka == kb ? da : inside_at(c, i, j, kb, cnt);
                if (kb - ka >= 8 && da == db) {
                    int km = ka + (kb - ka) / 2, dm = inside_at(c, i, j, km, cnt);
                    if (dm != da) {
                        fill_run(c, i, j, ka, km, da, dm, cnt);
                        fill_run(c, i, j, km + 1, kb, inside_at(c, i, j, km + 1, cnt), db, cnt);
                        goto next;
                    }
                }
                fill_run(c, i, j, ka, kb, da, db, cnt);
            }
        }
    next:
        if (r < n) cnt -= s[r];
    }
}

static int fill_row(int j, int t, void *ud)
{
    wctx *c = ud;
    if (poll(c, t)) return 1;
    if (j >= c->lo[1] && j <= c->hi[1])
        for (int i = c->lo[0]; i <= c->hi[0]; i++) {
            if (poll(c, t)) return 1; /* a column of a soup can take 0.1 s */
            column(c, i, j);
        }
    atomic_fetch_add(&c->done, 1);
    return 0;
}

/* ---- the driver --------------------------------------------------------- */

/* A parallel stage over n items, progress from p0 to p1. */
static int stage(wctx *c, int n, int (*fn)(int, int, void *), double p0, double p1, vx_err *err)
{
    atomic_store(&c->done, 0);
    c->total = n;
    c->p0 = p0;
    c->p1 = p1;
    vx_par_for(n, vx_par_cpus(), fn, c);
    if (atomic_load(&c->stop)) {
        if (err) *err = c->err;
        return -1;
    }
    return 0;
}

/* Counts, checks memory, then places every crossing of every column. */
static int crossings(wctx *c, vx_err *err)
{
    size_t ncols = (size_t)c->nx * c->ny;
    c->cnt = calloc(ncols + 1, sizeof *c->cnt);
    c->off = malloc((ncols + 1) * sizeof *c->off);
    if (!c->cnt || !c->off)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the columns");
    c->pass = 0;
    if (stage(c, c->nbands, raster_band, 0.0, 0.15, err)) return -1;
    c->off[0] = 0;
    for (size_t i = 0; i < ncols; i++)
        c->off[i + 1] = c->off[i] + c->cnt[i];
    size_t n = c->off[ncols];
    uint64_t bytes = vx_bitgrid_bytes(c->out->grid.dims, 1) + (uint64_t)n * 9 +
                     (uint64_t)ncols * 12 + c->bin_off[c->nbands] * 4;
    if (c->d->max_memory && bytes > c->d->max_memory)
        return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                          "the winding rule needs %llu bytes for %zu crossings of %zu columns, "
                          "over the job memory limit of %llu",
                          (unsigned long long)bytes, n, ncols,
                          (unsigned long long)c->d->max_memory);
    c->z = malloc(n * sizeof *c->z + 1);
    c->sg = malloc(n + 1);
    if (!c->z || !c->sg)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %zu crossings", n);
    memset(c->cnt, 0, ncols * sizeof *c->cnt);
    c->pass = 1;
    return stage(c, c->nbands, raster_band, 0.15, 0.3, err);
}

/* The centres that can be inside: the grid, and for an open mesh those in
 * the mesh's bounding box. */
static void inside_range(wctx *c)
{
    const int n[3] = {c->nx, c->ny, c->nz};
    for (int a = 0; a < 3; a++) {
        c->lo[a] = 0;
        c->hi[a] = n[a] - 1;
        if (!c->open) continue;
        double lo = ceil((c->m->bbox_min[a] - c->o[a]) / c->h - c->ix[a] - 0.5),
               hi = floor((c->m->bbox_max[a] - c->o[a]) / c->h - c->ix[a] - 0.5);
        if (lo > c->lo[a]) c->lo[a] = lo > n[a] ? n[a] : (int)lo;
        if (hi < c->hi[a]) c->hi[a] = hi < -1 ? -1 : (int)hi;
    }
}

int vx_voxelize_winding(const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                        vx_voxelize_stats *st, vx_err *err)
{
    memset(st, 0, sizeof *st);
    st->method = "winding";
    memset(out, 0, sizeof *out);
    double t0 = vx_mono();
    wctx *c = calloc(1, sizeof *c);
    if (!c) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the job");
    c->m = m;
    c->d = d;
    c->nx = d->grid.dims[0];
    c->ny = d->grid.dims[1];
    c->nz = d->grid.dims[2];
    c->nbands = (c->ny + BAND - 1) / BAND;
    memcpy(c->o, d->grid.origin, sizeof c->o);
    for (int a = 0; a < 3; a++)
        c->ix[a] = (double)d->grid.index[a];
    c->h = d->grid.h;
    c->out = out;
    int rc = -1;
    if (vx_bitgrid_alloc(out, &d->grid, 0, err) || vx_wcone_build(m, &c->cone, &c->ncone, err))
        goto done;
    c->ntot = m->ntris + c->ncone;
    c->open = c->ncone > 0;
    if (vx_wtree_build(&c->tree, c->ncone, c->cone, err) || bin_tris(c, err)) goto done;
    st->upload_ms = (vx_mono() - t0) * 1e3;
    if (crossings(c, err)) goto done;
    inside_range(c);
    if (stage(c, c->ny, fill_row, 0.3, 1.0, err)) goto done;
    st->voxels_inside = vx_bitgrid_count(out);
    st->chunks = 1;
    rc = 0;
done:
    st->gpu_fill_ms = 0;
    st->readback_ms = 0;
    if (rc) vx_bitgrid_free(out);
    vx_wtree_free(&c->tree);
    free(c->cone);
    free(c->bin_off);
    free(c->bin);
    free(c->cnt);
    free(c->off);
    free(c->z);
    free(c->sg);
    free(c);
    return rc;
}

vx_inside vx_voxelize_default_inside(const vx_mesh *m, const vx_voxelize_desc *d)
{
    int fits = d->method == VX_METHOD_AUTO && d->fill == VX_FILL_SOLID &&
               (d->supersample != 2 || d->samples == VX_SAMPLES_FACES);
    return m->boundary_edges > 0 && fits ? VX_INSIDE_WINDING : VX_INSIDE_NONZERO;
}
