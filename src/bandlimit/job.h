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

extern const vx_kind vx_kind_render;

#endif
