/* The `preview` job kind: a shaded PNG of the mesh (orbit camera around the
 * bbox centre, Lambert + ambient). It exists so the whole path queue -> GL
 * thread -> encoder -> result is real before the engines arrive. */
#ifndef VX_PREVIEW_H
#define VX_PREVIEW_H

#include <stdint.h>

#include "gl/gl.h"
#include "jobs/kind.h"
#include "mesh/mesh.h"

typedef struct vx_preview_params {
    double azimuth_deg;   /* around +Y (up), 0 = looking along -Z from +Z */
    double elevation_deg; /* above the XZ plane, -89..89 */
    int width, height;
    double fov_deg; /* vertical field of view; 0 = orthographic */
    float color[3], background[4], ambient;
    int samples; /* MSAA samples, 1 = none */
    /* Optional: called between the pieces the render is cut into (bands
     * of rows, draws of at most VX_PREVIEW_CHUNK_TRIS triangles) with the
     * fraction done; returning -1 (err filled) stops the render, which
     * then fails with that err and leaves the GL state clean. */
    int (*poll)(void *ud, double fraction, vx_err *err);
    void *poll_ud;
    int band_rows; /* rows per band; 0 = from VX_PREVIEW_BAND_SAMPLES */
} vx_preview_params;

typedef struct vx_preview_stats {
    double gpu_ms; /* draw + resolve, GPU timer */
    double upload_ms;
    uint64_t pixels_covered;
    int samples; /* MSAA samples used (p->samples clamped to GL_MAX_SAMPLES) */
} vx_preview_stats;

/* Framing: the mesh is scaled so that its bounding sphere (centred on the
 * bbox centre) has radius 1. Orthographic views show exactly that sphere
 * across the smaller image dimension; perspective views place the camera
 * so a sphere VX_PREVIEW_MARGIN times larger just fits. */
#define VX_PREVIEW_MARGIN 1.05
/* The narrowest perspective field of view drawn (degrees): a smaller fov
 * (but not 0) is drawn as this one. The eye is then 1.2e8 radii away, so
 * the perspective differs from any narrower one's by under a float's
 * precision: the same picture (the framing fits the sphere whatever the
 * fov). Below about 1e-13 the projection itself lost the mesh in float
 * (an empty picture), and 1e-300 made it infinite. */
#define VX_PREVIEW_MIN_FOV 1e-6
/* Direction towards the key light in view space (unnormalised): from the
 * camera, slightly up and to the left. */
#define VX_PREVIEW_LIGHT_X (-0.25)
#define VX_PREVIEW_LIGHT_Y 0.35
#define VX_PREVIEW_LIGHT_Z 1.0

/* The render is cut so that each piece is a small fraction of a job's time
 * limit on a CPU rasteriser: bands of about this many samples (pixels x
 * MSAA samples: ~0.1 s on a loaded llvmpipe), each drawn in draws of at
 * most CHUNK_TRIS triangles, starting at CHUNK_MIN and sized by how long
 * the draws take (about 50 ms each). */
#define VX_PREVIEW_BAND_SAMPLES (4 << 20)
#define VX_PREVIEW_CHUNK_TRIS (1 << 20)
#define VX_PREVIEW_CHUNK_MIN (1 << 14)

/* Renders into rgba (width*height*4 bytes, top row first). GL thread. */
int vx_preview_render(vx_gl *gl, const vx_mesh *m, const vx_preview_params *p, uint8_t *rgba,
                      vx_preview_stats *st, vx_err *err);

extern const vx_kind vx_kind_preview;

#endif
