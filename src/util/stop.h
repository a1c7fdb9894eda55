/* A stop hook for long loops in engines whose calls carry no progress
 * callback (the Gregory layout, the GPU tessellation): a job stage sets it
 * on its thread around the work, the loops call vx_stop_poll every so often
 * (each call reads the clock; the hook runs at most every
 * VX_STOP_INTERVAL_S), and a stop unwinds as an ordinary error. */
#ifndef VX_STOP_H
#define VX_STOP_H

#include "util/err.h"

#define VX_STOP_INTERVAL_S 0.01

/* Returns 0 to go on, or -1 with err filled to stop. */
typedef int (*vx_stop_fn)(void *ud, vx_err *err);

/* Sets the calling thread's hook (fn NULL clears it). */
void vx_stop_set(vx_stop_fn fn, void *ud);
/* 0, or -1 with err when the calling thread's hook says stop (and on every
 * later call until the hook is cleared). No hook: always 0. */
int vx_stop_poll(vx_err *err);

#endif
