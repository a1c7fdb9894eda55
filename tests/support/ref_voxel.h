/* CPU reference voxelizer for the tests: the exact inside answer at every
 * voxel centre, in double precision, by casting a ray from the centre
 * along +x. Edge and vertex hits are resolved by simulated perturbation of
 * the ray (y + eps, z + eps^2), so a watertight mesh is crossed exactly
 * once where two triangles meet. A centre exactly on a face follows the
 * project's tie rule: half-open [entry, exit) along x. */
#ifndef VX_REF_VOXEL_H
#define VX_REF_VOXEL_H

#include <stddef.h>
#include <stdint.h>

#include "mesh/mesh.h"
#include "voxel/voxel.h"

/* out: nx*ny*nz bytes, x fastest, 1 = inside. rule: parity or nonzero
 * (winding number along the ray != 0). Returns 0, -1 on allocation failure. */
int ref_voxelize(const vx_mesh *m, const vx_grid *g, vx_inside rule, uint8_t *out);
/* Generalized winding number at p (sum of signed solid angles / 4 pi):
 * ~1 inside a closed outward-oriented mesh, ~0 outside, in between near
 * holes. */
double ref_winding_number(const vx_mesh *m, const double p[3]);
/* Intersection over union of a reference byte grid and a bit grid. */
double ref_iou(const uint8_t *ref, const vx_bitgrid *g);
/* Voxels where a reference byte grid and a bit grid differ. */
size_t ref_mismatches(const uint8_t *ref, const vx_bitgrid *g);
/* Voxelizes m with the reference on g and compares b with it: prints one
 * line (what, dims, counts, mismatches, IoU), stores the IoU in *iou and
 * returns the number of differing voxels ((size_t)-1 when out of memory). */
size_t ref_compare(const char *what, const vx_mesh *m, const vx_grid *g, vx_inside rule,
                   const vx_bitgrid *b, double *iou);

#endif
