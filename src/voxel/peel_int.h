/* Internals of the depth-peeling engine (src/voxel/peel.c) that the
 * crossing-count voxelizer (src/voxel/scan.c) shares: the context, the GL
 * objects, the upload of the mesh in grid units (normalised in double),
 * slab buckets, progress, memory errors and timers. Not a public API. */
#ifndef VX_PEEL_INT_H
#define VX_PEEL_INT_H

#include <stddef.h>
#include <stdint.h>

#include "gl/gl.h"
#include "voxel/voxel.h"
#include "voxel/xing.h"

/* A peel image: the pass target and the layer arrays. */
typedef struct layer_set {
    GLuint fbo;          /* attachment-less w x h target of the passes */
    GLuint keys, counts; /* R32UI arrays of cap layers: sorted crossing keys, multiplicities */
    int w, h, cap;
    int shift;   /* a key's ib (voxel_peel.frag) = key >> shift */
    int counted; /* counts hold multiplicities (coincident crossings were seen) */
} layer_set;

/* Every GL object one call creates, so every exit path deletes the same set
 * (names of 0 are ignored by glDelete*). */
typedef struct peel_objs {
    GLuint vbo, ibo, vao;
    layer_set ls[2]; /* x and y rays; z rays (robust: peeled once, filled per slab) */
    GLuint ssbo[3];
    GLuint list;     /* surface: the triangles the GPU takes */
    GLuint ibo_slab; /* several slabs: triangles grouped by the slabs they reach */
    GLuint query;
    GLuint peel_stat;   /* peel: [0] coincident crossings seen, [1] most layers of a pixel */
    GLuint scan_fbo;    /* scan: the attachment-less framebuffer */
    GLuint scan_buf[4]; /* scan: delta counters, row tails, overflow flag, block bits */
    vx_xing xing;       /* the triangles as the fragment shaders read them */
} peel_objs;

typedef struct peel_ctx {
    vx_gl *gl;
    const vx_mesh *m;
    const vx_voxelize_desc *d;
    vx_voxelize_stats *st;
    vx_err *err;
    vx_bitgrid *out;
    GLuint prog_peel, prog_fill, prog_major, prog_surf, prog_scan, prog_sum;
    int dims[3], max_layers, rows, nslabs, naxes;
    size_t wx;
    double tlo[3], thi[3]; /* mesh bbox in grid units */
    uint64_t fixed_bytes;  /* everything but the layer arrays */
    uint64_t first_layers; /* the layer arrays as first allocated */
    uint64_t layers_now;   /* the layer arrays as allocated now */
    uint64_t limit;        /* max_memory, or UINT64_MAX */
    peel_objs o;
    int slab, axis_i;   /* for progress */
    double pass_ms_ray; /* slowest peel pass so far, ms per ray (0: none yet) */
    size_t ncpu_tris;
    uint32_t *cpu_tris; /* surface: triangles too large for one invocation */
    size_t *slab_first; /* with o.ibo_slab: first triangle of each slab, nslabs + 1 */
} peel_ctx;

/* Deletes every GL object in o (names of 0 are ignored) and zeroes it. */
void vx_peel_objs_free(peel_objs *o);
/* VX_ETOOBIG job_memory_limit: `need` bytes against c->limit. */
int vx_peel_too_big(peel_ctx *c, uint64_t need);
/* Progress of slab c->slab, axis c->axis_i of c->naxes, `within_slab`
 * 0..1 through it; nonzero when the caller's hook stops the job. */
int vx_peel_progress(peel_ctx *c, double within_slab);
/* Ends a timer around compute work (llvmpipe: wall clock, see peel.c). */
double vx_peel_timer_end_compute(vx_gl_timer *t);
/* Dispatches ceil(invocations / 64) groups of 64 over x and y. */
void vx_peel_dispatch_2d(uint64_t invocations);
/* Uploads the mesh in grid units (vx_grid_unit) into o.vbo / o.ibo /
 * o.vao and o.xing and sets c->tlo, c->thi; also creates o.query. */
int vx_peel_upload(peel_ctx *c);
/* Binds the element buffer of the slab's draw (o.ibo_slab when the
 * triangles were bucketed by slab and `bucketed`, else o.ibo) to the VAO
 * and to o.xing, and draws its triangles with program prog (in use). */
void vx_peel_draw_slab(peel_ctx *c, GLuint prog, int bucketed);
/* With c->nslabs > 1: o.ibo_slab and c->slab_first, the triangles grouped
 * by the z slabs of c->rows rows they reach (skipped when they would not
 * fit c->limit; needs c->fixed_bytes and c->first_layers). */
int vx_peel_slab_buckets(peel_ctx *c);
/* Bytes of one slab of `rows` z rows of bits. */
uint64_t vx_peel_slab_bytes(const peel_ctx *c, int rows);

/* Checks the grid and the mesh's indices before anything reaches the GPU
 * (a bad index would make it read outside the vertex buffer). */
int vx_peel_check_input(const vx_mesh *m, const vx_voxelize_desc *d, vx_err *err);

/* Resets the raster state other code may have left behind: no culling
 * (both faces are crossings), no blending, scissor, stencil, offset or
 * multisampling; filled polygons, counter-clockwise front faces. */
void vx_peel_raster_state(void);

#endif
