/* The `voxelize` row of the job table (kind.h): params, memory estimate,
 * GPU run through vx_voxelize, output writers (io.h). */
#ifndef VX_VOXEL_JOB_H
#define VX_VOXEL_JOB_H

#include "jobs/kind.h"
#include "voxel/voxel.h"

/* Bounds on a grid (each axis, and in total) whatever the memory limit. */
#define VX_VOXELIZE_MAX_DIM VX_GRID_MAX_DIM
#define VX_VOXELIZE_MAX_VOXELS (2048ull * 2048ull * 2048ull)

extern const vx_kind vx_kind_voxelize;

#endif
