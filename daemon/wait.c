#include "wait.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "conns.h"
#include "util/fsutil.h"

struct vx_wait {
    vx_jobs *jobs;
    pthread_mutex_t lock;
    pthread_cond_t cond; /* on CLOCK_MONOTONIC: a new waiter, or stopping */
    vx_waiter *list;
    size_t n, max; /* held now, at most */
    pthread_t timer;
    int timer_started;
    int stopping;
};

/* Takes wt off the list (if there) and resumes its connection; w->lock held. */
static void resume_locked(vx_wait *w, vx_waiter *wt)
{
    vx_waiter **pp = &w->list;
    while (*pp && *pp != wt)
        pp = &(*pp)->next;
    if (*pp) {
        *pp = wt->next;
        w->n--;
    }
    wt->waiting = 0;
    wt->resumed = 1;
    MHD_resume_connection(wt->conn);
}

/* 1 when the job of a by_progress waiter has reached its progress (or is
 * gone); w->lock held (the order is w->lock, then the registry's). */
static int progress_reached(vx_wait *w, const vx_waiter *wt)
{
    vx_err err;
    cJSON *doc = vx_jobs_get(w->jobs, wt->jid, NULL, &err);
    double p = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(doc, "progress"));
    cJSON_Delete(doc);
    return !doc || p >= wt->wake_progress;
}

/* Resumes waiters whose deadline has passed (or whose progress is reached);
 * sleeps until the next one (at most 250 ms, 100 ms with a by_progress
 * waiter) or a change of the list. */
static void *timer_main(void *arg)
{
    vx_wait *w = arg;
    pthread_mutex_lock(&w->lock);
    while (!w->stopping) {
        double now = vx_mono(), next = now + 0.25;
        for (vx_waiter *wt = w->list, *nx; wt; wt = nx) {
            nx = wt->next;
            /* a client gone (an aborted curl) holds no slot of --max-waits
             * until the deadline: answered now, to no one */
            if (wt->deadline <= now || (wt->by_progress && progress_reached(w, wt)) ||
                vx_conns_peer_gone(wt->conn)) {
                resume_locked(w, wt);
                continue;
            }
            if (wt->deadline < next) next = wt->deadline;
            if (wt->by_progress && now + 0.1 < next) next = now + 0.1;
        }
        struct timespec ts;
        vx_mono_deadline(next - now, &ts);
        pthread_cond_timedwait(&w->cond, &w->lock, &ts);
    }
    pthread_mutex_unlock(&w->lock);
    return NULL;
}

vx_wait *vx_wait_start(vx_jobs *jobs, size_t max_holds)
{
    vx_wait *w = calloc(1, sizeof *w);
    if (!w) return NULL;
    w->jobs = jobs;
    w->max = max_holds;
    pthread_mutex_init(&w->lock, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&w->cond, &ca);
    pthread_condattr_destroy(&ca);
    /* Without the timer, held requests are still answered when their job
     * finishes or at shutdown. */
    if (pthread_create(&w->timer, NULL, timer_main, w) == 0) w->timer_started = 1;
    return w;
}

int vx_wait_hold(vx_wait *w, vx_waiter *wt, struct MHD_Connection *c, const char *jid,
                 double wait_s)
{
    /* The job's state is read under the lock: a job that finishes after
     * this check resumes the waiter through vx_wait_job_changed. */
    pthread_mutex_lock(&w->lock);
    int terminal = 0;
    vx_err err;
    cJSON *doc = vx_jobs_get(w->jobs, jid, &terminal, &err);
    double progress = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(doc, "progress"));
    cJSON_Delete(doc);
    if (!doc || terminal || w->stopping || (wt->by_progress && progress >= wt->wake_progress)) {
        pthread_mutex_unlock(&w->lock);
        return 0;
    }
    if (w->n >= w->max) {
        pthread_mutex_unlock(&w->lock);
        return -1;
    }
    w->n++;
    wt->conn = c;
    snprintf(wt->jid, sizeof wt->jid, "%s", jid);
    wt->deadline = vx_mono() + wait_s;
    MHD_suspend_connection(c);
    wt->waiting = 1;
    wt->next = w->list;
    w->list = wt;
    pthread_cond_signal(&w->cond);
    pthread_mutex_unlock(&w->lock);
    return 1;
}

void vx_wait_job_changed(vx_wait *w, const char *jid)
{
    pthread_mutex_lock(&w->lock);
    for (vx_waiter *wt = w->list, *next; wt; wt = next) {
        next = wt->next;
        if (!strcmp(wt->jid, jid)) resume_locked(w, wt);
    }
    pthread_mutex_unlock(&w->lock);
}

int vx_waiter_resumed(vx_waiter *wt)
{
    if (!wt->resumed) return 0;
    wt->resumed = 0;
    return 1;
}

void vx_wait_forget(vx_wait *w, vx_waiter *wt)
{
    if (!wt->waiting) return;
    pthread_mutex_lock(&w->lock);
    vx_waiter **pp = &w->list;
    while (*pp && *pp != wt)
        pp = &(*pp)->next;
    if (*pp) {
        *pp = wt->next;
        w->n--;
    }
    pthread_mutex_unlock(&w->lock);
}

void vx_wait_quiesce(vx_wait *w)
{
    pthread_mutex_lock(&w->lock);
    w->stopping = 1;
    while (w->list)
        resume_locked(w, w->list);
    pthread_cond_broadcast(&w->cond);
    pthread_mutex_unlock(&w->lock);
}

void vx_wait_free(vx_wait *w)
{
    if (!w) return;
    vx_wait_quiesce(w);
    if (w->timer_started) pthread_join(w->timer, NULL);
    pthread_mutex_destroy(&w->lock);
    pthread_cond_destroy(&w->cond);
    free(w);
}
