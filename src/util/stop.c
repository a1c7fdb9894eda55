/* The per-thread stop hook (stop.h). */
#include "util/stop.h"

#include "util/fsutil.h"

typedef struct hook {
    vx_stop_fn fn;
    void *ud;
    double next; /* vx_mono() of the next call of fn */
    int stopped;
    vx_err err;
} hook;

static _Thread_local hook g_hook;

void vx_stop_set(vx_stop_fn fn, void *ud)
{
    g_hook.fn = fn;
    g_hook.ud = ud;
    g_hook.next = 0;
    g_hook.stopped = 0;
}

int vx_stop_poll(vx_err *err)
{
    hook *h = &g_hook;
    if (!h->fn) return 0;
    if (!h->stopped) {
        double now = vx_mono();
        if (now < h->next) return 0;
        h->next = now + VX_STOP_INTERVAL_S;
        if (h->fn(h->ud, &h->err) == 0) return 0;
        h->stopped = 1;
    }
    if (err) *err = h->err;
    return -1;
}
