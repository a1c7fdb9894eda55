/* The `approximate-cc` construction: bicubic Gregory patches that
 * approximate the Catmull-Clark limit surface (Loop, Schaefer, Ni & Castaño
 * 2009, as OpenSubdiv builds them), and its distance to the true limit.
 *
 * The patches are those of OpenSubdiv's Far::PatchTableFactory at isolation
 * level 0 with ENDCAP_GREGORY_BASIS on a quad mesh: the input itself when
 * every face is a quad, else the input refined once (Catmull-Clark, so the
 * limit surface is the same). One patch per quad of that mesh, in its face
 * order: a face whose four vertices are regular is a bicubic B-spline patch,
 * converted exactly to Bézier (interior pairs equal); any other face is a
 * Gregory-basis end cap, whose 20 points (P, Ep, Em, Fp, Fm per corner) map
 * to the slots of gregory.h. Boundaries: OpenSubdiv's boundary patches
 * (phantom points folded into the basis) and boundary end caps, with
 * VTX_BOUNDARY_EDGE_ONLY as in catmull_clark.h. corner_key is the quad
 * mesh's vertex id at each corner, face the input face the quad came from.
 * The surface's parameter on each patch is the quad's own: corner 0 at its
 * first vertex, u towards the second. */
#ifndef VX_GREGORY_OSD_H
#define VX_GREGORY_OSD_H

#include "gregory/gregory.h"
#include "mesh/mesh.h"
#include "util/err.h"

/* Builds the patches of m (faces of any size; a manifold surface; a plan
 * used once). Returns 0
 * with *out an owned set, or -1 (VX_EUNPROC osd_topology or osd_patches
 * when OpenSubdiv cannot make one patch per quad, e.g. non-manifold
 * vertices; out_of_memory). Any thread. */
int vx_gregory_build_approx_cc(const vx_mesh *m, vx_gpatch_set **out, vx_err *err);

/* Frames (the same topology, new positions) only redo the positional work:
 * a plan holds what depends on the topology alone (OpenSubdiv's refiners,
 * patch table and patch map, where each quad's patch is). */
typedef struct vx_gregory_cc_plan vx_gregory_cc_plan;

/* The plan for m's topology (positions unused). Returns an owned plan or
 * NULL (errors as vx_gregory_build_approx_cc; the stop hook's, util/stop.h,
 * polled per 1024 quads after OpenSubdiv made its patches). Any thread. */
vx_gregory_cc_plan *vx_gregory_cc_plan_new(const vx_mesh *m, vx_err *err);
/* Patches the plan makes (the size of the set plan_eval fills). */
size_t vx_gregory_cc_plan_patches(const vx_gregory_cc_plan *p);
/* Fills s (vx_gpatch_set_new(vx_gregory_cc_plan_patches(p))) from pos, 3
 * doubles for each vertex of the plan's mesh. The plan keeps scratch
 * buffers: one thread at a time per plan. Returns 0 or -1. */
int vx_gregory_cc_plan_eval(vx_gregory_cc_plan *p, const double *pos, vx_gpatch_set *s,
                            vx_err *err);
/* NULL is a no-op. */
void vx_gregory_cc_plan_free(vx_gregory_cc_plan *p);

/* The largest distance, over samples_per_patch^2 points (u, v) of every
 * patch of s (built from m by vx_gregory_build_approx_cc), between s at
 * (u, v) and the Catmull-Clark limit surface at the same parameter
 * (OpenSubdiv's adaptive patches at isolation level 6), divided by m's
 * bbox diagonal. Returns -1 with err on failure. Any thread. */
double vx_gregory_cc_distance(const vx_mesh *m, const vx_gpatch_set *s, int samples_per_patch,
                              vx_err *err);

/* The same against OpenSubdiv's evaluation of the very patches s was
 * converted from (isolation 0): rounding only, the proof that the
 * conversion is exact. */
double vx_gregory_cc_mismatch(const vx_mesh *m, const vx_gpatch_set *s, int samples_per_patch,
                              vx_err *err);

#endif
