/* The `gregory` row of the job table (kind.h): params, the patch
 * construction, GPU tessellation of every frame, the mesh writers. */
#ifndef VX_GREGORY_JOB_H
#define VX_GREGORY_JOB_H

#include "jobs/kind.h"

/* Entries of params.frames at most (each is one output mesh). */
#define VX_GREGORY_MAX_FRAMES 256

extern const vx_kind vx_kind_gregory;

#endif
