/* FFTW plumbing shared by lowpass.c and interp.c (not part of the API).
 * FFTW's planner is not thread-safe: every plan is made and destroyed
 * under one lock; executing distinct plans (or one plan on new arrays of
 * the same alignment) is. Plans are measured (FFTW_MEASURE, which scribbles
 * on the arrays it plans on: plan before filling them) when wisdom is kept
 * (vx_bl_wisdom_dir), else estimated. */
#ifndef VX_BANDLIMIT_FFT_INT_H
#define VX_BANDLIMIT_FFT_INT_H

#include <fftw3.h>
#include <time.h>

#include "util/clock.h"

void vx_bl_plan_lock(int nthreads);
/* Saves new wisdom, if any was made while the lock was held. */
void vx_bl_plan_unlock(void);
/* Planner flags for a job's transforms; under the plan lock. */
unsigned vx_bl_plan_flags(void);
void vx_bl_destroy_plan(fftwf_plan p);

/* FFT-order index j of an n-point transform -> signed frequency. */
static inline int vx_bl_freq(int j, int n)
{
    return j < n / 2 ? j : j - n;
}

#endif
