#include "ref_voxel.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct hit {
    double x;
    int s; /* +1: the ray leaves the solid (normal.x > 0), -1: enters */
} hit;

static int cmp_hit(const void *a, const void *b)
{
    double x = ((const hit *)a)->x, y = ((const hit *)b)->x;
    return (x > y) - (x < y);
}

/* Sign of the 2-D orientation of p against edge a->b in the yz plane, with
 * p perturbed to (y + eps, z + eps^2) so it is never zero for a real edge. */
static int side(const double *a, const double *b, double py, double pz)
{
    double o = (b[1] - a[1]) * (pz - a[2]) - (b[2] - a[2]) * (py - a[1]);
    if (o != 0) return o > 0 ? 1 : -1;
    double dz = b[2] - a[2], dy = b[1] - a[1];
    if (dz != 0) return dz < 0 ? 1 : -1;
    if (dy != 0) return dy > 0 ? 1 : -1;
    return 0;
}

int ref_voxelize(const vx_mesh *m, const vx_grid *g, vx_inside rule, uint8_t *out)
{
    int nx = g->dims[0], ny = g->dims[1], nz = g->dims[2];
    size_t nrows = (size_t)ny * (size_t)nz;
    /* Bucket triangles by the rows (j,k) whose centres their yz bbox covers. */
    uint32_t *cnt = calloc(nrows + 1, sizeof *cnt);
    if (!cnt) return -1;
    int *range = malloc(m->ntris * 4 * sizeof *range + 1);
    if (!range) {
        free(cnt);
        return -1;
    }
    for (size_t t = 0; t < m->ntris; t++) {
        double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
        for (int v = 0; v < 3; v++)
            for (int a = 0; a < 2; a++) {
                double x = m->pos[3 * m->tri[3 * t + v] + 1 + a];
                lo[a] = fmin(lo[a], x);
                hi[a] = fmax(hi[a], x);
            }
        int *r = range + 4 * t;
        /* centre c = origin + (j + 0.5) h within [lo, hi] */
        r[0] = (int)fmax(0, ceil(vx_grid_coord(g, 1, lo[0]) - 0.5) - 1);
        r[1] = (int)fmin(ny - 1, floor(vx_grid_coord(g, 1, hi[0]) - 0.5) + 1);
        r[2] = (int)fmax(0, ceil(vx_grid_coord(g, 2, lo[1]) - 0.5) - 1);
        r[3] = (int)fmin(nz - 1, floor(vx_grid_coord(g, 2, hi[1]) - 0.5) + 1);
        for (int k = r[2]; k <= r[3]; k++)
            for (int j = r[0]; j <= r[1]; j++)
                cnt[(size_t)k * ny + j + 1]++;
    }
    for (size_t i = 0; i < nrows; i++)
        cnt[i + 1] += cnt[i];
    uint32_t *ids = malloc((size_t)cnt[nrows] * sizeof *ids + 1);
    uint32_t *fill = malloc(nrows * sizeof *fill + 1);
    hit *hits = malloc(m->ntris * sizeof *hits + 1);
    if (!ids || !fill || !hits) {
        free(cnt), free(range), free(ids), free(fill), free(hits);
        return -1;
    }
    memcpy(fill, cnt, nrows * sizeof *fill);
    for (size_t t = 0; t < m->ntris; t++) {
        int *r = range + 4 * t;
        for (int k = r[2]; k <= r[3]; k++)
            for (int j = r[0]; j <= r[1]; j++)
                ids[fill[(size_t)k * ny + j]++] = (uint32_t)t;
    }
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++) {
            size_t row = (size_t)k * ny + j;
            /* centres in the lattice: origin + (index + j + 1/2) h */
            double py = g->origin[1] + ((double)g->index[1] + j + 0.5) * g->h,
                   pz = g->origin[2] + ((double)g->index[2] + k + 0.5) * g->h;
            size_t nh = 0;
            for (uint32_t q = cnt[row]; q < cnt[row + 1]; q++) {
                const uint32_t *tv = m->tri + 3 * (size_t)ids[q];
                const double *a = m->pos + 3 * tv[0], *b = m->pos + 3 * tv[1],
                             *c = m->pos + 3 * tv[2];
                double nxc = (b[1] - a[1]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[1] - a[1]);
                if (nxc == 0) continue; /* parallel to the ray */
                int s0 = side(a, b, py, pz), s1 = side(b, c, py, pz), s2 = side(c, a, py, pz);
                int want = nxc > 0 ? 1 : -1;
                if (s0 != want || s1 != want || s2 != want) continue;
                double nyc = (b[2] - a[2]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[2] - a[2]);
                double nzc = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
                /* in the lattice's units, snapped to 1/VX_GRID_XING_SNAP voxel as
                 * every engine snaps it (shaders/voxel_xing.glsl) */
                double x = a[0] - (nyc * (py - a[1]) + nzc * (pz - a[2])) / nxc;
                hits[nh].x =
                    nearbyint((x - g->origin[0]) / g->h * VX_GRID_XING_SNAP) / VX_GRID_XING_SNAP;
                hits[nh].s = want;
                nh++;
            }
            qsort(hits, nh, sizeof *hits, cmp_hit);
            /* Sweep: crossings strictly beyond the centre count. */
            int w = 0, par = 0;
            for (size_t q = 0; q < nh; q++) {
                w += hits[q].s;
                par ^= 1;
            }
            size_t q = 0;
            uint8_t *o = out + row * (size_t)nx;
            for (int i = 0; i < nx; i++) {
                double xc = (double)g->index[0] + i + 0.5;
                while (q < nh && hits[q].x <= xc) {
                    w -= hits[q].s;
                    par ^= 1;
                    q++;
                }
                o[i] = rule == VX_INSIDE_PARITY ? (uint8_t)par : (uint8_t)(w != 0);
            }
        }
    free(cnt), free(range), free(ids), free(fill), free(hits);
    return 0;
}

double ref_winding_number(const vx_mesh *m, const double p[3])
{
    double sum = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        double v[3][3], l[3];
        for (int i = 0; i < 3; i++) {
            const double *q = m->pos + 3 * m->tri[3 * t + i];
            for (int a = 0; a < 3; a++)
                v[i][a] = q[a] - p[a];
            l[i] = sqrt(v[i][0] * v[i][0] + v[i][1] * v[i][1] + v[i][2] * v[i][2]);
        }
        /* Van Oosterom & Strackee: tan(omega/2) = det / denominator */
        double det = v[0][0] * (v[1][1] * v[2][2] - v[1][2] * v[2][1]) -
                     v[0][1] * (v[1][0] * v[2][2] - v[1][2] * v[2][0]) +
                     v[0][2] * (v[1][0] * v[2][1] - v[1][1] * v[2][0]);
        double d01 = v[0][0] * v[1][0] + v[0][1] * v[1][1] + v[0][2] * v[1][2];
        double d12 = v[1][0] * v[2][0] + v[1][1] * v[2][1] + v[1][2] * v[2][2];
        double d20 = v[2][0] * v[0][0] + v[2][1] * v[0][1] + v[2][2] * v[0][2];
        double den = l[0] * l[1] * l[2] + d01 * l[2] + d12 * l[0] + d20 * l[1];
        sum += 2 * atan2(det, den);
    }
    return sum / (4 * M_PI);
}

double ref_iou(const uint8_t *ref, const vx_bitgrid *g)
{
    uint64_t inter = 0, uni = 0;
    int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++) {
                int a = ref[((size_t)k * ny + j) * nx + i], b = vx_bitgrid_get(g, i, j, k);
                inter += a & b;
                uni += a | b;
            }
    return uni ? (double)inter / (double)uni : 1.0;
}

size_t ref_mismatches(const uint8_t *ref, const vx_bitgrid *g)
{
    size_t n = 0;
    const int *dm = g->grid.dims;
    for (int k = 0; k < dm[2]; k++)
        for (int j = 0; j < dm[1]; j++)
            for (int i = 0; i < dm[0]; i++)
                n += ref[((size_t)k * dm[1] + j) * dm[0] + i] != vx_bitgrid_get(g, i, j, k);
    return n;
}

size_t ref_compare(const char *what, const vx_mesh *m, const vx_grid *g, vx_inside rule,
                   const vx_bitgrid *b, double *iou)
{
    size_t n = (size_t)g->dims[0] * g->dims[1] * g->dims[2], in = 0;
    uint8_t *ref = malloc(n ? n : 1);
    if (!ref || ref_voxelize(m, g, rule, ref)) {
        free(ref);
        return (size_t)-1;
    }
    for (size_t q = 0; q < n; q++)
        in += ref[q];
    size_t mis = ref_mismatches(ref, b);
    *iou = ref_iou(ref, b);
    printf("%-32s %dx%dx%d ref=%zu got=%llu mismatches=%zu IoU=%.6f\n", what, g->dims[0],
           g->dims[1], g->dims[2], in, (unsigned long long)vx_bitgrid_count(b), mis, *iou);
    free(ref);
    return mis;
}
