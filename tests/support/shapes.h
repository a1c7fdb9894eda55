/* Test meshes: built in code, or the shared meshes of ../shared/data
 * (shared by the unit tests). The builders abort on failure (they are test
 * fixtures). */
#ifndef VX_TEST_SHAPES_H
#define VX_TEST_SHAPES_H

#include <stddef.h>
#include <stdint.h>

#include "mesh/mesh.h"

vx_mesh *shape_mesh_from(size_t nv, const double *pos, size_t nt, const uint32_t *idx);
/* Axis-aligned box [lo, hi] as 12 outward-facing triangles. */
vx_mesh *shape_box(const double lo[3], const double hi[3]);
double shape_signed_volume(const vx_mesh *m);
void shape_flip(vx_mesh *m);
/* Closed surface from an (nu x nv) parameter grid: sphere (poles) or torus
 * (r1, r2); outward unless `inward`. */
vx_mesh *shape_param_mesh(int nu, int nv, int poles, int inward, double cx, double cy, double cz,
                          double r1, double r2);
vx_mesh *shape_sphere(double cx, double cy, double cz, double r, int inward);
/* Concatenation of meshes. */
vx_mesh *shape_merge(vx_mesh **parts, int n);
/* Polygon mesh: face f has sizes[f] corners (sizes NULL: every face a
 * quad), indices face after face; analysed. */
vx_mesh *shape_poly_mesh(size_t nv, const double *pos, size_t nf, const uint32_t *sizes,
                         const uint32_t *idx);
/* The shared test mesh NAME (VX_MESH_DIR/NAME, any upload format, through
 * the sniffer), or NULL with the reader's message on stderr. */
vx_mesh *shape_load(const char *name);
/* Point (u, v) of Bézier patch p of a .bpt mesh (its 4x4 net, patch_idx). */
void shape_bezier_eval(const vx_mesh *m, size_t p, double u, double v, double out[3]);

#endif
