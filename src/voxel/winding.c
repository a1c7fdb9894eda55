/* inside "winding" (voxel.h): voxel centres where the generalized winding
 * number of the mesh (Jacobson et al. 2013) is at least 1/2, on the CPU.
 *
 * The winding number w of the mesh S at q is split in two. The boundary
 * of S (its directed edges not cancelled by an opposite twin, vertices
 * welded by position) is closed by cones K of triangles, one apex per
 * connected part of the boundary (a hole), so that S + K has no boundary.
 * Then w_S(q) = w_{S+K}(q) - w_K(q), where w_{S+K}(q) is an integer: the
 * signed crossings of S + K along the z ray above q (front +1 where the
 * surface faces +z), counted exactly per voxel column by lattice.h's
 * rules (cpu.c's, along z): coverage by exact integer edge tests on the
 * positions snapped to 1/256 voxel in the lattice, each crossing placed
 * at its first centre at or beyond it by the shaders' formula, so a
 * centre on a face counts half-open [entry, exit) along every axis and a
 * brick gives the whole grid's voxels. w_K is smooth between K's
 * crossings. On a run of centres between two crossings, when a bound of |w_K| (area over
 * squared distance per tree node) stays under the crossing count's margin
 * to 1/2, the count decides alone; else w_K is evaluated with a tree over
 * K (wtree.c, Barill et al. 2018) at both ends of the run (and its middle
 * when it is over 8 voxels), and where they disagree about w >= 1/2 the
 * run is split (fill_run) until the change is found. A closed mesh has no cone:
 * then w is the crossing count and nothing is evaluated. Centres outside
 * the mesh's bounding box are outside (|w| < 1/2 outside its convex hull).
 *
 * The approximation: a run whose sampled centres agree is filled as they
 * say, so a dip of w across 1/2 and back between two samples is missed
 * (a column that grazes a hole's rim, where w varies fastest); far nodes
 * of the tree carry an error of about (1/beta)^3 of their field. */
#include <limits.h>
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "util/clock.h"
#include "util/par.h"
#include "voxel/lattice.h"
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
    double ix[3];     /* grid.index_offset: centre i of axis a is o + (ix + i + 1/2) h */
    int64_t index[3]; /* the same, as integers */
    double *lat;      /* lattice units (p - o) / h: 3 a mesh vertex, then 9 a cone triangle */
    size_t *bin_off;  /* nbands + 1 */
    uint32_t *bin;    /* triangle ids per band */
    uint32_t *cnt;    /* crossings per column (pass 1), then fill cursor */
    size_t *off;      /* ncols + 1 */
    int32_t *z;       /* per crossing, the first centre k at or beyond it */
    int8_t *sg;       /* +1 front (facing +z), -1 back */
    int pass;         /* 0 count, 1 fill */
    vx_wtree tree;
    int lo[3], hi[3], open; /* centres that can be inside (the bbox for an open mesh) */
    /* An open mesh's runs along z are cut to its bbox's centres rlo..rhi,
     * counted from this brick but not cut to it: a run is sampled the same
     * way in every brick it crosses (and the whole grid's). */
    int rlo, rhi;
    vx_bitgrid *out;
    atomic_int stop, done;
    int total;
    double p0, p1, last; /* progress span, last report */
    vx_err err;
} wctx;

/* ---- crossings per column --------------------------------------------- */

/* Triangle t's vertices in the lattice's units, x y z each. */
static void tri_lat(const wctx *c, size_t t, double u[9])
{
    if (t < c->m->ntris) {
        for (int q = 0; q < 3; q++)
            memcpy(u + 3 * q, c->lat + 3 * (size_t)c->m->tri[3 * t + q], 3 * sizeof *u);
    } else {
        memcpy(u, c->lat + 3 * c->m->nverts + 9 * (t - c->m->ntris), 9 * sizeof *u);
    }
}

/* Triangle t's snapped (x, y) corners, counter-clockwise, and the column
 * centres its snapped bounding box holds; its crossings' sign (+1 facing
 * +z), or 0 when it covers no centre (edge-on to z, or off the grid). */
static int tri_cols(const wctx *c, const double u[9], int64_t P[3][2], int r[4])
{
    for (int q = 0; q < 3; q++) {
        P[q][0] = vx_lattice_snap(u[3 * q]);
        P[q][1] = vx_lattice_snap(u[3 * q + 1]);
    }
    vx_i128 det = vx_lattice_det(P[0], P[1], P[2]);
    if (det == 0) return 0;
    if (det < 0) { /* counter-clockwise for the edge tests */
        int64_t tmp[2] = {P[1][0], P[1][1]};
        memcpy(P[1], P[2], sizeof tmp);
        memcpy(P[2], tmp, sizeof tmp);
    }
    const int n[2] = {c->nx, c->ny};
    for (int a = 0; a < 2; a++) {
        int64_t lo = P[0][a], hi = P[0][a];
        for (int q = 1; q < 3; q++) {
            lo = P[q][a] < lo ? P[q][a] : lo;
            hi = P[q][a] > hi ? P[q][a] : hi;
        }
        vx_lattice_centres(lo, hi, c->index[a], n[a], &r[2 * a], &r[2 * a + 1]);
        if (r[2 * a] > r[2 * a + 1]) return 0;
    }
    return det > 0 ? 1 : -1;
}

/* Crossing of column col: kb, the first centre at or beyond it, sign s. */
static void add_crossing(wctx *c, size_t col, int32_t kb, int s)
{
    if (c->pass == 0) {
        c->cnt[col]++;
        return;
    }
    size_t at = c->off[col] + c->cnt[col]++;
    c->z[at] = kb;
    c->sg[at] = (int8_t)s;
}

/* Triangle t's crossings of the columns of rows [j0, j1): coverage by
 * lattice.h's snapped edge tests, each crossing placed by its formula with
 * z as the ray's axis. */
static void raster_tri(wctx *c, size_t t, int j0, int j1)
{
    double u[9];
    tri_lat(c, t, u);
    int64_t P[3][2];
    int r[4];
    int sign = tri_cols(c, u, P, r);
    if (!sign) return;
    int jlo = r[2] < j0 ? j0 : r[2], jhi = r[3] > j1 - 1 ? j1 - 1 : r[3];
    const int64_t S = (int64_t)VX_GRID_SNAP;
    int64_t cx0 = (c->index[0] + r[0]) * S + S / 2, cy0 = (c->index[1] + jlo) * S + S / 2;
    vx_lattice_edge e[3];
    for (int q = 0; q < 3; q++)
        vx_lattice_edge_set(&e[q], P[q], P[(q + 1) % 3], cx0, cy0);
    /* (z, x, y): the ray's axis first */
    double a[3] = {u[2], u[0], u[1]}, e1[3] = {u[5] - u[2], u[3] - u[0], u[4] - u[1]},
           e2[3] = {u[8] - u[2], u[6] - u[0], u[7] - u[1]};
    for (int j = jlo; j <= jhi; j++) {
        vx_i128 f0 = e[0].at, f1 = e[1].at, f2 = e[2].at;
        double cy = (c->ix[1] + j) + 0.5;
        for (int i = r[0]; i <= r[1]; i++) {
            if (f0 > 0 && f1 > 0 && f2 > 0)
                add_crossing(c, (size_t)j * c->nx + i,
                             vx_lattice_xing(a, e1, e2, (c->ix[0] + i) + 0.5, cy, c->ix[2]), sign);
            f0 += e[0].d1;
            f1 += e[1].d1;
            f2 += e[2].d1;
        }
        for (int q = 0; q < 3; q++)
            e[q].at += e[q].d2;
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
            double u[9];
            tri_lat(c, t, u);
            int64_t P[3][2];
            int r[4];
            if (!tri_cols(c, u, P, r)) continue;
            for (int b = r[2] / BAND; b <= r[3] / BAND; b++) {
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

/* Voxel (i, k) of the row being filled: its slice of the grid, the words
 * of every z row for this y, contiguous (a column's voxels are a row of
 * the grid apart: set in place they missed the cache at every bit). */
static void set_bit(const wctx *c, uint32_t *slice, int i, int k)
{
    slice[(size_t)k * c->out->wx + (size_t)(i >> 5)] |= 1u << (i & 31);
}

/* n - w - 1/2 at centre k of column (i, j), whose crossing count above
 * is n: the centre is inside (w >= 1/2) where it is >= 0. */
static double margin_at(const wctx *c, int i, int j, int k, int n)
{
    double q[3] = {c->o[0] + (c->ix[0] + i + 0.5) * c->h, c->o[1] + (c->ix[1] + j + 0.5) * c->h,
                   c->o[2] + (c->ix[2] + k + 0.5) * c->h};
    return n - vx_wtree_eval(&c->tree, q) - 0.5;
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

/* Centres ka..kb of one run between crossings, the margins at its ends
 * known (fa, fb; margin_at), the run possibly reaching past the brick:
 * only its centres in the brick are set, and only parts that reach into
 * the brick are looked at (which decides nothing in it: each part is
 * decided from its own samples). Where the ends disagree, the run is
 * split where the margin's straight line through them crosses 0 (w is
 * smooth along a run: the change is found in a few samples, not log2 of
 * the run's length), or at its middle when the last split did not halve
 * the part (prev, the length before it), as regula falsi can stall. */
static void fill_run(wctx *c, uint32_t *slice, int i, int j, int ka, int kb, double fa, double fb,
                     int n, int prev)
{
    if (kb < 0 || ka > c->nz - 1) return;
    int da = fa >= 0, db = fb >= 0;
    if (da == db) {
        int k0 = ka < 0 ? 0 : ka, k1 = kb > c->nz - 1 ? c->nz - 1 : kb;
        if (da)
            for (int k = k0; k <= k1; k++)
                set_bit(c, slice, i, k);
        return;
    }
    if (kb - ka <= 1) {
        if (da && ka >= 0) set_bit(c, slice, i, ka);
        if (db && kb < c->nz) set_bit(c, slice, i, kb);
        return;
    }
    int km = ka + (kb - ka) / 2;
    if (2 * (kb - ka) <= prev) {
        double t = fa / (fa - fb) * (kb - ka); /* in [0, kb - ka]: the ends' signs differ */
        if (t >= 0 && t <= kb - ka) {          /* (not a NaN) */
            km = ka + (int)t;
            if (km > kb - 1) km = kb - 1;
        }
    }
    if (km >= 0) {
        double fm = margin_at(c, i, j, km, n);
        fill_run(c, slice, i, j, ka, km, fa, fm, n, kb - ka);
    }
    if (km + 1 <= c->nz - 1) {
        double fm1 = margin_at(c, i, j, km + 1, n);
        fill_run(c, slice, i, j, km + 1, kb, fm1, fb, n, kb - ka);
    }
}

typedef struct zs {
    int32_t z;
    int s;
} zs;

static int zs_cmp(const void *a, const void *b)
{
    int32_t x = ((const zs *)a)->z, y = ((const zs *)b)->z;
    return x < y ? -1 : x > y;
}

static void sort_column(int32_t *z, int8_t *s, size_t n)
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
        int32_t zv = z[a];
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

static void column(wctx *c, uint32_t *slice, int i, int j)
{
    size_t col = (size_t)j * c->nx + i, n = c->off[col + 1] - c->off[col];
    int32_t *z = c->z + c->off[col];
    int8_t *s = c->sg + c->off[col];
    sort_column(z, s, n);
    int cnt = 0;
    for (size_t a = 0; a < n; a++)
        cnt += s[a];
    for (size_t r = 0; r <= n; r++) {
        /* run r: centres k with z[r-1] <= k < z[r] have cnt crossings above;
         * for an open mesh the whole run in its bbox, past the brick */
        int lo = c->open ? c->rlo : c->lo[2], hi = c->open ? c->rhi : c->hi[2];
        int ka = r && z[r - 1] > lo ? z[r - 1] : lo;
        int kb = r < n && z[r] - 1 < hi ? z[r] - 1 : hi;
        if (ka <= kb && kb >= 0 && ka <= c->nz - 1) {
            if (!c->open || far_run(c, i, j, ka, kb, cnt)) {
                double f = cnt >= 1 ? 1 : -1;
                fill_run(c, slice, i, j, ka, kb, f, f, cnt, 0);
            } else {
                double fa = margin_at(c, i, j, ka, cnt),
                       fb = ka == kb ? fa : margin_at(c, i, j, kb, cnt);
                if (kb - ka >= 8 && (fa >= 0) == (fb >= 0)) {
                    int km = ka + (kb - ka) / 2;
                    double fm = margin_at(c, i, j, km, cnt);
                    if ((fm >= 0) != (fa >= 0)) {
                        fill_run(c, slice, i, j, ka, km, fa, fm, cnt, INT_MAX);
                        fill_run(c, slice, i, j, km + 1, kb, margin_at(c, i, j, km + 1, cnt), fb,
                                 cnt, INT_MAX);
                        goto next;
                    }
                }
                fill_run(c, slice, i, j, ka, kb, fa, fb, cnt, INT_MAX);
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
    if (j >= c->lo[1] && j <= c->hi[1]) {
        size_t wx = c->out->wx;
        uint32_t *slice = calloc((size_t)c->nz * wx + 1, sizeof *slice);
        if (!slice) {
            if (!atomic_exchange(&c->stop, 1))
                vx_err_set(&c->err, VX_EINTERNAL, "out_of_memory", "no memory for a row");
            return 1;
        }
        for (int i = c->lo[0]; i <= c->hi[0]; i++) {
            if (poll(c, t)) { /* a column of a soup can take 0.1 s */
                free(slice);
                return 1;
            }
            column(c, slice, i, j);
        }
        for (int k = 0; k < c->nz; k++)
            memcpy(c->out->bits + ((size_t)k * c->ny + (size_t)j) * wx, slice + (size_t)k * wx,
                   wx * sizeof *slice);
        free(slice);
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
    uint64_t bytes = vx_bitgrid_bytes(c->out->grid.dims, 1) + (uint64_t)n * 5 +
                     (uint64_t)ncols * 12 + c->bin_off[c->nbands] * 4 +
                     ((uint64_t)c->m->nverts * 3 + (uint64_t)c->ncone * 9) * 8 +
                     (uint64_t)vx_par_cpus() * (uint64_t)c->nz * c->out->wx * 4; /* row slices */
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

/* u snapped as the crossings' rules see it along axis a: across the z
 * rays to 1/VX_GRID_SNAP voxel (the coverage), along them to
 * 1/VX_GRID_XING_SNAP (the crossings). */
static double snapped(double u, int a)
{
    double k = a == 2 ? VX_GRID_XING_SNAP : VX_GRID_SNAP;
    return nearbyint(u * k) / k;
}

/* The centres that can be inside: the grid, and for an open mesh those in
 * the bounding box of the vertices its faces use, in lattice units (each
 * bound is one vertex's coordinate: the number lattice_units gave it)
 * snapped as the crossings are, so a face on a plane of centres keeps
 * its centres whichever way (p - origin) / h rounded. */
static void inside_range(wctx *c)
{
    const int n[3] = {c->nx, c->ny, c->nz};
    for (int a = 0; a < 3; a++) {
        c->lo[a] = 0;
        c->hi[a] = n[a] - 1;
        if (!c->open) continue;
        double umin = snapped((c->m->bbox_min[a] - c->o[a]) / c->h, a),
               umax = snapped((c->m->bbox_max[a] - c->o[a]) / c->h, a);
        double lo = ceil(umin - 0.5) - c->ix[a], hi = floor(umax - 0.5) - c->ix[a];
        if (lo > c->lo[a]) c->lo[a] = lo > n[a] ? n[a] : (int)lo;
        if (hi < c->hi[a]) c->hi[a] = hi < -1 ? -1 : (int)hi;
        if (a == 2) { /* as the crossings are clamped */
            c->rlo = (int)fmax(fmin(lo, VX_LATTICE_XING_MAX), -VX_LATTICE_XING_MAX);
            c->rhi = (int)fmax(fmin(hi, VX_LATTICE_XING_MAX), -VX_LATTICE_XING_MAX);
        }
    }
}

/* Every mesh vertex and cone corner in the lattice's units. */
static int lattice_units(wctx *c, vx_err *err)
{
    const vx_mesh *m = c->m;
    c->lat = malloc((m->nverts * 3 + c->ncone * 9) * sizeof *c->lat + 1);
    if (!c->lat) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for positions");
    for (size_t v = 0; v < m->nverts; v++)
        vx_lattice_unit(&c->d->grid, m->pos + 3 * v, c->lat + 3 * v);
    /* the vertices a face uses (one left over may lie anywhere) */
    for (size_t i = 0; i < 3 * m->ntris; i++)
        if (!vx_lattice_in_range(c->lat + 3 * (size_t)m->tri[i]))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "vertex %u lies more than 2^50 voxels from the grid origin; "
                              "use a larger voxel size",
                              m->tri[i]);
    /* a cone's corners are boundary vertices and their mean: in range too */
    for (size_t v = 0; v < 3 * c->ncone; v++)
        vx_lattice_unit(&c->d->grid, c->cone + 3 * v, c->lat + 3 * (m->nverts + v));
    return 0;
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
    for (int a = 0; a < 3; a++) {
        c->index[a] = d->grid.index[a];
        c->ix[a] = (double)d->grid.index[a];
    }
    c->h = d->grid.h;
    c->out = out;
    int rc = -1;
    if (vx_bitgrid_alloc(out, &d->grid, 0, err) || vx_wcone_build(m, &c->cone, &c->ncone, err))
        goto done;
    c->ntot = m->ntris + c->ncone;
    c->open = c->ncone > 0;
    if (lattice_units(c, err) || vx_wtree_build(&c->tree, c->ncone, c->cone, err) ||
        bin_tris(c, err))
        goto done;
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
    free(c->lat);
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
    if (m->boundary_edges_welded > 0 && fits) return VX_INSIDE_WINDING;
    /* closed, but faces either side of some edge disagree on the way
     * round: the crossing count is no winding number then (streaks from
     * the surface to the grid's edge), while parity needs no orientation */
    return m->boundary_edges_welded == 0 && m->misoriented_edges > 0 ? VX_INSIDE_PARITY
                                                                     : VX_INSIDE_NONZERO;
}
