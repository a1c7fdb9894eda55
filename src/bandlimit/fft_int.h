/* FFTW plumbing shared by lowpass.c and interp.c (not part of the API).
 * FFTW's planner is not thread-safe: every plan is made and destroyed
 * under one lock; executing distinct plans (or one plan on new arrays of
 * the same alignment) is. No wisdom files: plans use FFTW_ESTIMATE, which
 * needs none (the daemon gives kinds no cache directory). */
#ifndef VX_BANDLIMIT_FFT_INT_H
#define VX_BANDLIMIT_FFT_INT_H

#include <fftw3.h>
#include <time.h>

void vx_bl_plan_lock(int nthreads);
void vx_bl_plan_unlock(void);
void vx_bl_destroy_plan(fftwf_plan p);

static inline double vx_bl_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

/* FFT-order index j of an n-point transform -> signed frequency. */
static inline int vx_bl_freq(int j, int n)
{
    return j < n / 2 ? j : j - n;
}

#endif
