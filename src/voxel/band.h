/* The narrow band of a bit grid's signed distance field (vdb.cc's level
 * sets): for each voxel centre, the exact Euclidean distance to the nearest
 * voxel cube of the other state, that is to the boundary between set and
 * unset voxels, where voxels outside the grid are unset. Within 3 voxels
 * that distance takes one of VX_BAND_LEVELS values, sqrt(s) / 2 for s a sum
 * of three of 0, 1, 9, 25 ((|d| - 1/2)^2 along an axis, in quarters).
 *
 * The work is cut in tasks of 8 z rows by VX_BAND_TY y rows, all x; the
 * grid's rows are read 64 bits at a time and the levels of 64 voxels are
 * decided together, each distance a union of shifted rows. */
#ifndef VX_VOXEL_BAND_H
#define VX_VOXEL_BAND_H

#include <stddef.h>
#include <stdint.h>

#define VX_BAND_HALF 3    /* half width, voxels: the band is |distance| < 3 */
#define VX_BAND_LEVELS 13 /* distances below VX_BAND_HALF */
#define VX_BAND_TY 64     /* y rows of a task */

/* vx_band_q[l]: 4 d^2 for d the distance of level l (1..VX_BAND_LEVELS),
 * voxels: d = sqrt(q) / 2. */
extern const int vx_band_q[VX_BAND_LEVELS + 1];

/* Rows of a grid of dims voxels: row (j, k) is wx 32-bit words (bit i of
 * word i / 32 is voxel i) at bits + ((k - k0) * dims[1] + j) * wx, held for
 * k in [k0, k1). Rows outside the grid are unset; a task reads the rows
 * within 3 of its own, which must be held. */
typedef struct vx_band_rows {
    int dims[3];
    size_t wx;
    const uint32_t *bits;
    int k0, k1;
} vx_band_rows;

/* Columns of 64 voxels a task covers: x from -64 to 64 (columns - 1), so
 * that the band outside the grid (x down to -3 and up to dims[0] + 2) is in. */
int vx_band_columns(const vx_band_rows *r);
/* Scratch bytes vx_band_task needs (16-byte aligned, as malloc gives). */
size_t vx_band_scratch_bytes(const vx_band_rows *r);
/* The band's levels for z in [z0, z0 + 8) and y in [y0, y0 + VX_BAND_TY)
 * (any z0, y0; rows outside the grid included): need[p] (columns bytes) is
 * 1 where column p may hold band voxels, and only there is lev written:
 * lev[((z - z0) * VX_BAND_TY + y - y0) * 64 columns + x + 64] is the voxel's
 * level, 0 outside the band. */
void vx_band_task(const vx_band_rows *r, int z0, int y0, void *scratch, uint8_t *need,
                  uint8_t *lev);
/* Voxels i to i + 7 of row (j, k) as the bits of a byte, for i a multiple
 * of 8 (0 outside the grid or the held rows). */
unsigned vx_band_byte(const vx_band_rows *r, int i, int j, int k);

#endif
