/* The one clock: wall time for timestamps, monotonic time for durations
 * and deadlines. Any thread. */
#ifndef VX_CLOCK_H
#define VX_CLOCK_H

/* Wall clock as seconds since the epoch (CLOCK_REALTIME). */
double vx_now(void);
/* Monotonic seconds (CLOCK_MONOTONIC): durations and deadlines. */
double vx_mono(void);
/* Monotonic milliseconds (CLOCK_MONOTONIC): the engines' stage timings. */
double vx_mono_ms(void);

#endif
