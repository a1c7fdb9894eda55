/* Private to the tessellator (tess.c, tess_cpu.c): a patch as both
 * engines read it, and the CPU engine. */
#ifndef VX_GREGORY_TESS_INT_H
#define VX_GREGORY_TESS_INT_H

#include "gregory/tess.h"

/* Floats per patch: the 20 points relative to the first (float derivatives
 * without the cancellation of large coordinates), the first relative to
 * the output origin, a pad. */
#define VX_GTESS_CP_FLOATS 64

/* Patch p of s as VX_GTESS_CP_FLOATS floats into f. */
void vx_gtess_pack(const vx_gpatch_set *s, size_t p, const double origin[3], float *f);

/* Every grid vertex of l on the CPU threads (tess_cpu.c): the shader's
 * formulas, the same grid layout, `lanes` vertices of a row at once (4:
 * SSE; 8: AVX2 with FMA, where the CPU has them; 0: the widest it has).
 * *ms = the pass's wall time. 0, or -1 with err when the calling thread's
 * stop hook says stop. */
int vx_gtess_cpu_run(const vx_gtess_layout *l, const vx_gpatch_set *s, const double origin[3],
                     float *grid, int lanes, double *ms, vx_err *err);

#endif
