/* ?wait: requests held until their job finishes or their wait runs out.
 *
 * A held request's connection is suspended (libmicrohttpd) and sits in one
 * list; it is resumed by the job hook (vx_wait_job_changed, any thread) when
 * its job finishes, by a timer thread when its deadline passes, or by
 * vx_wait_quiesce at shutdown. The access handler is then called again and
 * answers as it would have without waiting (vx_waiter_resumed). A waiter
 * with by_progress set (?progress=) is also resumed once its job's progress
 * reaches wake_progress: the timer reads those jobs every 100 ms. At most
 * max_holds requests are held at once (each holds a connection). All list
 * changes are under one lock. */
#ifndef VX_WAIT_H
#define VX_WAIT_H

#include <microhttpd.h>

#include "jobs/jobs.h"

typedef struct vx_wait vx_wait;

/* One held request, embedded in the request (zeroed with it). */
typedef struct vx_waiter {
    struct MHD_Connection *conn;
    char jid[33];
    double deadline; /* monotonic */
    int waiting;     /* suspended, not yet resumed */
    int resumed;     /* resumed, the handler has not answered yet */
    int by_progress; /* set before vx_wait_hold: also wake at wake_progress */
    double wake_progress;
    struct vx_waiter *next;
} vx_waiter;

/* Starts the timer thread; jobs is asked whether a job has finished; at
 * most max_holds requests are held at once. Owned; free with
 * vx_wait_free. NULL without memory. */
vx_wait *vx_wait_start(vx_jobs *jobs, size_t max_holds);
/* Suspends c and holds it in w until job jid finishes or wait_s passes (or
 * its progress reaches wt->wake_progress, with wt->by_progress).
 * Returns 1 when held, 0 when jid is unknown or finished (or far enough
 * along) or the daemon is stopping (answer now), -1 when max_holds
 * requests are held already (not held). */
int vx_wait_hold(vx_wait *w, vx_waiter *wt, struct MHD_Connection *c, const char *jid,
                 double wait_s);
/* Resumes every request held on jid (the job hook: jid has finished). */
void vx_wait_job_changed(vx_wait *w, const char *jid);
/* 1 once, when wt was held and has been resumed since: answer it now. */
int vx_waiter_resumed(vx_waiter *wt);
/* Forgets wt if it is still held (its connection closed while waiting). */
void vx_wait_forget(vx_wait *w, vx_waiter *wt);
/* Resumes every held request and holds no more (shutdown). */
void vx_wait_quiesce(vx_wait *w);
/* Stops the timer thread (after vx_wait_quiesce) and frees w. */
void vx_wait_free(vx_wait *w);

#endif
