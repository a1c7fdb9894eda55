/* Face-centre supersampling: supersample 2 with samples "faces".
 *
 * Seed 003's accuracy improvement samples a voxel at 2 x 2 x 2 points, a
 * quarter voxel from its centre along each axis, and sets it when at least
 * `threshold` are inside. Measured by the seed's own figure (the mean
 * distance from the centres of surface voxels to the surface), that pattern
 * has a floor: on a face parallel to a grid plane the lowest threshold sets
 * a voxel when the face lies less than 3/4 voxel above its centre and more
 * than 1/4 below, so over the face's offsets the distance is uniform on
 * [0, 3/4) and its mean 0.3125 (bench/RESULTS.md).
 *
 * This pattern samples the centre and the centres of the six faces. With
 * threshold 1 a voxel is set when the surface lies less than half a voxel
 * beyond its centre along some axis: on a plane with unit normal n the
 * surface voxels are those whose signed distance lies within
 * [-m/2, m/2), m = max |n_a|, and their mean distance is m/4 -- at most
 * 0.25 (faces parallel to grid planes) and 0.14 on a plane at equal angles
 * to the axes. That is the least any binary voxelization can reach on a
 * plane parallel to a grid plane (exactly one voxel per column is the last
 * inside, and the nearest centre is on average 1/4 away). Higher
 * thresholds shrink the solid back towards centre sampling (4 of 7: the
 * centre's own answer wherever the surface is flat within the voxel).
 *
 * The samples are the centres of four grids: the voxel grid itself, and the
 * grid moved by half a voxel against x (one more voxel along x: its voxel i
 * is centred on the face between voxels i-1 and i), against y and against
 * z. Each is voxelized at its centres by the requested method (auto: scan),
 * with the same inside rule and tie rule; a voxel's count is its centre plus
 * its two faces along each axis. */
#include <stdlib.h>
#include <string.h>

#include "voxel/voxel.h"

typedef struct sub_progress {
    const vx_voxelize_desc *d;
    int part; /* 0..3 */
} sub_progress;

static int progress(void *ud, double f, vx_err *err)
{
    sub_progress *p = ud;
    return p->d->progress(p->d->ud, (p->part + f) / 4.0, err);
}

static void add_stats(vx_voxelize_stats *st, const vx_voxelize_stats *s)
{
    st->method = s->method;
    if (s->layers > st->layers) st->layers = s->layers;
    st->passes += s->passes;
    st->slices += s->slices;
    st->chunks += s->chunks;
    st->upload_ms += s->upload_ms;
    st->gpu_peel_ms += s->gpu_peel_ms;
    st->gpu_fill_ms += s->gpu_fill_ms;
    st->gpu_slice_ms += s->gpu_slice_ms;
    st->readback_ms += s->readback_ms;
}

static inline uint32_t word(const vx_bitgrid *g, int j, int k, size_t w)
{
    if (w >= g->wx) return 0;
    return g->bits[((size_t)k * (size_t)g->grid.dims[1] + (size_t)j) * g->wx + w];
}

/* out->counts[i,j,k] = samples inside; out->bits where >= threshold. */
static void combine(const vx_bitgrid g[4], int threshold, vx_bitgrid *out)
{
    const int nx = out->grid.dims[0], ny = out->grid.dims[1], nz = out->grid.dims[2];
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++) {
            uint8_t *cnt = out->counts + ((size_t)k * ny + j) * (size_t)nx;
            uint32_t *row = out->bits + ((size_t)k * ny + j) * out->wx;
            for (size_t w = 0; w < out->wx; w++) {
                /* the centre, then the lower and upper face along x, y, z */
                uint32_t x0 = word(&g[1], j, k, w), xn = word(&g[1], j, k, w + 1);
                uint32_t s[7] = {word(&g[0], j, k, w),     x0,
                                 (x0 >> 1) | (xn << 31),   word(&g[2], j, k, w),
                                 word(&g[2], j + 1, k, w), word(&g[3], j, k, w),
                                 word(&g[3], j, k + 1, w)};
                int n = nx - (int)(32 * w) < 32 ? nx - (int)(32 * w) : 32;
                uint32_t set = 0;
                for (int b = 0; b < n; b++) {
                    int c = 0;
                    for (int q = 0; q < 7; q++)
                        c += (int)((s[q] >> b) & 1u);
                    cnt[32 * w + (size_t)b] = (uint8_t)c;
                    if (c >= threshold) set |= 1u << b;
                }
                row[w] = set;
            }
        }
}

int vx_voxelize_faces(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                      vx_voxelize_stats *st, vx_err *err)
{
    vx_voxelize_stats dummy;
    if (!st) st = &dummy;
    memset(st, 0, sizeof *st);
    memset(out, 0, sizeof *out);
    const vx_grid *grid = &d->grid;
    /* The result's bits and counts, then the four sample grids, live
     * together: each run gets what the ones before it left of max_memory. */
    uint64_t held = vx_bitgrid_bytes(grid->dims, 2);
    if (d->max_memory && held > d->max_memory)
        return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                          "the faces sample pattern on a %dx%dx%d grid needs more than %llu "
                          "bytes, the job may use %llu",
                          grid->dims[0], grid->dims[1], grid->dims[2], (unsigned long long)held,
                          (unsigned long long)d->max_memory);
    if (vx_bitgrid_alloc(out, grid, 1, err)) return -1;
    out->nsamples = 7;

    vx_bitgrid g[4];
    memset(g, 0, sizeof g);
    sub_progress sp = {d, 0};
    vx_voxelize_desc sub = *d;
    sub.supersample = 1;
    sub.samples = VX_SAMPLES_CUBE;
    sub.progress = d->progress ? progress : NULL;
    sub.ud = &sp;
    int rc = -1;
    for (int part = 0; part < 4; part++) {
        sub.grid = *grid;
        if (part > 0) {
            sub.grid.origin[part - 1] -= 0.5 * grid->h;
            sub.grid.dims[part - 1] += 1;
        }
        if (d->max_memory) {
            if (held >= d->max_memory) {
                vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                           "the faces sample pattern on a %dx%dx%d grid needs more than the "
                           "%llu bytes the job may use",
                           grid->dims[0], grid->dims[1], grid->dims[2],
                           (unsigned long long)d->max_memory);
                goto done;
            }
            sub.max_memory = d->max_memory - held;
        }
        sp.part = part;
        vx_voxelize_stats s;
        if (vx_voxelize(gl, m, &sub, &g[part], &s, err)) goto done;
        add_stats(st, &s);
        held += vx_bitgrid_bytes(sub.grid.dims, 1);
    }
    combine(g, d->threshold, out);
    st->voxels_inside = vx_bitgrid_count(out);
    rc = 0;
done:
    for (int part = 0; part < 4; part++)
        vx_bitgrid_free(&g[part]);
    if (rc) vx_bitgrid_free(out);
    return rc;
}
