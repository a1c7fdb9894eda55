/* Bicubic Gregory patches (seed 001): the patch set every construction
 * produces and the tessellator consumes.
 *
 * Constructions (each fills a vx_gpatch_set):
 *   interpolate     the seed's: edges become cubic curves through their end
 *                   vertices, interiors from the compatibility correction
 *   approximate-cc  Gregory patches approximating the Catmull-Clark limit
 *   bezier          bicubic Bézier patches (.bpt uploads): interior pairs equal
 *
 * Control points of one patch, 20 points of 3 doubles:
 *   slot 4*j + i (i, j = 0..3)  the 4x4 net P_ij, i along u, j along v; for the
 *                               four interior slots (i, j in {1, 2}) this is
 *                               P_ij0, the point that moves the v-boundaries
 *                               (weight u in Q11)
 *   slots 16..19                P_111, P_211, P_121, P_221 (the k = 1 points,
 *                               weight v in Q11: they move the u-boundaries)
 * so that, with the seed's formulas,
 *   Q11 = (u P110 + v P111) / (u + v)
 *   Q21 = ((1-u) P210 + v P211) / ((1-u) + v)
 *   Q12 = (u P120 + (1-v) P121) / (u + (1-v))
 *   Q22 = ((1-u) P220 + (1-v) P221) / ((1-u) + (1-v))
 *   S(u, v) = sum_ij B_i(u) B_j(v) Q_ij(u, v)
 * A patch whose k = 0 and k = 1 points coincide is the bicubic Bézier patch
 * of the 4x4 net.
 *
 * Corners are numbered 0: (u,v) = (0,0), 1: (1,0), 2: (1,1), 3: (0,1).
 * corner_key says which corners are the same point of the surface: the
 * input vertex id for mesh constructions, the de-duplicated control point
 * for Bézier input. Two patches share an edge when they share both corner
 * keys of it and its boundary curve: two different curves can join the
 * same two corners (the halves of a tube's cross-section), so the layout
 * (layout.c) also compares the curves' inner control points, to 1e-6 of
 * the curve's control polygon. Corners weld by keys alone. */
#ifndef VX_GREGORY_H
#define VX_GREGORY_H

#include <stddef.h>
#include <stdint.h>

#include "mesh/mesh.h"
#include "util/err.h"

#define VX_GPATCH_POINTS 20

typedef struct vx_gpatch_set {
    size_t npatches;
    double *cp;           /* npatches * VX_GPATCH_POINTS * 3 */
    uint32_t *corner_key; /* npatches * 4 */
    uint32_t *face;       /* npatches: the input face (or Bézier patch) it came from */
} vx_gpatch_set;

/* Allocates a set of n patches (arrays zeroed); NULL on allocation failure. */
vx_gpatch_set *vx_gpatch_set_new(size_t n);
void vx_gpatch_set_free(vx_gpatch_set *s);

/* Evaluates one patch (60 doubles, the layout above) at (u, v) in [0,1]^2:
 * position, and the unit normal dS/du x dS/dv (normalised; at a corner where
 * that product vanishes the limit along the diagonal is used). nrm may be
 * NULL. The blend at a corner (u + v = 0 and the like) takes the limit: the
 * k point that the boundary through that corner uses. */
void vx_gpatch_eval(const double *cp, double u, double v, double pos[3], double nrm[3]);

/* Patches whose normal at their centre turns against their face (the input
 * face they came from, Newell normal; for Bézier input the patch's corner
 * quad): folds, where a construction bends a patch over. Any thread. */
size_t vx_gpatch_folded(const vx_gpatch_set *s, const vx_mesh *m);

/* ---- The interpolate construction (build.c) ----
 *
 * A mesh of quads only gives one patch per face. Any other mesh (a
 * triangle or n-gon anywhere) has every face split into n quads around its
 * centre (corners: vertex, edge midpoint, centre, previous edge midpoint),
 * so that both sides of every edge split it at the same point (no
 * T-junctions). Every patch corner ("node": input vertex, edge midpoint,
 * face centre) has a position and a tangent plane; every patch edge is a
 * cubic curve whose end tangents lie in those planes; the interior points
 * come from the Chiyokura-Kimura correction of every patch edge on its own
 * (seed 001 §2.1.4).
 *
 * vx_gregory_topo holds what depends only on the face structure (edges,
 * boundary neighbours, nodes, curves, patch/curve incidences), so that a
 * deformation frame redoes only the position-dependent part. */
typedef struct vx_gregory_topo vx_gregory_topo;

/* Builds the topology tables of a polygon mesh (faces of >= 3 vertices).
 * Owned; NULL with err (VX_EUNPROC for an unusable mesh, VX_EINTERNAL for
 * memory). Any thread. */
vx_gregory_topo *vx_gregory_topo_new(const vx_mesh *m, vx_err *err);
void vx_gregory_topo_free(vx_gregory_topo *t);
/* Patches the construction makes (faces, or the sum of face sizes when split). */
size_t vx_gregory_topo_npatches(const vx_gregory_topo *t);
/* Input vertices the positions of vx_gregory_build must have. */
size_t vx_gregory_topo_nverts(const vx_gregory_topo *t);

/* Fills s (vx_gregory_topo_npatches patches, allocated by the caller) from
 * the vertex positions pos (3 * nverts doubles). Any thread; t is only read. */
void vx_gregory_build(const vx_gregory_topo *t, const double *pos, vx_gpatch_set *s);

/* Bicubic Bézier input (m->npatches > 0): one Gregory patch per Bézier
 * patch with equal interior pairs; positions from pos (3 * m->nverts
 * doubles) or m->pos when NULL. corner_key = the corner's position index
 * after merging bitwise-equal positions. Owned; NULL with err. */
vx_gpatch_set *vx_gregory_from_bezier(const vx_mesh *m, const double *pos, vx_err *err);

#endif
