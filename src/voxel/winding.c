/* inside "winding" (voxel.h): voxel centres where the generalized winding
 * number of the mesh (Jacobson et al. 2013) is at least 1/2, on the CPU.
 *
 * The winding number w of the mesh S at q is split in two. The boundary
 * of S (its directed edges not cancelled by an opposite twin, vertices
 * welded by position) is closed by cones K of triangles, one apex per
 * connected part of the boundary (a hole), so that S + K has no boundary.
 * Then w_S(q) = w_{S+K}(q) - w_K(q), where w_{S+K}(q) is an integer: the
 * signed crossings of S + K along the z ray above q (front +1 where the
 * surface faces +z; the y ray where the holes face z: pick_axis, the
 * engine's y and z are then the grid's z and y), counted exactly per
 * voxel column by lattice.h's rules (cpu.c's, along z): coverage by exact
 * integer edge tests on the positions snapped to 1/256 voxel in the
 * lattice, each crossing placed at its first centre at or beyond it by
 * the shaders' formula, so a centre on a face counts half-open [entry,
 * exit) along every axis and a brick gives the whole grid's voxels. Each
 * task takes a band of rows of columns: its triangles' crossings (once
 * each) sorted by column, then its rows filled, as cpu.c does along x.
 * w_K is smooth between K's crossings. On a run of centres between two
 * crossings, when a bound of w_K (area over squared distance per tree
 * node, the distance to its bounding box; first of |w_K| over blocks of
 * columns, then over the run, of w_K from the side that could flip it:
 * from above where the count n >= 1, and there a triangle the whole run
 * sees from its front adds nothing, from below where n <= 0) stays within
 * the count's margin to 1/2, the count decides alone; else w_K is
 * evaluated with a tree over K (wtree.c, Barill et al. 2018) at both ends
 * of the run (and its middle when it is over 8 voxels), and where they
 * disagree about w >= 1/2 the run is split (fill_run), one evaluation a
 * split, until the change is found. A run that starts after crossings of
 * the mesh alone (no cone triangle crosses its column) takes w_K of the
 * centre before them, the end of the run before (evaluated once for
 * both). The runs of a row's columns are taken a block at a time: their
 * bounds four at a time, then the samples of those left open four at a
 * time (vx_wtree_bound4, vx_wtree_eval4: one walk of the tree for four
 * lanes of AVX2, each lane the bits of one walk alone), then filled in
 * order: the same voxels as run by run. A closed mesh has no cone: then
 * w is the crossing count and nothing is evaluated. Centres outside the mesh's bounding box are
 * outside (|w| < 1/2 outside its convex hull).
 *
 * The approximation: a run whose sampled centres agree is filled as they
 * say, so a dip of w across 1/2 and back between two samples is missed
 * (a column that grazes a hole's rim, where w varies fastest); a run's
 * first centre that takes w_K from one centre back is off by w_K's change
 * over a voxel (large only next to a rim); far nodes of the tree carry an
 * error of about (1/beta)^3 of their field. */
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
#include "voxel/xband.h"

#define BAND 8       /* column rows (y) per task, at most */
#define FAR_BLOCK 16 /* columns of a band's rows bounded together */

typedef struct wtri {
    int ilo, ihi, jlo, jhi; /* column centres its snapped bbox holds (ilo > ihi: none) */
    int8_t sign;            /* +1 facing +z (counter-clockwise in (x, y)) */
} wtri;

/* A thread's band: its crossings (row: the column, (j - band's first
 * row) * nx + i), a row's slice and a column's sorted crossings. */
typedef struct scratch {
    vx_xband x;
    uint32_t *slice; /* a row's voxels, every z row of it (set_bit) */
    int32_t *z;      /* a column's crossings, sorted */
    uint8_t *far;    /* per block of FAR_BLOCK columns: the cone is far */
    uint8_t *cone;   /* per column of the band: a cone triangle crosses it */
    size_t zcap;
} scratch;

typedef struct wctx {
    const vx_mesh *m;
    const vx_voxelize_desc *d;
    double *cone; /* 9 doubles per cone triangle */
    size_t ncone, ntot;
    /* The engine's axes: a = 0, 1, 2 is the grid's axis ax[a]; the rays
     * run along ax[2] (z, or y: pick_axis), x is always the grid's x (the
     * rows' bits). nx, ny, nz, o, ix and index are along the engine's. */
    int ax[3];
    int nx, ny, nz, band, nbands; /* band: rows per task */
    double o[3], h;
    double ix[3];     /* grid.index_offset: centre i of axis a is o + (ix + i + 1/2) h */
    int64_t index[3]; /* the same, as integers */
    /* lattice units (p - o) / h, 3 a corner: the mesh's vertices, then the
     * cone triangles' corners (3 each); and each corner's (x, y) snapped */
    double *lat;
    int64_t *snap;
    wtri *tri;       /* ntot: the mesh's triangles, then the cone's */
    size_t *bin_off; /* nbands + 1 */
    uint32_t *bin;   /* triangle ids per band */
    scratch sc[VX_PAR_MAX];
    vx_xmeter mem;
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

/* Corner q of triangle t: its index into lat and snap. */
static size_t corner(const wctx *c, size_t t, int q)
{
    return t < c->m->ntris ? c->m->tri[3 * t + q] : c->m->nverts + 3 * (t - c->m->ntris) + q;
}

#define SETUP_CHUNK 8192 /* corners, then triangles, per setup task */

/* Corners [i * SETUP_CHUNK, +SETUP_CHUNK) in the lattice's units
 * (lattice_units), and snapped. */
static int setup_corners(int i, int t, void *ud)
{
    (void)t;
    wctx *c = ud;
    size_t nv = c->m->nverts, n = nv + 3 * c->ncone, v0 = (size_t)i * SETUP_CHUNK;
    size_t v1 = v0 + SETUP_CHUNK < n ? v0 + SETUP_CHUNK : n;
    for (size_t v = v0; v < v1; v++) {
        double *u = c->lat + 3 * v, g[3];
        vx_lattice_unit(&c->d->grid, v < nv ? c->m->pos + 3 * v : c->cone + 3 * (v - nv), g);
        for (int a = 0; a < 3; a++)
            u[a] = g[c->ax[a]];
        int in = vx_lattice_in_range(u); /* checked where a face uses it */
        c->snap[2 * v] = in ? vx_lattice_snap(u[0]) : 0;
        c->snap[2 * v + 1] = in ? vx_lattice_snap(u[1]) : 0;
    }
    return 0;
}

/* Triangles [i * SETUP_CHUNK, +SETUP_CHUNK): each one's columns and sign
 * (0 when it covers no centre: edge-on to z, or off the grid). */
static int setup_tris(int i, int t, void *ud)
{
    (void)t;
    wctx *c = ud;
    const int n[2] = {c->nx, c->ny};
    size_t t0 = (size_t)i * SETUP_CHUNK,
           t1 = t0 + SETUP_CHUNK < c->ntot ? t0 + SETUP_CHUNK : c->ntot;
    for (size_t tr = t0; tr < t1; tr++) {
        const int64_t *P[3];
        for (int q = 0; q < 3; q++)
            P[q] = c->snap + 2 * corner(c, tr, q);
        wtri *x = &c->tri[tr];
        vx_i128 det = vx_lattice_det(P[0], P[1], P[2]);
        x->sign = det > 0 ? 1 : det < 0 ? -1 : 0;
        int r[4];
        for (int a = 0; a < 2; a++) {
            int64_t lo = P[0][a], hi = P[0][a];
            for (int q = 1; q < 3; q++) {
                lo = P[q][a] < lo ? P[q][a] : lo;
                hi = P[q][a] > hi ? P[q][a] : hi;
            }
            vx_lattice_centres(lo, hi, c->index[a], n[a], &r[2 * a], &r[2 * a + 1]);
        }
        x->ilo = r[0];
        x->ihi = r[1];
        x->jlo = r[2];
        x->jhi = r[3];
        if (!x->sign || x->jlo > x->jhi) x->ilo = x->ihi + 1;
    }
    return 0;
}

/* Triangle t's rows of columns (vx_xband_bin): 0 when it covers none. */
static int tri_rows(const void *ud, size_t t, int *lo, int *hi)
{
    const wtri *x = &((const wctx *)ud)->tri[t];
    *lo = x->jlo;
    *hi = x->jhi;
    return x->ilo <= x->ihi;
}

/* Triangle t's crossings of the columns of rows [j0, j1): coverage by
 * lattice.h's snapped edge tests, each crossing placed by its formula with
 * z as the ray's axis. */
static int raster_tri(wctx *c, vx_xband *sc, uint8_t *cone, size_t t, int j0, int j1)
{
    const wtri *x = &c->tri[t];
    size_t v[3] = {corner(c, t, 0), corner(c, t, 1), corner(c, t, 2)};
    const int64_t *P[3] = {c->snap + 2 * v[0], c->snap + 2 * v[1], c->snap + 2 * v[2]};
    if (x->sign < 0) { /* counter-clockwise for the edge tests */
        const int64_t *tmp = P[1];
        P[1] = P[2];
        P[2] = tmp;
    }
    int jlo = x->jlo < j0 ? j0 : x->jlo, jhi = x->jhi > j1 - 1 ? j1 - 1 : x->jhi;
    const int64_t S = (int64_t)VX_GRID_SNAP;
    int64_t cx0 = (c->index[0] + x->ilo) * S + S / 2, cy0 = (c->index[1] + jlo) * S + S / 2;
    vx_lattice_edge e[3];
    for (int q = 0; q < 3; q++)
        vx_lattice_edge_set(&e[q], P[q], P[(q + 1) % 3], cx0, cy0);
    /* (z, x, y): the ray's axis first */
    const double *u0 = c->lat + 3 * v[0], *u1 = c->lat + 3 * v[1], *u2 = c->lat + 3 * v[2];
    double a[3] = {u0[2], u0[0], u0[1]}, e1[3] = {u1[2] - u0[2], u1[0] - u0[0], u1[1] - u0[1]},
           e2[3] = {u2[2] - u0[2], u2[0] - u0[0], u2[1] - u0[1]};
    /* rays along y: the engine's axes are a mirror image of the grid's, so
     * a face towards +z there faces away from the rays' +y */
    const int32_t pos = (x->sign > 0) != (c->ax[2] != 2);
    for (int j = jlo; j <= jhi; j++) {
        vx_i128 f0 = e[0].at, f1 = e[1].at, f2 = e[2].at;
        double cy = (c->ix[1] + j) + 0.5;
        uint32_t col0 = (uint32_t)((j - j0) * c->nx);
        for (int i = x->ilo; i <= x->ihi; i++) {
            if (f0 > 0 && f1 > 0 && f2 > 0) {
                int32_t kb = vx_lattice_xing(a, e1, e2, (c->ix[0] + i) + 0.5, cy, c->ix[2]);
                if (vx_xband_push(sc, &c->mem, col0 + (uint32_t)i, 2 * kb + pos)) return -1;
                if (t >= c->m->ntris) cone[col0 + (uint32_t)i] = 1;
            }
            f0 += e[0].d1;
            f1 += e[1].d1;
            f2 += e[2].d1;
        }
        for (int q = 0; q < 3; q++)
            e[q].at += e[q].d2;
    }
    return 0;
}

/* Progress and the stop check from the calling thread (t = 0); every
 * thread stops once it said stop. */
#define POLL_COLUMN 16
#define POLL_WORK 1024 /* every 64 empty columns, or after 1,008 crossings */
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

/* ---- inside per column ------------------------------------------------ */

/* Voxels (i, k0..k1) of the row being filled, in its slice of the grid:
 * the words of every engine z row for this engine y, contiguous (with rays
 * along z a column's voxels are a row of the grid apart: set in place they
 * missed the cache at every bit; along y the slice is one layer of the
 * grid). The slice holds where each column's state changes along k, bit i
 * flipped at k0 and past k1 (a column's runs are disjoint): slice_out
 * makes the voxels of it by an XOR along k, a word of 32 columns at a
 * time (a run set bit by bit was 13% of the bunny's time at 1024^3). */
static void set_run(const wctx *c, uint32_t *slice, int i, int k0, int k1)
{
    const size_t wx = c->out->wx, w = (size_t)(i >> 5);
    const uint32_t bit = 1u << (i & 31);
    slice[(size_t)k0 * wx + w] ^= bit;
    if (k1 + 1 < c->nz) slice[(size_t)(k1 + 1) * wx + w] ^= bit;
}

/* The world position of the engine's centre (i, j, k), in the grid's axes. */
static void centre(const wctx *c, int i, int j, int k, double q[3])
{
    const int e[3] = {i, j, k};
    for (int a = 0; a < 3; a++)
        q[c->ax[a]] = c->o[a] + (c->ix[a] + e[a] + 0.5) * c->h;
}

/* The cones' w at centre k of column (i, j). */
static double cone_w(const wctx *c, int i, int j, int k)
{
    double q[3];
    centre(c, i, j, k, q);
    return vx_wtree_eval(&c->tree, q);
}

/* n - w - 1/2 at centre k of column (i, j), whose crossing count above
 * is n: the centre is inside (w >= 1/2) where it is >= 0. */
static double margin_at(const wctx *c, int i, int j, int k, int n)
{
    return n - cone_w(c, i, j, k) - 0.5;
}

/* 1 when the cone's w stays under n - 1/2 (side +1, for n >= 1), over it
 * (side -1, n <= 0), or |w| under |n - 1/2| (side 0) on the centres of
 * columns i0..i1 of rows j0..j1, ka..kb along z: there w >= 1/2 exactly
 * where n >= 1, with nothing evaluated. */
static int far_box(const wctx *c, int i0, int i1, int j0, int j1, int ka, int kb, int n, int side)
{
    double lo[3], hi[3];
    centre(c, i0, j0, ka, lo);
    centre(c, i1, j1, kb, hi);
    double limit = fabs(n - 0.5);
    return vx_wtree_bound(&c->tree, lo, hi, limit, side) < limit;
}

/* Centres ka..kb of one run between crossings, the margins at its ends
 * known (fa, fb; margin_at), ka's own voxel set by this part when own_a
 * (else by the part before it, which ends there), the run possibly
 * reaching past the brick: only its centres in the brick are set, and
 * only parts that reach into the brick are looked at (which decides
 * nothing in it: each part is decided from its own samples). Where the
 * ends disagree, the run is split at a centre km strictly between them,
 * one evaluation, into ka..km and km..kb (km owned by the first): where
 * the margin's straight line through the ends crosses 0 (w is smooth
 * along a run: the change is found in a few samples, not log2 of the
 * run's length), or at the middle when the last split did not halve the
 * part (prev, the length before it), as regula falsi can stall. */
static void fill_run(wctx *c, uint32_t *slice, int i, int j, int ka, int kb, double fa, double fb,
                     int own_a, int n, int prev)
{
    if (kb < 0 || ka + !own_a > c->nz - 1) return;
    int da = fa >= 0, db = fb >= 0;
    if (da == db || kb - ka <= 1) {
        if (da == db) {
            int k0 = own_a ? ka : ka + 1;
            k0 = k0 < 0 ? 0 : k0;
            int k1 = kb > c->nz - 1 ? c->nz - 1 : kb;
            if (da && k0 <= k1) set_run(c, slice, i, k0, k1);
        } else {
            if (da && own_a && ka >= 0) set_run(c, slice, i, ka, ka);
            if (db && kb < c->nz) set_run(c, slice, i, kb, kb);
        }
        return;
    }
    int km = ka + (kb - ka) / 2;
    if (2 * (kb - ka) <= prev) {
        double t = fa / (fa - fb) * (kb - ka); /* in [0, kb - ka]: the ends' signs differ */
        if (t >= 0 && t <= kb - ka) {          /* (not a NaN) */
            km = ka + (int)(t + 0.5);
            km = km < ka + 1 ? ka + 1 : km > kb - 1 ? kb - 1 : km;
        }
    }
    double fm = margin_at(c, i, j, km, n);
    fill_run(c, slice, i, j, ka, km, fa, fm, own_a, n, kb - ka);
    fill_run(c, slice, i, j, km, kb, fm, fb, 0, n, kb - ka);
}

/* Sorts z[0..n) (2 kb + front: by kb, then back before front). */
static int i32_cmp(const void *a, const void *b)
{
    int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
    return x < y ? -1 : x > y;
}

static void sort_column(int32_t *z, size_t n)
{
    if (n > 64) {
        qsort(z, n, sizeof *z, i32_cmp);
        return;
    }
    for (size_t a = 1; a < n; a++) {
        int32_t v = z[a];
        size_t b = a;
        for (; b > 0 && z[b - 1] > v; b--)
            z[b] = z[b - 1];
        z[b] = v;
    }
}

/* Runs of a row's columns decided together: their bounds taken four at
 * a time (vx_wtree_bound4), then the w of the centres of those the bounds
 * leave open (vx_wtree_eval4), then the runs filled in order. */
#define RUN_BLOCK 64

typedef struct wrun {
    int i, ka, kb, cnt;
    int at;    /* the centre whose w its start takes: ka, or the one before */
    int first; /* the first run of its column in the row */
    int open;  /* its own bound is to be taken (an open mesh, its block of
                * columns not far), then: the bound did not decide it */
    /* where the w of its start, end and middle centres are in the block's
     * samples: -1 none (the middle of a run under 8), -3 the start is the
     * block before's last sample */
    int ia, ib, im;
} wrun;

typedef struct wblock {
    wrun run[RUN_BLOCK];
    double q[3 * RUN_BLOCK][3], w[3 * RUN_BLOCK];
    int nr, nq;
    int w_at;     /* the column's last centre whose w is sampled (INT_MIN: none) */
    int last;     /* its sample, or -3 */
    double carry; /* its w once the block is flushed */
    int t;        /* the thread's index, for poll */
} wblock;

static int sample(const wctx *c, wblock *b, int i, int j, int k)
{
    centre(c, i, j, k, b->q[b->nq]);
    return b->nq++;
}

/* The open runs' bounds (far_box's, four at a time): a run whose bound
 * stays under its limit is decided by its count. */
static void bound_runs(const wctx *c, int j, wblock *b)
{
    int idx[4], n = 0;
    double lo[4][3], hi[4][3], limit[4], out[4];
    int side[4];
    for (int r = 0; r <= b->nr; r++) {
        if (r < b->nr && b->run[r].open) {
            const wrun *u = &b->run[r];
            centre(c, u->i, j, u->ka, lo[n]);
            centre(c, u->i, j, u->kb, hi[n]);
            limit[n] = fabs(u->cnt - 0.5);
            side[n] = u->cnt >= 1 ? 1 : -1;
            idx[n++] = r;
        }
        if (n == 4 || (r == b->nr && n)) {
            vx_wtree_bound4(&c->tree, (const double(*)[3])lo, (const double(*)[3])hi, limit, side,
                            n, out);
            for (int l = 0; l < n; l++)
                if (out[l] < limit[l]) b->run[idx[l]].open = 0;
            n = 0;
        }
    }
}

/* Decides the block's runs into slice, in order: the bounds, then the
 * samples of the runs left open (a run's start shares the sample of its
 * column's centre before it where that is the last one sampled), their w,
 * then each run filled: one whose ends agree is probed at its middle when
 * it has one (8 centres or more), and split there where that disagrees. */
static void flush(wctx *c, uint32_t *slice, int j, wblock *b)
{
    /* The stop check here too: a block's evaluations are most of a
     * column's cost where each is slow (a soup of large triangles: 0.9 s
     * between the column loop's checks, 6 s past a 2 s job limit on a
     * loaded machine). A stopped block is dropped: the job ends. */
    if (poll(c, b->t)) {
        b->nr = b->nq = 0;
        return;
    }
    bound_runs(c, j, b);
    for (int r = 0; r < b->nr; r++) {
        wrun *u = &b->run[r];
        if (u->first) b->w_at = INT_MIN;
        if (!u->open) continue;
        const int i = u->i, ka = u->ka, kb = u->kb;
        u->ia = b->w_at == u->at ? b->last : sample(c, b, i, j, u->at);
        u->ib = ka < kb ? sample(c, b, i, j, kb) : u->ia;
        u->im = kb - ka >= 8 ? sample(c, b, i, j, ka + (kb - ka) / 2) : -1;
        b->w_at = ka < kb ? kb : u->at;
        b->last = u->ib;
    }
    for (int a = 0; a < b->nq; a += 4)
        vx_wtree_eval4(&c->tree, (const double(*)[3])b->q[a], b->nq - a < 4 ? b->nq - a : 4,
                       b->w + a);
    for (int r = 0; r < b->nr; r++) {
        if ((r & 31) == 31 && poll(c, b->t)) { /* a run's splits evaluate one by one */
            b->nr = b->nq = 0;
            return;
        }
        const wrun *u = &b->run[r];
        const int i = u->i, ka = u->ka, kb = u->kb, cnt = u->cnt;
        if (!u->open) {
            double f = cnt >= 1 ? 1 : -1;
            fill_run(c, slice, i, j, ka, kb, f, f, 1, cnt, 0);
            continue;
        }
        double fa = cnt - (u->ia == -3 ? b->carry : b->w[u->ia]) - 0.5, fb = fa;
        if (ka < kb) fb = cnt - b->w[u->ib] - 0.5;
        if (u->im >= 0 && (fa >= 0) == (fb >= 0)) {
            const int km = ka + (kb - ka) / 2;
            const double fm = cnt - b->w[u->im] - 0.5;
            if ((fm >= 0) != (fa >= 0)) {
                fill_run(c, slice, i, j, ka, km, fa, fm, 1, cnt, INT_MAX);
                fill_run(c, slice, i, j, km, kb, fm, fb, 0, cnt, INT_MAX);
                continue;
            }
        }
        fill_run(c, slice, i, j, ka, kb, fa, fb, 1, cnt, INT_MAX);
    }
    if (b->last >= 0) {
        b->carry = b->w[b->last];
        b->last = -3;
    }
    b->nr = b->nq = 0;
}

/* Column (i, j), its n crossings z (2 kb + front, sorted), into the block
 * (flushed into slice when full; the row's caller flushes the rest);
 * far_col: the cone's |w| is under 1/2 on all of its block of columns
 * (far_box with n = 1: |n - 1/2| >= 1/2 for every n, so every run is
 * decided by its count). A column outside such a block is not bounded as
 * a whole before its runs are: near a hole that seldom holds (12% of
 * those columns on the bunny at 1024^3), and its runs' own bounds hold in
 * 70%. */
static void column(wctx *c, uint32_t *slice, wblock *b, int i, int j, const int32_t *z, size_t n,
                   int far_col, int cone_col)
{
    int cnt = 0, first = 1;
    for (size_t a = 0; a < n; a++)
        cnt += z[a] & 1 ? 1 : -1;
    for (size_t r = 0; r <= n; r++) {
        /* run r: centres k with z[r-1] <= k < z[r] have cnt crossings above;
         * for an open mesh the whole run in its bbox, past the brick */
        int lo = c->open ? c->rlo : c->lo[2], hi = c->open ? c->rhi : c->hi[2];
        int zp = r ? z[r - 1] >> 1 : 0, zr = r < n ? z[r] >> 1 : 0;
        int ka = r && zp > lo ? zp : lo;
        int kb = r < n && zr - 1 < hi ? zr - 1 : hi;
        if (ka <= kb && kb >= 0 && ka <= c->nz - 1) {
            if (b->nr == RUN_BLOCK) flush(c, slice, j, b);
            /* the start across crossings of the mesh alone: w one centre back */
            b->run[b->nr++] = (wrun){.i = i,
                                     .ka = ka,
                                     .kb = kb,
                                     .cnt = cnt,
                                     .at = r && ka == zp && !cone_col ? ka - 1 : ka,
                                     .first = first,
                                     .open = c->open && !far_col,
                                     .ia = -1,
                                     .ib = -1,
                                     .im = -1};
            first = 0;
        }
        if (r < n) cnt -= z[r] & 1 ? 1 : -1;
    }
}

/* The voxels of engine row j from its slice of state changes (set_run),
 * into the grid: row j of every layer, or with rays along y layer j. */
static void slice_out(const wctx *c, uint32_t *slice, int j)
{
    const size_t wx = c->out->wx;
    for (int k = 0; k < c->nz; k++) {
        uint32_t *s = slice + (size_t)k * wx;
        const size_t row =
            c->ax[2] == 2 ? (size_t)k * c->ny + (size_t)j : (size_t)j * c->nz + (size_t)k;
        uint32_t *out = c->out->bits + row * wx;
        if (k) {
            const uint32_t *above = s - wx;
            for (size_t w = 0; w < wx; w++)
                s[w] ^= above[w];
        }
        memcpy(out, s, wx * sizeof *s);
    }
}

/* The rows of band b: its triangles' crossings into the thread's scratch,
 * sorted by column, then each row's columns filled into the slice and
 * copied into the grid. */
static int band_task(int b, int t, void *ud)
{
    wctx *c = ud;
    if (poll(c, t)) return 1;
    scratch *sc = &c->sc[t];
    int j0 = b * c->band, j1 = j0 + c->band < c->ny ? j0 + c->band : c->ny;
    size_t cols = (size_t)(j1 - j0) * c->nx, wx = c->out->wx;
    sc->x.n = 0;
    if (!sc->slice) sc->slice = malloc((size_t)c->nz * wx * sizeof *sc->slice + 1);
    if (!sc->far) sc->far = malloc((size_t)c->nx / FAR_BLOCK + 1);
    if (!sc->cone) sc->cone = malloc((size_t)c->band * c->nx + 1);
    if (!sc->slice || !sc->far || !sc->cone) return vx_xmeter_oom(&c->mem);
    memset(sc->cone, 0, cols);
    /* a band of a triangle soup can hold 10^5 large triangles: the stop
     * check comes every 64 of them, not only between bands */
    for (size_t k = c->bin_off[b]; k < c->bin_off[b + 1]; k++) {
        if ((k & 63) == 63 && poll(c, t)) return 1;
        if (raster_tri(c, &sc->x, sc->cone, c->bin[k], j0, j1)) return 1;
    }
    if (vx_xband_sort(&sc->x, &c->mem, cols)) return 1;
    /* the cone's bound over blocks of FAR_BLOCK columns of the band's rows
     * first: most are far from every hole */
    int ja = j0 > c->lo[1] ? j0 : c->lo[1], jb = j1 - 1 < c->hi[1] ? j1 - 1 : c->hi[1];
    wblock blk = {.nr = 0, .nq = 0, .w_at = INT_MIN, .last = -1, .t = t};
    if (c->open)
        for (int i = c->lo[0]; i <= c->hi[0] && ja <= jb; i += FAR_BLOCK) {
            int ib = i + FAR_BLOCK - 1 < c->hi[0] ? i + FAR_BLOCK - 1 : c->hi[0];
            sc->far[(i - c->lo[0]) / FAR_BLOCK] =
                (uint8_t)far_box(c, i, ib, ja, jb, c->rlo, c->rhi, 1, 0);
        }
    /* the stop check and progress every POLL_WORK of work (a column, and
     * its crossings): a column of a soup can take 0.1 s, but a clock read
     * a column was a tenth of a 1024^3 job on a virtual machine's clock */
    size_t work = POLL_WORK;
    for (int j = ja; j <= jb; j++) {
        memset(sc->slice, 0, (size_t)c->nz * wx * sizeof *sc->slice);
        for (int i = c->lo[0]; i <= c->hi[0]; i++) {
            size_t col = (size_t)(j - j0) * c->nx + i, end = sc->x.end[col];
            size_t begin = col ? sc->x.end[col - 1] : 0, n = end - begin;
            if ((work += POLL_COLUMN + n) >= POLL_WORK) {
                work = 0;
                if (poll(c, t)) return 1;
            }
            if (n > sc->zcap) {
                int32_t *z = realloc(sc->z, n * sizeof *z);
                if (!z) return vx_xmeter_oom(&c->mem);
                sc->z = z;
                sc->zcap = n;
            }
            for (size_t k = 0; k < n; k++)
                sc->z[k] = sc->x.sorted[begin + k].at2;
            sort_column(sc->z, n);
            int far = c->open && sc->far[(i - c->lo[0]) / FAR_BLOCK];
            column(c, sc->slice, &blk, i, j, sc->z, n, far, sc->cone[col]);
        }
        flush(c, sc->slice, j, &blk);
        slice_out(c, sc->slice, j);
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
        double umin = snapped((c->m->bbox_min[c->ax[a]] - c->o[a]) / c->h, a),
               umax = snapped((c->m->bbox_max[c->ax[a]] - c->o[a]) / c->h, a);
        double lo = ceil(umin - 0.5) - c->ix[a], hi = floor(umax - 0.5) - c->ix[a];
        if (lo > c->lo[a]) c->lo[a] = lo > n[a] ? n[a] : (int)lo;
        if (hi < c->hi[a]) c->hi[a] = hi < -1 ? -1 : (int)hi;
        if (a == 2) { /* as the crossings are clamped */
            c->rlo = (int)fmax(fmin(lo, VX_LATTICE_XING_MAX), -VX_LATTICE_XING_MAX);
            c->rhi = (int)fmax(fmin(hi, VX_LATTICE_XING_MAX), -VX_LATTICE_XING_MAX);
        }
    }
}

/* Every mesh vertex and cone corner in the lattice's units, and snapped
 * (setup_corners); every vertex a face uses checked to be in range (one
 * left over may lie anywhere; a cone's corners are boundary vertices and
 * their means: in range too). */
static int lattice_units(wctx *c, vx_err *err)
{
    const vx_mesh *m = c->m;
    size_t n = m->nverts + 3 * c->ncone;
    c->lat = malloc(3 * n * sizeof *c->lat + 1);
    c->snap = malloc(2 * n * sizeof *c->snap + 1);
    if (!c->lat || !c->snap)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for positions");
    vx_par_for((int)((n + SETUP_CHUNK - 1) / SETUP_CHUNK), vx_par_cpus(), setup_corners, c);
    for (size_t i = 0; i < 3 * m->ntris; i++)
        if (!vx_lattice_in_range(c->lat + 3 * (size_t)m->tri[i]))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "vertex %u lies more than 2^50 voxels from the grid origin; "
                              "use a larger voxel size",
                              m->tri[i]);
    return 0;
}

/* The rays' axis: z, or y where the cones that close the holes face z more
 * than y (summed |area| of their triangles along each). Runs near a hole
 * need its winding number: rays through a cap cross it near the rim over
 * its whole area, rays along its plane meet it in a few rows (the bunny's
 * base holes face y; suzanne's eyes face z and take a third less time with
 * rays along y). From the mesh alone, so every brick takes the same axis;
 * a closed mesh keeps z. */
static void pick_axis(wctx *c)
{
    double f[3] = {0, 0, 0};
    for (size_t t = 0; t < c->ncone; t++) {
        const double *v = c->cone + 9 * t;
        double e1[3], e2[3];
        for (int a = 0; a < 3; a++) {
            e1[a] = v[3 + a] - v[a];
            e2[a] = v[6 + a] - v[a];
        }
        f[1] += fabs(e1[2] * e2[0] - e1[0] * e2[2]);
        f[2] += fabs(e1[0] * e2[1] - e1[1] * e2[0]);
    }
    int y = f[2] > f[1];
    c->ax[0] = 0;
    c->ax[1] = y ? 2 : 1;
    c->ax[2] = y ? 1 : 2;
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
    c->h = d->grid.h;
    c->out = out;
    c->mem = (vx_xmeter){
        .limit = d->max_memory, .who = "the winding rule", .stop = &c->stop, .err = &c->err};
    int rc = -1;
    if (vx_bitgrid_alloc(out, &d->grid, 0, err) || vx_wcone_build(m, &c->cone, &c->ncone, err))
        goto done;
    c->ntot = m->ntris + c->ncone;
    c->open = c->ncone > 0;
    pick_axis(c);
    for (int a = 0; a < 3; a++) {
        c->o[a] = d->grid.origin[c->ax[a]];
        c->index[a] = d->grid.index[c->ax[a]];
        c->ix[a] = (double)c->index[a];
    }
    c->nx = d->grid.dims[0];
    c->ny = d->grid.dims[c->ax[1]];
    c->nz = d->grid.dims[c->ax[2]];
    /* bands of BAND rows, fewer where that makes under 16 a thread: the
     * columns near a hole cost most, and they lie in a few rows */
    c->band = c->ny / (16 * vx_par_cpus());
    c->band = c->band < 1 ? 1 : c->band > BAND ? BAND : c->band;
    c->nbands = (c->ny + c->band - 1) / c->band;
    /* the grid, the corners and triangles, and every thread's slice,
     * column counters and cone flags; bins and crossings are charged as
     * they are made */
    size_t ncorner = m->nverts + 3 * c->ncone;
    if (vx_xmeter_charge(&c->mem,
                         vx_bitgrid_bytes(d->grid.dims, 1) + (uint64_t)ncorner * 40u +
                             (uint64_t)c->ntot * sizeof(wtri) +
                             (uint64_t)vx_par_cpus() *
                                 (((uint64_t)c->nz * out->wx + (uint64_t)c->band * c->nx + 1) * 4u +
                                  (uint64_t)c->band * c->nx))) {
        if (err) *err = c->err;
        goto done;
    }
    c->tri = malloc(c->ntot * sizeof *c->tri + 1);
    if (!c->tri) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the triangles");
        goto done;
    }
    if (lattice_units(c, err) || vx_wtree_build(&c->tree, c->ncone, c->cone, err)) goto done;
    vx_par_for((int)((c->ntot + SETUP_CHUNK - 1) / SETUP_CHUNK), vx_par_cpus(), setup_tris, c);
    if (vx_xband_bin(c->ntot, tri_rows, c, c->band, c->nbands, &c->mem, &c->bin_off, &c->bin)) {
        if (err) *err = c->err;
        goto done;
    }
    inside_range(c);
    st->upload_ms = (vx_mono() - t0) * 1e3;
    if (stage(c, c->nbands, band_task, 0.0, 1.0, err)) goto done;
    st->voxels_inside = vx_bitgrid_count(out);
    st->chunks = 1;
    rc = 0;
done:
    st->gpu_fill_ms = 0;
    st->readback_ms = 0;
    if (rc) vx_bitgrid_free(out);
    vx_wtree_free(&c->tree);
    for (int t = 0; t < VX_PAR_MAX; t++) {
        vx_xband_free(&c->sc[t].x);
        free(c->sc[t].slice);
        free(c->sc[t].z);
        free(c->sc[t].far);
        free(c->sc[t].cone);
    }
    free(c->cone);
    free(c->lat);
    free(c->snap);
    free(c->tri);
    free(c->bin_off);
    free(c->bin);
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
