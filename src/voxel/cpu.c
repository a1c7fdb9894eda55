/* Crossing counts on the CPU threads (voxel.h, method `cpu`): scan's
 * algorithm without a GPU.
 *
 * Where the GL renderer is itself a CPU rasterizer (llvmpipe), scan's draw
 * and compute dispatches run on the same cores behind a driver: most of a
 * 1024^3 job is the driver's (spot: ~190 ms draw, ~350 ms prefix sums).
 * Here the same crossings are found directly, rays along x (the packed
 * axis, so a run of inside voxels is a few whole words):
 *   1. setup: every vertex in the lattice's units (p - origin) / h, and
 *      snapped to 1/VX_GRID_SNAP voxel as exact integers (y, z); triangles
 *      binned by bands of z rows;
 *   2. per band (a task for any thread): each triangle covers the column
 *      centres (j, k) its snapped (y, z) projection contains, decided by
 *      integer edge functions with a tie rule that perturbs the centre by
 *      (eps, eps^2): exact, and a centre on an edge or vertex shared by
 *      triangles of a closed mesh is covered exactly once. Each covered
 *      centre is a crossing, placed by voxel_xing.glsl's formula in double
 *      from the lattice's unsnapped units (then snapped to 2^-20 voxel
 *      along x), signed +1 where the triangle
 *      faces +x (those rules are lattice.h's, shared with winding.c);
 *   3. per row: the crossings sorted along x, counted from each centre
 *      towards +x (the [entry, exit) rule of scan, peel and the CPU
 *      reference), and runs of inside voxels written as whole words.
 * Everything a column sees is computed from lattice numbers (the column's
 * lattice index, never the brick's), so every brick of a lattice gives
 * the same voxels, bit for bit. On a GPU with the same coverage tie rule
 * the voxels are scan's too.
 *
 * nonzero and parity, fill solid, supersample 1 (vx_voxelize checks). */
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "util/clock.h"
#include "util/par.h"
#include "voxel/lattice.h"
#include "voxel/voxel.h"
#include "voxel/xband.h"

#define CPU_BAND 4 /* z rows per task when max_slab_rows does not say */

typedef struct xtri {
    int jlo, jhi, klo, khi; /* column centres of the grid its snapped bbox holds */
    int8_t sign;            /* +1 facing +x (counter-clockwise in (y, z)) */
} xtri;

typedef struct cctx {
    const vx_mesh *m;
    const vx_voxelize_desc *d;
    vx_bitgrid *out;
    int nx, ny, nz, band, nbands, parity;
    double ix[3];   /* the brick's lattice index */
    int64_t iy, iz; /* the same, as integers */
    double *u;      /* 3 doubles a vertex: (p - origin) / h */
    int64_t *s;     /* 2 a vertex: y, z snapped */
    xtri *tri;
    size_t *bin_off;
    uint32_t *bin;
    vx_xband sc[VX_PAR_MAX];
    vx_xmeter mem;
    _Atomic uint64_t inside; /* voxels set */
    atomic_int stop, done;
    vx_err err;
} cctx;

static int setup(cctx *c, vx_err *err)
{
    const vx_mesh *m = c->m;
    const vx_grid *g = &c->d->grid;
    for (size_t v = 0; v < m->nverts; v++) {
        double *u = c->u + 3 * v;
        int in = vx_lattice_unit(g, m->pos + 3 * v, u) == 0; /* checked where a face uses it */
        c->s[2 * v] = in ? vx_lattice_snap(u[1]) : 0;
        c->s[2 * v + 1] = in ? vx_lattice_snap(u[2]) : 0;
    }
    for (size_t t = 0; t < m->ntris; t++) {
        const uint32_t *q = m->tri + 3 * t;
        for (int k = 0; k < 3; k++)
            if (!vx_lattice_in_range(c->u + 3 * (size_t)q[k]))
                return vx_err_set(err, VX_EUNPROC, "invalid_params",
                                  "vertex %u lies more than 2^50 voxels from the grid origin; "
                                  "use a larger voxel size",
                                  q[k]);
        const int64_t *A = c->s + 2 * q[0], *B = c->s + 2 * q[1], *C = c->s + 2 * q[2];
        vx_i128 det = vx_lattice_det(A, B, C);
        xtri *x = &c->tri[t];
        x->sign = det > 0 ? 1 : det < 0 ? -1 : 0;
        int64_t y0 = A[0], y1 = A[0], z0 = A[1], z1 = A[1];
        for (int k = 1; k < 3; k++) {
            const int64_t *P = c->s + 2 * q[k];
            y0 = P[0] < y0 ? P[0] : y0;
            y1 = P[0] > y1 ? P[0] : y1;
            z0 = P[1] < z0 ? P[1] : z0;
            z1 = P[1] > z1 ? P[1] : z1;
        }
        vx_lattice_centres(y0, y1, c->iy, c->ny, &x->jlo, &x->jhi);
        vx_lattice_centres(z0, z1, c->iz, c->nz, &x->klo, &x->khi);
        /* a triangle wholly before the first centre along x counts for no
         * voxel (every crossing of it has ib <= 0, XING_REACH included) */
        double xmax = fmax(c->u[3 * q[0]], fmax(c->u[3 * q[1]], c->u[3 * q[2]]));
        if (x->sign == 0 || xmax + 1.0 < c->ix[0]) x->jlo = x->jhi + 1;
    }
    return 0;
}

/* Triangle t's z rows (vx_xband_bin): 0 when it covers no column. */
static int tri_rows(const void *ud, size_t t, int *lo, int *hi)
{
    const xtri *x = &((const cctx *)ud)->tri[t];
    *lo = x->klo;
    *hi = x->khi;
    return x->jlo <= x->jhi && x->klo <= x->khi;
}

/* Triangle t's crossings of the columns in rows k0..k1-1. */
static int raster_tri(cctx *c, vx_xband *sc, size_t t, int k0, int k1)
{
    const xtri *x = &c->tri[t];
    const uint32_t *q = c->m->tri + 3 * t;
    const int64_t *P[3] = {c->s + 2 * q[0], c->s + 2 * q[1], c->s + 2 * q[2]};
    if (x->sign < 0) { /* counter-clockwise for the edge tests */
        const int64_t *tmp = P[1];
        P[1] = P[2];
        P[2] = tmp;
    }
    int ka = x->klo > k0 ? x->klo : k0, kb = x->khi < k1 - 1 ? x->khi : k1 - 1;
    const int64_t S = (int64_t)VX_GRID_SNAP;
    int64_t cy0 = (c->iy + x->jlo) * S + S / 2, cz0 = (c->iz + ka) * S + S / 2;
    vx_lattice_edge e[3];
    for (int i = 0; i < 3; i++)
        vx_lattice_edge_set(&e[i], P[i], P[(i + 1) % 3], cy0, cz0);
    const double *a = c->u + 3 * q[0], *b = c->u + 3 * q[1], *d = c->u + 3 * q[2];
    double e1[3], e2[3];
    for (int i = 0; i < 3; i++) {
        e1[i] = b[i] - a[i];
        e2[i] = d[i] - a[i];
    }
    const int32_t pos = x->sign > 0;
    for (int k = ka; k <= kb; k++) {
        vx_i128 f0 = e[0].at, f1 = e[1].at, f2 = e[2].at;
        double cz = (c->ix[2] + k) + 0.5;
        uint32_t row0 = (uint32_t)((k - k0) * c->ny);
        for (int j = x->jlo; j <= x->jhi; j++) {
            if (f0 > 0 && f1 > 0 && f2 > 0) {
                int32_t ib = vx_lattice_xing(a, e1, e2, (c->ix[1] + j) + 0.5, cz, c->ix[0]);
                if (ib > 0 && vx_xband_push(sc, &c->mem, row0 + (uint32_t)j, 2 * ib + pos))
                    return -1;
            }
            f0 += e[0].d1;
            f1 += e[1].d1;
            f2 += e[2].d1;
        }
        for (int i = 0; i < 3; i++)
            e[i].at += e[i].d2;
    }
    return 0;
}

/* ---- rows --------------------------------------------------------------- */

static void set_run(uint32_t *w, int lo, int hi) /* bits lo..hi-1 */
{
    if (lo >= hi) return;
    int a = lo >> 5, b = (hi - 1) >> 5;
    uint32_t ma = ~0u << (lo & 31), mb = ~0u >> (31 - ((hi - 1) & 31));
    if (a == b) {
        w[a] |= ma & mb;
        return;
    }
    w[a] |= ma;
    for (int i = a + 1; i < b; i++)
        w[i] = ~0u;
    w[b] |= mb;
}

static int ent_cmp(const void *p, const void *q)
{
    int32_t a = ((const vx_xent *)p)->at2, b = ((const vx_xent *)q)->at2;
    return a < b ? -1 : a > b;
}

/* One row's crossings (n of them) into its words: voxel i is inside when
 * the crossings with ib > i sum to nonzero (odd for parity). Returns the
 * voxels set (the runs are disjoint). */
static uint64_t fill_row(const cctx *c, vx_xent *e, size_t n, uint32_t *w)
{
    if (n > 24) {
        qsort(e, n, sizeof *e, ent_cmp);
    } else {
        for (size_t a = 1; a < n; a++) {
            vx_xent v = e[a];
            size_t b = a;
            for (; b > 0 && e[b - 1].at2 > v.at2; b--)
                e[b] = e[b - 1];
            e[b] = v;
        }
    }
    int cur = 0;
    for (size_t a = 0; a < n; a++)
        cur += (e[a].at2 & 1) ? 1 : -1;
    int prev = 0;
    uint64_t set = 0;
    for (size_t a = 0; a < n && prev < c->nx; a++) {
        int ib = e[a].at2 >> 1; /* ib >= 1 (push dropped the rest) */
        if (ib > prev) {
            int end = ib < c->nx ? ib : c->nx;
            if (c->parity ? (cur & 1) : cur != 0) {
                set_run(w, prev, end);
                set += (uint64_t)(end - prev);
            }
            prev = ib;
        }
        cur -= (e[a].at2 & 1) ? 1 : -1;
    }
    return set;
}

/* The progress hook, from the calling thread (t = 0) only; 1 once any
 * thread said stop. */
static int poll(cctx *c, int t, double f)
{
    if (atomic_load(&c->stop)) return 1;
    if (t != 0 || !c->d->progress) return 0;
    vx_err e = {0};
    if (c->d->progress(c->d->ud, f, &e)) {
        if (e.kind == VX_EOK)
            vx_err_set(&e, VX_ECANCELED, "canceled", "voxelization stopped by its caller");
        if (!atomic_exchange(&c->stop, 1)) c->err = e; /* the first error wins */
        return 1;
    }
    return 0;
}

static int band_task(int b, int t, void *ud)
{
    cctx *c = ud;
    if (poll(c, t, (double)atomic_load(&c->done) / c->nbands)) return 1;
    vx_xband *sc = &c->sc[t];
    int k0 = b * c->band, k1 = k0 + c->band < c->nz ? k0 + c->band : c->nz;
    size_t rows = (size_t)(k1 - k0) * c->ny;
    sc->n = 0;
    for (size_t i = c->bin_off[b]; i < c->bin_off[b + 1]; i++)
        if (raster_tri(c, sc, c->bin[i], k0, k1)) return 1;
    if (vx_xband_sort(sc, &c->mem, rows)) return 1;
    uint32_t *words = c->out->bits + (size_t)k0 * c->ny * c->out->wx;
    size_t begin = 0;
    uint64_t set = 0;
    for (size_t r = 0; r < rows; r++) {
        size_t end = sc->end[r];
        if (end > begin)
            set += fill_row(c, sc->sorted + begin, end - begin, words + r * c->out->wx);
        begin = end;
    }
    atomic_fetch_add(&c->inside, set);
    atomic_fetch_add(&c->done, 1);
    return 0;
}

int vx_voxelize_cpu(const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                    vx_voxelize_stats *st, vx_err *err)
{
    vx_voxelize_stats dummy;
    if (!st) st = &dummy;
    memset(st, 0, sizeof *st);
    st->method = "cpu";
    memset(out, 0, sizeof *out);
    const vx_grid *g = &d->grid;
    if (vx_mesh_check_indices(m, err)) return -1;
    double t0 = vx_mono();
    cctx *c = calloc(1, sizeof *c);
    if (!c) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the job");
    c->m = m;
    c->d = d;
    c->out = out;
    c->nx = g->dims[0];
    c->ny = g->dims[1];
    c->nz = g->dims[2];
    c->parity = d->inside == VX_INSIDE_PARITY;
    c->band = d->max_slab_rows > 0 ? d->max_slab_rows : CPU_BAND;
    if (c->band > c->nz) c->band = c->nz;
    /* a band's rows are numbered in 32 bits */
    if ((uint64_t)c->band * (uint64_t)c->ny > UINT32_MAX / 2) c->band = 1;
    c->nbands = (c->nz + c->band - 1) / c->band;
    for (int a = 0; a < 3; a++)
        c->ix[a] = (double)g->index[a];
    c->iy = g->index[1];
    c->iz = g->index[2];
    int rc = -1;
    /* the grid, the mesh's setup and every thread's row counters; bins
     * and crossings are charged as they are made */
    c->mem = (vx_xmeter){
        .limit = d->max_memory, .who = "the cpu method", .stop = &c->stop, .err = &c->err};
    uint64_t fixed = vx_bitgrid_bytes(g->dims, 1) + (uint64_t)m->nverts * 40u +
                     (uint64_t)m->ntris * sizeof(xtri) +
                     (uint64_t)vx_par_cpus() * ((uint64_t)c->band * c->ny + 1) * 4u;
    if (vx_xmeter_charge(&c->mem, fixed)) {
        if (err) *err = c->err;
        goto done;
    }
    if (poll(c, 0, 0.0)) goto stopped;
    c->u = malloc(m->nverts * 3 * sizeof *c->u + 1);
    c->s = malloc(m->nverts * 2 * sizeof *c->s + 1);
    c->tri = malloc(m->ntris * sizeof *c->tri + 1);
    if (!c->u || !c->s || !c->tri) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the mesh");
        goto done;
    }
    if (setup(c, err)) goto done;
    if (vx_xband_bin(m->ntris, tri_rows, c, c->band, c->nbands, &c->mem, &c->bin_off, &c->bin)) {
        if (err) *err = c->err;
        goto done;
    }
    if (vx_bitgrid_alloc(out, g, 0, err)) goto done;
    st->upload_ms = (vx_mono() - t0) * 1e3;
    if (poll(c, 0, 0.0)) goto stopped;
    vx_par_for(c->nbands, vx_par_cpus(), band_task, c);
    if (atomic_load(&c->stop) || poll(c, 0, 1.0)) goto stopped;
    st->voxels_inside = atomic_load(&c->inside);
    st->chunks = c->nbands;
    rc = 0;
    goto done;
stopped:
    if (err) *err = c->err;
done:
    if (rc) vx_bitgrid_free(out);
    for (int t = 0; t < VX_PAR_MAX; t++) {
        vx_xband_free(&c->sc[t]);
    }
    free(c->u);
    free(c->s);
    free(c->tri);
    free(c->bin_off);
    free(c->bin);
    free(c);
    return rc;
}
