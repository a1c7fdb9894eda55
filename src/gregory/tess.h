/* Tessellation of Gregory patch sets: the output layout (divisions per
 * patch, welding by corner keys and boundary curves, triangles) on the CPU, and the one-pass
 * GPU evaluation of every grid vertex (seed 001 §3: each vertex of an N x N
 * division is independent, so a compute shader evaluates them all at once).
 *
 * Patch p is evaluated on an (N_p + 1)^2 grid, vertex (i, j) at
 * (u, v) = (i / N_p, j / N_p), stored at grid index voff[p] + j (N_p + 1) + i.
 * Every patch edge gets the most divisions of the patches on it, N_e. A
 * patch whose edges all have N_e = N_p is triangulated as its grid; one
 * with a finer edge (a transition patch, N_p >= 2) as its inner grid
 * (1..N_p-1) plus a zipper strip from the inner ring to its outer loop,
 * whose points on a finer edge are the finer neighbour's grid vertices (the
 * same boundary curve): shared edges match exactly, no cracks, no
 * T-junctions.
 * The layout depends only on the topology (corner keys, which boundary
 * curves are one: from the first frame's control points) and the divisions,
 * so deformation frames reuse it. */
#ifndef VX_GREGORY_TESS_H
#define VX_GREGORY_TESS_H

#include <stddef.h>
#include <stdint.h>

#include "gl/gl.h"
#include "gregory/gregory.h"

#define VX_GREGORY_MAX_DIVISIONS 256

typedef struct vx_gtess_layout {
    size_t npatches;
    uint32_t *ndiv; /* per patch */
    uint64_t *voff; /* npatches + 1: first grid vertex of each patch */
    int weld;
    size_t nverts;   /* output vertices */
    uint64_t *rep;   /* nverts: the grid vertex an output vertex is taken from
                        (another patch's on a transition edge) */
    uint64_t *share; /* unwelded only (else NULL), nverts: the one grid vertex
                        that gives a point several patches share (UINT64_MAX:
                        a patch interior point) */
    size_t ntris;
    uint32_t *tri;       /* 3 * ntris output vertex ids, counter-clockwise seen from the normal */
    uint32_t *tri_patch; /* ntris: the patch of each triangle */
} vx_gtess_layout;

/* Divisions per patch: n for every patch (max_edge <= 0), or, for
 * max_edge > 0, each patch's own N: the one that brings every boundary
 * control polygon of the patch under max_edge per segment, clamped to
 * 1..256, raised to at least half (rounded up) of each neighbour's N
 * (graded: no zipper strip fans out to a much finer edge), and at least 2
 * where a patch of its connected component (patches joined by shared
 * edges) has more (a transition patch needs an interior).
 * Owned array of npatches; NULL on allocation failure. Any thread. */
uint32_t *vx_gregory_divisions(const vx_gpatch_set *s, int n, double max_edge, vx_err *err);

/* Counts for a given division array: grid vertices, and the output
 * vertices and triangles an unwelded tessellation makes (welding only
 * lowers the vertex count, collapsed edges the triangle count). For limit
 * checks before the layout is built. -1 with err on allocation failure
 * (or the stop hook's, util/stop.h). */
int vx_gregory_count(const vx_gpatch_set *s, const uint32_t *ndiv, uint64_t *grid_verts,
                     uint64_t *verts, uint64_t *tris, vx_err *err);

/* Builds the layout: welded (weld != 0: one output vertex per corner key,
 * per shared edge position and per patch interior point; triangles that
 * collapse onto a degenerate edge are dropped) or one vertex set per patch.
 * ndiv is copied. Owned; NULL with err (VX_EUNPROC gregory_divisions when a
 * patch of 1 division has a finer edge: vx_gregory_divisions never makes
 * one; the stop hook's err, util/stop.h). Any thread. */
vx_gtess_layout *vx_gregory_layout_new(const vx_gpatch_set *s, const uint32_t *ndiv, int weld,
                                       vx_err *err);
void vx_gregory_layout_free(vx_gtess_layout *l);

/* A tessellator for one layout: the GPU buffers (per-patch info, control
 * points, outputs) made once, so that deformation frames only upload their
 * control points and run the pass. Owned (free with vx_gtess_free); l must
 * outlive it. NULL with err (also the stop hook's, util/stop.h). GL thread.
 * Engines: the GPU pass, or the same formulas on the CPU threads
 * (tess_cpu.c: no GL objects, the grid written in place); AUTO (what
 * vx_gtess_new and vx_gregory_tessellate take) runs the CPU where the
 * renderer is a CPU rasterizer (vx_gl_info_software) or gl is NULL. */
typedef struct vx_gtess vx_gtess;
typedef enum vx_gtess_engine { VX_GTESS_AUTO = 0, VX_GTESS_GPU, VX_GTESS_CPU } vx_gtess_engine;
vx_gtess *vx_gtess_new(vx_gl *gl, const vx_gtess_layout *l, vx_err *err);
vx_gtess *vx_gtess_new_on(vx_gl *gl, const vx_gtess_layout *l, vx_gtess_engine engine, vx_err *err);
/* "gpu" or "cpu": the engine t runs. */
const char *vx_gtess_engine_name(const vx_gtess *t);
void vx_gtess_free(vx_gtess *t);
/* One pass over s (the layout's patch count), as vx_gregory_tessellate;
 * between chunks (about 10^6 grid vertices each; cpu: 64 patches) it waits
 * for the GPU and polls the thread's stop hook (util/stop.h): -1 with its
 * err. *gpu_ms: the pass (cpu: its wall time). GL thread. */
int vx_gtess_run(vx_gtess *t, const vx_gpatch_set *s, const double origin[3], float *grid,
                 double *gpu_ms, vx_err *err);

/* Evaluates every grid vertex of the layout on the GPU: grid gets 6 floats
 * per grid vertex (position - origin, unit normal), voff[npatches] of them.
 * One compute pass over all patches (one invocation per grid row, 2-D
 * dispatch of at most 65535 groups per dimension; chunks of at most 65535
 * patches and of output buffers under the SSBO limit), one read-back. *gpu_ms = time of the pass
 * (wall clock where the driver's timer cannot see compute), buffer set-up and read-back not
 * included. vx_gtess_new + run + free. GL thread. */
int vx_gregory_tessellate(vx_gl *gl, const vx_gpatch_set *s, const vx_gtess_layout *l,
                          const double origin[3], float *grid, double *gpu_ms, vx_err *err);

/* Output vertex positions (3 doubles, origin added back) and normals
 * (3 floats) from a grid the tessellator filled. Unwelded, every copy of a
 * point that patches share gets the position one evaluation gave, and its
 * normal too unless the patches meet at a crease there (normals over 1°
 * apart): float evaluation in each patch would part them by ~1e-3°. 0, or -1 with err when the
 * thread's stop hook (util/stop.h) says stop. Any thread. */
int vx_gregory_gather(const vx_gtess_layout *l, const float *grid, const double origin[3],
                      double *pos, float *nrm, vx_err *err);

#endif
