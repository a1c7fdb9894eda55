/* The one parallel-for (par.h). */
#include "util/par.h"

#include <pthread.h>
#include <stdatomic.h>
#include <unistd.h>

int vx_par_run(int nthreads, void *(*worker)(void *ud), void *ud)
{
    int nt = nthreads < 1 ? 1 : nthreads > VX_PAR_MAX ? VX_PAR_MAX : nthreads;
    pthread_t th[VX_PAR_MAX];
    int started = 0;
    for (int i = 1; i < nt; i++)
        if (pthread_create(&th[started], NULL, worker, ud) == 0) started++;
    worker(ud);
    for (int i = 0; i < started; i++)
        pthread_join(th[i], NULL);
    return started + 1;
}

typedef struct par_for {
    int n;
    int (*fn)(int i, int t, void *ud);
    void *ud;
    atomic_int next;    /* the next item to hand out */
    pthread_t caller;   /* thread index 0 */
    atomic_int threads; /* indices handed out to the new threads */
    atomic_int rc;      /* first nonzero fn result */
} par_for;

static void *par_for_worker(void *arg)
{
    par_for *p = arg;
    int t = pthread_equal(pthread_self(), p->caller) ? 0 : 1 + atomic_fetch_add(&p->threads, 1);
    while (atomic_load(&p->rc) == 0) {
        int i = atomic_fetch_add(&p->next, 1);
        if (i >= p->n) break;
        int rc = p->fn(i, t, p->ud);
        int zero = 0;
        if (rc) atomic_compare_exchange_strong(&p->rc, &zero, rc);
    }
    return NULL;
}

int vx_par_for(int n, int nthreads, int (*fn)(int i, int t, void *ud), void *ud)
{
    par_for p = {.n = n, .fn = fn, .ud = ud, .caller = pthread_self()};
    atomic_init(&p.next, 0);
    atomic_init(&p.threads, 0);
    atomic_init(&p.rc, 0);
    vx_par_run(nthreads, par_for_worker, &p);
    return atomic_load(&p.rc);
}

int vx_par_cpus(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : n > VX_PAR_MAX ? VX_PAR_MAX : (int)n;
}
