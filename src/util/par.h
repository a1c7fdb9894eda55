/* The one parallel-for: fork/join over a few threads for the CPU engines
 * (FFTs, ray casting). Threads made here have the default stop hook
 * (util/stop.h: always go on): only the calling thread polls the job's. */
#ifndef VX_PAR_H
#define VX_PAR_H

#define VX_PAR_MAX 16 /* threads at most, the caller's included */

/* Runs worker(ud) on n threads, n = nthreads clamped to 1..VX_PAR_MAX: the
 * calling thread and n - 1 new ones (fewer when one cannot be made), then
 * joins them. Returns the number of threads that ran it. */
int vx_par_run(int nthreads, void *(*worker)(void *ud), void *ud);

/* Runs fn(i, t, ud) for each i in 0..n-1 on vx_par_run's threads, items
 * handed out in increasing order to whichever thread is free; t is the
 * thread's index, 0 for the calling thread. When fn returns nonzero, no
 * further item is started. Returns 0, or the first nonzero value fn gave. */
int vx_par_for(int n, int nthreads, int (*fn)(int i, int t, void *ud), void *ud);

/* The CPUs online, clamped to 1..VX_PAR_MAX: the CPU engines' thread count. */
int vx_par_cpus(void);

#endif
