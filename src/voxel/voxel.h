/* Solid voxelization (issue #3): a mesh -> a bit grid, on the GL thread.
 *
 * Grid convention: voxel (i,j,k) covers origin + [i,i+1) x [j,j+1) x [k,k+1)
 * times h and is inside when its centre origin + (i+0.5, j+0.5, k+0.5) h is.
 * The result is bit-packed with x fastest: bit (i,j,k) is bit i % 32 (least
 * significant first) of word (k * ny + j) * wx + i / 32, wx = ceil(nx / 32).
 * That is also the layout of the `raw1` output, row padding aside.
 *
 * Methods: `peel` (seed 000, depth peeling along x, entry/exit pairing on
 * the GPU), `slice` (seed 003, a near plane stepped through the slices),
 * `scan` (one draw per slab counting signed crossings into per-voxel
 * counters, then a prefix sum along x; no peeling), `cpu` (scan's
 * crossing counts on the CPU threads, no GL), `auto` (the fastest correct
 * one for the request and the renderer). */
#ifndef VX_VOXEL_H
#define VX_VOXEL_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "gl/gl.h"
#include "mesh/mesh.h"
#include "util/err.h"

typedef struct vx_grid {
    double origin[3];
    double h; /* voxel edge */
    int dims[3];
    /* Lattice index of voxel (0,0,0) (a brick of a larger grid; 0 = the
     * grid is the lattice's own): voxel (i,j,k)'s centre is origin +
     * (index + (i,j,k) + 1/2) h, whatever brick it falls in. */
    int64_t index[3];
} vx_grid;

/* The most |index| along an axis (exact in double with room to spare). */
#define VX_GRID_INDEX_MAX ((int64_t)1 << 40)

/* Position p along axis a in the grid's frame, in double: voxel (0,0,0)
 * spans [0,1), so centres sit at integers + 1/2. (p - origin) / h is the
 * same number for every brick of one lattice; the integer index then
 * shifts it exactly. */
static inline double vx_grid_coord(const vx_grid *g, int a, double p)
{
    return (p - g->origin[a]) / g->h - (double)g->index[a];
}

/* Steps per voxel the GPU methods snap positions to: what GPU rasterizers
 * snap window coordinates to anyway (8 subpixel bits). */
#define VX_GRID_SNAP 256.0

/* Steps per voxel every engine snaps a crossing along its ray to (2^20):
 * far below any real geometry, far above the rounding of (p - origin) / h,
 * so a face on a plane of centres (0.15 on origin -0.2, h 0.1) is exactly
 * on it, a tie decided half-open, on any lattice. */
#define VX_GRID_XING_SNAP 1048576.0

/* Position p along axis a as the GPU methods upload it (xing.h): the
 * lattice's units (p - origin) / h snapped to 1/VX_GRID_SNAP, the same
 * number for every brick, less the brick's integer index. Exact as a float
 * within 2^16 voxels of the brick, so every brick of a lattice sees the
 * same triangles shifted by exact integers. */
static inline float vx_grid_unit(const vx_grid *g, int a, double p)
{
    double u = nearbyint((p - g->origin[a]) / g->h * VX_GRID_SNAP) / VX_GRID_SNAP;
    return (float)(u - (double)g->index[a]);
}

typedef enum vx_method {
    VX_METHOD_AUTO = 0,
    VX_METHOD_PEEL,
    VX_METHOD_SLICE,
    VX_METHOD_SCAN,
    VX_METHOD_CPU,
} vx_method;
typedef enum vx_inside {
    VX_INSIDE_NONZERO = 0, /* signed crossings: front face +1, back face -1; union of parts */
    VX_INSIDE_PARITY,      /* entry/exit pairing as in the seeds */
    VX_INSIDE_ROBUST,      /* for meshes with holes: majority of parity along x, y and z */
    VX_INSIDE_WINDING,     /* generalized winding number >= 1/2 (winding.c, on the CPU) */
} vx_inside;
/* The rules' names in the API, in vx_inside order, NULL-terminated. */
extern const char *const vx_inside_names[];
typedef enum vx_fill { VX_FILL_SOLID = 0, VX_FILL_SURFACE } vx_fill;
/* Where supersample 2 samples a voxel (src/voxel/faces.c for FACES). */
typedef enum vx_samples {
    VX_SAMPLES_CUBE = 0, /* seed 003: 2 x 2 pixels x 2 planes, at +-1/4 voxel; 8 samples */
    VX_SAMPLES_FACES,    /* the centre and the centres of the six faces; 7 samples */
} vx_samples;

typedef struct vx_voxelize_desc {
    vx_grid grid;
    vx_method method;
    vx_inside inside;
    vx_fill fill;
    int supersample;     /* 1 (default) or 2: several samples per voxel, see samples */
    vx_samples samples;  /* with supersample 2: the sample pattern */
    int threshold;       /* with supersample 2: samples inside (1..8, faces 1..7) to set a voxel;
                            default 4 */
    int max_layers;      /* peel: depth layers before giving up (0 = GL_MAX_ARRAY_TEXTURE_LAYERS) */
    uint64_t max_memory; /* bytes of GPU + CPU memory this job may use (0 = no limit) */
    /* Called between passes with progress 0..1; nonzero return stops the job
     * (err filled by the callee). May be NULL. */
    int (*progress)(void *ud, double fraction, vx_err *err);
    void *ud;
    /* Tests and benchmarks: at most this many z rows per GPU slab (0 = as
     * many as the GPU limits and max_memory allow). */
    int max_slab_rows;
} vx_voxelize_desc;

/* Voxels per GPU slab the job kinds allow: a slab's passes are one piece
 * of work between two progress reports (the job's time limit), ~0.1 s of
 * llvmpipe at 2^26. */
#define VX_VOXELIZE_SLAB_VOXELS ((uint64_t)1 << 26)
/* max_slab_rows for slabs of at most VX_VOXELIZE_SLAB_VOXELS of a grid
 * (at least 1 row). */
int vx_voxelize_slab_rows(const int dims[3]);

typedef struct vx_bitgrid {
    vx_grid grid;
    size_t wx;       /* 32-bit words per x row */
    uint32_t *bits;  /* wx * ny * nz words */
    uint8_t *counts; /* supersample 2: samples inside per voxel, x fastest; else NULL */
    int nsamples;    /* with counts: samples per voxel (8 cube, 7 faces) */
    size_t bits_mapped, counts_mapped; /* vx_bitgrid_alloc's: bytes mmap'd, or 0 */
} vx_bitgrid;

typedef struct vx_voxelize_stats {
    const char *method; /* "peel", "slice", "scan", "cpu" or "winding" as run */
    uint64_t voxels_inside;
    int layers;       /* peel: most depth layers of one ray (max over axes for robust); scan: 0 */
    int passes;       /* peel: geometry passes drawn, over all slabs and axes; else 0 */
    int slices;       /* slice: slices drawn */
    int chunks;       /* slabs the grid was split into to fit GPU limits */
    double upload_ms; /* CPU: normalise in double + upload */
    /* GPU timer per stage; scan: gpu_peel_ms the draw, gpu_fill_ms the sums */
    double gpu_peel_ms, gpu_fill_ms, gpu_slice_ms;
    double readback_ms;
} vx_voxelize_stats;

/* Bytes a grid of these dims needs on the CPU (bits + counts). */
uint64_t vx_bitgrid_bytes(const int dims[3], int supersample);
int vx_bitgrid_alloc(vx_bitgrid *g, const vx_grid *grid, int with_counts, vx_err *err);
void vx_bitgrid_free(vx_bitgrid *g);
static inline int vx_bitgrid_get(const vx_bitgrid *g, int i, int j, int k)
{
    size_t w = ((size_t)k * (size_t)g->grid.dims[1] + (size_t)j) * g->wx + (size_t)(i >> 5);
    return (int)((g->bits[w] >> (i & 31)) & 1u);
}
uint64_t vx_bitgrid_count(const vx_bitgrid *g);
/* The set bits of n words from w (with the POPCNT instruction where the
 * CPU has it). */
uint64_t vx_bits_count(const uint32_t *w, size_t n);

/* Grid covering the mesh bbox: `resolution` cells along the longest axis,
 * the others proportional (at least 1), plus `padding` voxels each side. */
int vx_grid_from_resolution(const vx_mesh *m, int resolution, int padding, vx_grid *out,
                            vx_err *err);
/* Grid of voxel edge h covering the bbox plus padding; VX_ETOOBIG
 * job_memory_limit past VX_GRID_MAX_DIM voxels along an axis. */
#define VX_GRID_MAX_DIM 16384
int vx_grid_from_voxel_size(const vx_mesh *m, double h, int padding, vx_grid *out, vx_err *err);

/* Voxelizes m into out (allocated here; free with vx_bitgrid_free). GL thread.
 * Validates d (VX_EUNPROC invalid_params), then auto runs slice when
 * supersample is 2 (peeling, scan and cpu have no supersampling); cpu for
 * nonzero/parity solid fills (on every renderer: the GL engines are not
 * yet right on NVIDIA, bench/RESULTS.md); else peel. st->method says which
 * ran. */
int vx_voxelize(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                vx_voxelize_stats *st, vx_err *err);
/* Depth peeling along x (src/voxel/peel.c); also runs fill=surface (GPU
 * triangle/box tests). Takes d as given (vx_voxelize validates and fills
 * defaults); supersample is ignored. Errors: VX_ETOOBIG job_memory_limit
 * (max_memory), grid_too_large (GPU limits), VX_EUNPROC too_many_layers
 * (max_layers), VX_EGPU, or the progress hook's own. */
int vx_voxelize_peel(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                     vx_voxelize_stats *st, vx_err *err);
/* Crossing counts (src/voxel/scan.c): one draw per slab, per-voxel
 * counters, prefix sums along x. Same contract and errors as peel (no
 * too_many_layers; VX_EUNPROC too_many_crossings when more than 32767 net
 * crossings of one ray fall into one voxel). robust and fill=surface run
 * vx_voxelize_peel (st->method "peel"). */
int vx_voxelize_scan(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                     vx_voxelize_stats *st, vx_err *err);
/* Scan's crossing counts on the CPU threads (src/voxel/cpu.c), no GL: the
 * same voxels as scan wherever the GPU's coverage tie rule is cpu's, and
 * brick-exact. nonzero and parity, fill solid, supersample 1 (vx_voxelize
 * refuses the rest for method cpu). Errors: VX_ETOOBIG job_memory_limit
 * (max_memory), VX_EUNPROC invalid_params (a vertex 2^50 voxels away),
 * VX_EINTERNAL out_of_memory, or the progress hook's own. Any thread;
 * progress runs on the calling one. */
int vx_voxelize_cpu(const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                    vx_voxelize_stats *st, vx_err *err);
int vx_voxelize_slice(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                      vx_voxelize_stats *st, vx_err *err);
/* supersample 2 with VX_SAMPLES_FACES (src/voxel/faces.c): the voxel
 * centres and the face centres, as four centre-sampled grids voxelized by
 * d->method (auto: cpu), counted per voxel into out->counts on the GPU
 * (shaders/voxel_faces_count.comp). d validated by vx_voxelize (fill
 * solid). st sums the four runs and the count (gpu_fill_ms, upload_ms,
 * readback_ms). */
int vx_voxelize_faces(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                      vx_voxelize_stats *st, vx_err *err);
/* inside winding (src/voxel/winding.c): the centres where the mesh's
 * generalized winding number is >= 1/2, on the CPU threads (crossings per
 * z column, winding numbers between them). d validated by vx_voxelize
 * (fill solid, supersample 1; method and max_slab_rows are ignored);
 * progress runs on the calling thread. Errors: VX_ETOOBIG
 * job_memory_limit (max_memory, the crossings counted), VX_EINTERNAL
 * out_of_memory, or the progress hook's own. st->method "winding". */
int vx_voxelize_winding(const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                        vx_voxelize_stats *st, vx_err *err);
/* The inside rule when the request names none: winding for a mesh with
 * boundary edges (vertices welded by position: a seam of split vertices
 * is not a hole) when d could run it (method auto, fill solid, no cube
 * supersampling); parity for a closed mesh whose faces disagree on their
 * orientation (misoriented edges); else nonzero. */
vx_inside vx_voxelize_default_inside(const vx_mesh *m, const vx_voxelize_desc *d);

#endif
