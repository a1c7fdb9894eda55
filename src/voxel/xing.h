/* Brick-exact crossings for the GPU methods (peel, scan, slice): the GL
 * side of shaders/voxel_xing.glsl.
 *
 * A brick of a lattice (vx_grid.index) must give the same voxels as the
 * whole grid, bit for bit (issue 14). The GPU methods get there by three
 * rules, each kept here or in the shader:
 *   1. the rasterizer's positions are uploaded as vx_grid_unit gives them:
 *      the lattice's units snapped to 1/VX_GRID_SNAP voxel, less the
 *      brick's integer index, so they are exact floats (within 2^15 voxels
 *      of the brick);
 *   2. window coordinates are those positions times powers of two
 *      (vx_xing_viewport: power-of-two viewports, the image bounded by
 *      the framebuffer or a scissor), so the rasterizer's fixed-point
 *      coverage test sees a brick as an integer translate of the whole
 *      grid and covers the same pixel centres; and the viewport holds
 *      every vertex drawn, so nothing is clipped: a clipped triangle's new
 *      corners are snapped again, and its edges can then cover other
 *      pixel centres (on llvmpipe a slab's rows differed from the whole
 *      grid's where the viewport ended at the slab);
 *   3. the fragment shader computes where the ray crosses the triangle
 *      (xing() in the shader) in double from the lattice's own unsnapped
 *      units (p - origin) / h, the same numbers for every brick, and the
 *      lattice index of the pixel's centre, and snaps it to 1/VX_GRID_XING_SNAP
 *      voxel (so a face on a plane of centres is the same half-open tie
 *      on every lattice, as rule 1 makes it across the ray); only the
 *      last step subtracts the brick's index. Never from a varying the
 *      rasterizer interpolated from where the triangle sits in the window.
 * The fragment shader reads the lattice positions (3 doubles a vertex) and
 * the triangles drawn (the element buffer) as texture buffers on units 6
 * and 7, and the brick's index from u_xing_index. */
#ifndef VX_XING_H
#define VX_XING_H

#include <stddef.h>
#include <stdint.h>

#include "gl/gl.h"
#include "mesh/mesh.h"
#include "util/err.h"
#include "voxel/voxel.h"

typedef struct vx_xing {
    GLuint pos_buf;          /* the lattice positions, 3 doubles a vertex */
    GLuint pos_tex, tri_tex; /* texture buffers over pos_buf and the element buffer */
    GLuint tri_buf;          /* the element buffer tri_tex shows now */
    double index[3];         /* the brick's lattice index */
} vx_xing;

/* Uploads m's lattice positions for grid g and creates x's texture
 * buffers. VX_ETOOBIG mesh_too_large when the mesh has more vertices or
 * triangles than a texture buffer may hold (GL_MAX_TEXTURE_BUFFER_SIZE),
 * VX_EINTERNAL out_of_memory. */
int vx_xing_init(vx_xing *x, vx_gl *gl, const vx_mesh *m, const vx_grid *g, vx_err *err);
/* Bytes of GPU memory vx_xing_init takes for m. */
uint64_t vx_xing_bytes(const vx_mesh *m);
/* Binds units 6 and 7 for draws of program prog from element buffer ibo,
 * and sets prog's u_xing_index. */
void vx_xing_bind(vx_xing *x, GLuint prog, GLuint ibo);
/* Unbinds units 6 and 7. */
void vx_xing_unbind(void);
/* Deletes x's objects (names of 0 are ignored) and zeroes it. */
void vx_xing_free(vx_xing *x);
/* Draws triangles [first, first + n) of the bound element buffer with
 * program prog (in use), telling xing() where each draw starts. */
void vx_xing_draw(GLuint prog, size_t first, size_t n);
/* The least power of two >= n (n >= 1): viewport sizes whose NDC scale
 * 2 / size is exact. */
int vx_xing_pow2(int n);
/* Sets the viewport for an image of w x h pixels whose window coordinates
 * are (p - off) * ss for p a rasterizer position (grid units) along each
 * window axis, and writes the vertex shader's mapping: NDC = p * ndc[0] +
 * ndc[1] across, p * ndc[2] + ndc[3] up. The viewport holds the image and
 * the vertices' positions lo..hi along each axis when the GPU's viewport
 * limits allow, else the image alone; its sizes are powers of two. */
void vx_xing_viewport(int w, int h, const int off[2], int ss, const double lo[2],
                      const double hi[2], float ndc[4]);

#endif
