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
/* *ts = the CLOCK_MONOTONIC time s seconds from now (s >= 0), for
 * pthread_cond_timedwait on a condition variable set to that clock. */
struct timespec;
void vx_mono_deadline(double s, struct timespec *ts);

#endif
