/* The CPU side of the lattice rules every engine shares (xing.h gives the
 * GL side): positions in the lattice's units (p - origin) / h, coverage
 * decided on those positions snapped to 1/VX_GRID_SNAP voxel by exact
 * integer edge functions with one tie rule, and each crossing placed by
 * shaders/voxel_xing.glsl's formula in double, then snapped to
 * 1/VX_GRID_XING_SNAP voxel. cpu.c (rays along x) and
 * winding.c (rays along z) both decide their voxels here, so a column's
 * voxels come from lattice numbers only and every brick of a lattice gives
 * the same ones. The two axes across a ray are called (y, z) below, the
 * ray's own axis x; a caller along another axis permutes its coordinates.
 * lattice.c builds with -ffp-contract=off (the shader's operations, one
 * for one). */
#ifndef VX_VOXEL_LATTICE_H
#define VX_VOXEL_LATTICE_H

#include <math.h>
#include <stdint.h>

#include "voxel/voxel.h"

typedef __int128 vx_i128;

/* Snapped coordinates (VX_GRID_SNAP units) stay within +-2^58 so that edge
 * functions fit __int128 and centres int64 (lattice index <= 2^40). */
#define VX_LATTICE_SNAP_MAX 288230376151711744.0 /* 2^58 */

/* 1 when lattice position u lies within 2^50 voxels of the origin along
 * every axis (so it snaps into int64 with room for the edge functions). */
static inline int vx_lattice_in_range(const double u[3])
{
    return fabs(u[0] * VX_GRID_SNAP) < VX_LATTICE_SNAP_MAX &&
           fabs(u[1] * VX_GRID_SNAP) < VX_LATTICE_SNAP_MAX &&
           fabs(u[2] * VX_GRID_SNAP) < VX_LATTICE_SNAP_MAX;
}

/* u[a] = (p[a] - origin[a]) / h for a = 0..2: 0, or -1 when u is not
 * vx_lattice_in_range (or not finite). */
int vx_lattice_unit(const vx_grid *g, const double p[3], double u[3]);

/* Lattice coordinate u snapped to 1/VX_GRID_SNAP voxel, in those units. */
static inline int64_t vx_lattice_snap(double u)
{
    return (int64_t)nearbyint(u * VX_GRID_SNAP);
}

/* Column centres c with lo <= (index + c) * SNAP + SNAP / 2 <= hi (snapped
 * units), as the range [*a, *b] clipped to 0..n-1 (empty: *a > *b). */
void vx_lattice_centres(int64_t lo, int64_t hi, int64_t index, int n, int *a, int *b);

/* Edge A -> B of a triangle counter-clockwise in (y, z), snapped:
 * E(q) = (B - A) x (q - A), positive inside, plus 1 where a centre on the
 * edge counts as inside (the centre perturbed by (eps, eps^2): the sign of
 * -(Bz - Az), else of By - Ay), so that the two triangles of a shared edge
 * split its centres and exactly one triangle of a fan holds its vertex.
 * `at` is E at the first centre (cy0, cz0); add d1 per centre along y, d2
 * per centre along z. */
typedef struct vx_lattice_edge {
    vx_i128 at, d1, d2;
} vx_lattice_edge;

void vx_lattice_edge_set(vx_lattice_edge *e, const int64_t A[2], const int64_t B[2], int64_t cy0,
                         int64_t cz0);

/* Twice the signed area of the snapped (y, z) triangle A, B, C: positive
 * counter-clockwise. */
static inline vx_i128 vx_lattice_det(const int64_t A[2], const int64_t B[2], const int64_t C[2])
{
    return (vx_i128)(B[0] - A[0]) * (C[1] - A[1]) - (vx_i128)(B[1] - A[1]) * (C[0] - A[0]);
}

/* The most |centre index| vx_lattice_xing answers (it clamps to it). */
#define VX_LATTICE_XING_MAX 536870912.0 /* 2^29 */

/* xing() of shaders/voxel_xing.glsl, one sample per voxel: the first
 * centre along x at or beyond where the ray through lattice centre
 * (cy, cz) crosses the triangle (vertex a, edges e1, e2 from it, lattice
 * units, x first), that crossing snapped to 1/VX_GRID_XING_SNAP voxel, less the
 * brick's index ix, clamped to +-2^29. A ray the
 * snapped coverage gave the triangle but that misses it by a rounding is
 * placed at the nearest point of its edges, within 1/64 voxel of the
 * plane's own crossing. */
int32_t vx_lattice_xing(const double a[3], const double e1[3], const double e2[3], double cy,
                        double cz, double ix);

#endif
