/* The faces sample pattern's count (src/voxel/faces.c), exposed for its
 * unit test. Not a public API. */
#ifndef VX_FACES_INT_H
#define VX_FACES_INT_H

#include <stdint.h>

#include "gl/gl.h"
#include "voxel/voxel.h"

/* Zero means default: slabs as FACES_SLAB_CAP and the GPU allow. */
typedef struct vx_faces_count_desc {
    int max_rows;       /* z rows per slab at most (tests force many slabs) */
    uint64_t max_bytes; /* GPU buffer bytes the count may take */
    /* called before each slab with the fraction done (and so polls the
     * job's stop hook); nonzero stops the count: -1 with err as it set */
    int (*progress)(void *ud, double fraction, vx_err *err);
    void *ud;
} vx_faces_count_desc;

/* The sample grids: the centres, then the lower and upper face samples
 * along x, y and z. */
#define VX_FACES_SAMPLES 7

/* out->counts[i,j,k] = how many of the seven sample grids g (each of the
 * voxel grid's dims: g[0] the centres, g[2a + 1] and g[2a + 2] the samples
 * just inside voxel (i,j,k)'s lower and upper face along axis a) have
 * voxel (i,j,k) set, and out's bits where that count >= threshold,
 * counted on the GPU a z slab at a time. out is allocated with counts, its
 * grid the voxel grid; fd may be NULL. Adds upload, count and read-back
 * times to st. GL thread. 0 or -1 (grid_too_large, job_memory_limit, GL
 * errors). */
int vx_faces_count(vx_gl *gl, const vx_bitgrid g[VX_FACES_SAMPLES], int threshold, vx_bitgrid *out,
                   const vx_faces_count_desc *fd, vx_voxelize_stats *st, vx_err *err);

#endif
