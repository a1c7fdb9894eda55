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
    double fov_deg;       /* vertical field of view; 0 = orthographic */
    float color[3], background[4], ambient;
    int samples;          /* MSAA samples, 1 = none */
} vx_preview_params;

typedef struct vx_preview_stats {
    double gpu_ms;          /* draw + resolve, GPU timer */
    double upload_ms;
    uint64_t pixels_covered;
} vx_preview_stats;

/* Renders into rgba (width*height*4 bytes, top row first). GL thread. */
int vx_preview_render(vx_gl *gl, const vx_mesh *m, const vx_preview_params *p, uint8_t *rgba,
                      vx_preview_stats *st, vx_err *err);

extern const vx_kind vx_kind_preview;

#endif
