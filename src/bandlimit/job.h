/* The `render` job kind (issue #4): band-limited iso-surface renders of
 * one or more meshes (seed 002); see job.c and api/openapi.yaml
 * (RenderParams, RenderStats). */
#ifndef VX_BANDLIMIT_JOB_H
#define VX_BANDLIMIT_JOB_H

#include "jobs/kind.h"

/* Padding of the sampling box around the meshes' bbox, per side, as a
 * fraction of its longest edge: keeps the periodic low-pass's ringing from
 * wrapping onto the shape. */
#define VX_BL_PAD 0.2
#define VX_BL_MAX_MESHES 16 /* params.meshes entries */
#define VX_BL_MAX_FRAMES 360
#define VX_BL_MAX_LIGHTS 8
/* The narrowest field of view (degrees) of an orbit camera that fits its
 * distance (distance 0): a smaller fov (not 0) is taken as this one. The
 * eye is then 1.2e8 radii away and the rays' spread differs from a
 * narrower one's by under the caster's precision: the same picture. A fov
 * of 1e-20 put the eye 1e22 radii away, where the rays' entry points lost
 * the mesh (an empty picture); 1e-300 on a mesh of 1e30 put it at
 * infinity. */
#define VX_BL_MIN_FIT_FOV 1e-6

extern const vx_kind vx_kind_render;

#endif
