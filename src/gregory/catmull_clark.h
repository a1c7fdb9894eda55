/* Uniform Catmull-Clark subdivision through OpenSubdiv Far (the seed 001
 * comparison), and the `catmull-clark` job kind.
 *
 * Topology goes to OpenSubdiv as it is (every face size, boundaries,
 * non-manifold edges as OpenSubdiv takes them). Boundaries use
 * VTX_BOUNDARY_EDGE_ONLY: boundary edges become the cubic B-spline curve of
 * the boundary polygon and boundary corners stay smooth (OpenSubdiv's own
 * default, VTX_BOUNDARY_NONE, leaves boundary faces out of the limit
 * surface). After level 1 every face is a quad: level k has
 * corners(mesh) * 4^(k-1) quads, where corners is the sum of the face sizes. */
#ifndef VX_GREGORY_CATMULL_CLARK_H
#define VX_GREGORY_CATMULL_CLARK_H

#include <stddef.h>
#include <stdint.h>

#include "jobs/kind.h"
#include "mesh/mesh.h"
#include "util/err.h"

/* The most levels a job may ask for, whatever the limits (OpenSubdiv's own
 * bound is 15). */
#define VX_CC_MAX_LEVELS 10

/* Quads after `levels` (>= 1) uniform levels of m (any thread). */
uint64_t vx_cc_quads(const vx_mesh *m, int levels);

/* Refines m `levels` times (1..VX_CC_MAX_LEVELS). With `limit`, positions
 * are projected to the limit surface; normals are always the limit
 * normals (cross product of OpenSubdiv's limit tangents; where that
 * vanishes, the area-weighted normal of the adjacent faces). Returns 0 with
 * *out an owned analysed all-quad mesh and *normals (3 floats per vertex,
 * owned, free()), or -1 (VX_EUNPROC osd_topology when OpenSubdiv refuses
 * the topology; out_of_memory). Any thread. */
int vx_cc_refine(const vx_mesh *m, int levels, int limit, vx_mesh **out, float **normals,
                 vx_err *err);

extern const vx_kind vx_kind_catmull_clark;

#endif
