/* STAND-IN for the GPU voxelizers while they are written on the `peel` and
 * `slice` branches: a plain CPU ray caster along +x implementing voxel.h's
 * contract closely enough for the job kind, its writers and its API tests
 * to run. src/CMakeLists.txt drops this file as soon as the real dispatcher
 * (src/voxel/voxelize.c) exists; it is deleted when those branches merge.
 *
 * Differences from the contract, on purpose (it is a stand-in): `robust`
 * is parity along x only; no GPU timers (stage times are 0). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "voxel/voxel.h"

typedef struct xing {
    double x;
    int s; /* +1 entering (normal.x < 0), -1 leaving */
} xing;

static int cmp_xing(const void *a, const void *b)
{
    double d = ((const xing *)a)->x - ((const xing *)b)->x;
    return (d > 0) - (d < 0);
}

/* Edge function with a consistent tie rule, so a ray through an edge
 * shared by two triangles counts for exactly one of them. */
static int edge_in(double ay, double az, double by, double bz, double py, double pz, double sgn)
{
    double e = ((by - ay) * (pz - az) - (bz - az) * (py - ay)) * sgn;
    if (e != 0) return e > 0;
    double dy = (by - ay) * sgn, dz = (bz - az) * sgn;
    return dz > 0 || (dz == 0 && dy < 0);
}

/* Crossings of the ray (y, z) along +x with the triangles in list. */
static size_t row_xings(const vx_mesh *m, const uint32_t *list, size_t n, double y, double z,
                        xing *out)
{
    size_t c = 0;
    for (size_t t = 0; t < n; t++) {
        const uint32_t *v = m->tri + 3 * (size_t)list[t];
        const double *a = m->pos + 3 * (size_t)v[0], *b = m->pos + 3 * (size_t)v[1],
                     *d = m->pos + 3 * (size_t)v[2];
        /* normal.x = area of the yz projection, signed */
        double nx = (b[1] - a[1]) * (d[2] - a[2]) - (b[2] - a[2]) * (d[1] - a[1]);
        if (nx == 0) continue;
        double sgn = nx > 0 ? 1 : -1;
        if (!edge_in(a[1], a[2], b[1], b[2], y, z, sgn) ||
            !edge_in(b[1], b[2], d[1], d[2], y, z, sgn) ||
            !edge_in(d[1], d[2], a[1], a[2], y, z, sgn))
            continue;
        double w0 = ((b[1] - y) * (d[2] - z) - (b[2] - z) * (d[1] - y)) / nx;
        double w1 = ((d[1] - y) * (a[2] - z) - (d[2] - z) * (a[1] - y)) / nx;
        double w2 = 1 - w0 - w1;
        out[c].x = w0 * a[0] + w1 * b[0] + w2 * d[0];
        out[c].s = nx > 0 ? -1 : 1;
        c++;
    }
    qsort(out, c, sizeof *out, cmp_xing);
    return c;
}

/* Inside test of x against sorted crossings: half-open [entry, exit). */
static int inside_at(const xing *xs, size_t n, double x, vx_inside rule)
{
    int w = 0, p = 0;
    for (size_t i = 0; i < n && xs[i].x <= x; i++) {
        w += xs[i].s;
        p ^= 1;
    }
    return rule == VX_INSIDE_NONZERO ? w != 0 : p;
}

static int standin(const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                   vx_voxelize_stats *st, const char *method, vx_err *err)
{
    memset(st, 0, sizeof *st);
    st->method = method;
    const vx_grid *g = &d->grid;
    const int nx = g->dims[0], ny = g->dims[1], nz = g->dims[2];
    const int ss = d->supersample == 2 ? 2 : 1;
    if (vx_bitgrid_alloc(out, g, ss == 2, err)) return -1;
    uint32_t *list = malloc((m->ntris + 1) * sizeof *list);
    xing *xs = malloc((m->ntris + 1) * sizeof *xs);
    if (!list || !xs) {
        free(list);
        free(xs);
        vx_bitgrid_free(out);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the voxelizer");
    }
    vx_inside rule = d->inside == VX_INSIDE_ROBUST ? VX_INSIDE_PARITY : d->inside;
    for (int k = 0; k < nz; k++) {
        if (d->progress && d->progress(d->ud, (double)k / nz, err)) goto fail;
        double z0 = g->origin[2] + k * g->h, z1 = z0 + g->h;
        size_t n = 0;
        for (size_t t = 0; t < m->ntris; t++) {
            const uint32_t *v = m->tri + 3 * t;
            double lo =
                fmin(fmin(m->pos[3 * v[0] + 2], m->pos[3 * v[1] + 2]), m->pos[3 * v[2] + 2]);
            double hi =
                fmax(fmax(m->pos[3 * v[0] + 2], m->pos[3 * v[1] + 2]), m->pos[3 * v[2] + 2]);
            if (hi >= z0 && lo <= z1) list[n++] = (uint32_t)t;
        }
        for (int j = 0; j < ny; j++) {
            uint8_t *cnt = ss == 2 ? out->counts + ((size_t)k * ny + j) * nx : NULL;
            for (int sz = 0; sz < ss; sz++)
                for (int sy = 0; sy < ss; sy++) {
                    double off = ss == 2 ? 0.25 : 0.5;
                    double y = g->origin[1] + (j + off + 0.5 * sy) * g->h;
                    double z = g->origin[2] + (k + off + 0.5 * sz) * g->h;
                    size_t c = row_xings(m, list, n, y, z, xs);
                    if (!c) continue;
                    for (int i = 0; i < nx; i++)
                        for (int sx = 0; sx < ss; sx++) {
                            double x = g->origin[0] + (i + off + 0.5 * sx) * g->h;
                            if (!inside_at(xs, c, x, rule)) continue;
                            if (cnt)
                                cnt[i]++;
                            else
                                out->bits[((size_t)k * ny + j) * out->wx + (size_t)(i >> 5)] |=
                                    1u << (i & 31);
                        }
                }
            if (cnt)
                for (int i = 0; i < nx; i++)
                    if (cnt[i] >= d->threshold)
                        out->bits[((size_t)k * ny + j) * out->wx + (size_t)(i >> 5)] |= 1u
                                                                                        << (i & 31);
        }
    }
    if (d->fill == VX_FILL_SURFACE) {
        /* keep inside voxels with an outside 6-neighbour (or on the border) */
        vx_bitgrid solid;
        if (vx_bitgrid_alloc(&solid, g, 0, err)) goto fail;
        memcpy(solid.bits, out->bits, out->wx * (size_t)ny * nz * sizeof *out->bits);
        for (int k = 0; k < nz; k++)
            for (int j = 0; j < ny; j++)
                for (int i = 0; i < nx; i++) {
                    if (!vx_bitgrid_get(&solid, i, j, k)) continue;
                    int interior = i > 0 && j > 0 && k > 0 && i < nx - 1 && j < ny - 1 &&
                                   k < nz - 1 && vx_bitgrid_get(&solid, i - 1, j, k) &&
                                   vx_bitgrid_get(&solid, i + 1, j, k) &&
                                   vx_bitgrid_get(&solid, i, j - 1, k) &&
                                   vx_bitgrid_get(&solid, i, j + 1, k) &&
                                   vx_bitgrid_get(&solid, i, j, k - 1) &&
                                   vx_bitgrid_get(&solid, i, j, k + 1);
                    if (interior)
                        out->bits[((size_t)k * ny + j) * out->wx + (size_t)(i >> 5)] &=
                            ~(1u << (i & 31));
                }
        vx_bitgrid_free(&solid);
    }
    free(list);
    free(xs);
    st->voxels_inside = vx_bitgrid_count(out);
    st->chunks = 1;
    if (!strcmp(method, "slice")) st->slices = nz * ss;
    return 0;
fail:
    free(list);
    free(xs);
    vx_bitgrid_free(out);
    return -1;
}

int vx_voxelize_peel(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                     vx_voxelize_stats *st, vx_err *err)
{
    return standin(m, d, out, st, "peel", err);
}

int vx_voxelize_slice(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                      vx_voxelize_stats *st, vx_err *err)
{
    return standin(m, d, out, st, "slice", err);
}

int vx_voxelize(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                vx_voxelize_stats *st, vx_err *err)
{
    VX_WARN("voxel.standin", "CPU stand-in voxelizer (GPU engines not merged yet)");
    if (d->method == VX_METHOD_SLICE) return vx_voxelize_slice(gl, m, d, out, st, err);
    return vx_voxelize_peel(gl, m, d, out, st, err);
}
