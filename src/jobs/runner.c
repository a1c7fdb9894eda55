/* The runner: the GL thread (the only one with the EGL context), the CPU
 * workers, the retry after a context loss, the mesh cache. jobs_int.h. */
#include "jobs/jobs_int.h"

#include <fcntl.h>
#include <malloc.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "util/fsutil.h"
#include "util/log.h"

static vx_job_run *run_new(vx_jobs *j, job *jb)
{
    vx_job_run *r = calloc(1, sizeof *r);
    if (!r) return NULL;
    r->jobs = j;
    r->job = jb;
    r->kind = jb->kind;
    /* Cluster mode: each attempt its own results (a stale one never
     * writes over the winner's). */
    if (j->cl)
        snprintf(r->rid, sizeof r->rid, "%s/%d", jb->id, jb->attempts);
    else
        snprintf(r->rid, sizeof r->rid, "%s", jb->id);
    r->t0 = vx_mono();
    r->stats = cJSON_CreateObject();
    r->outputs = cJSON_CreateObject();
    r->paths = cJSON_CreateArray();
    return r;
}

static void run_free(vx_job_run *r)
{
    if (!r) return;
    /* r->kind, not r->job->kind: once finished, the job may already have
     * left the history. */
    if (r->state && r->kind->free_state) r->kind->free_state(r->state);
    cJSON_Delete(r->stats);
    cJSON_Delete(r->outputs);
    cJSON_Delete(r->paths);
    vx_kind_params_free(r->kind, r->typed);
    int big = r->big_params;
    free(r);
    if (big) malloc_trim(0); /* as at submission */
}

/* Syncs each output file and records its size in its entry ("bytes"):
 * a result file found another size later is not served (result_damaged). */
static void sync_outputs(vx_job_run *r)
{
    cJSON *it;
    cJSON_ArrayForEach(it, r->outputs)
    {
        if (cJSON_GetObjectItemCaseSensitive(it, "rid")) continue; /* a child's, stored */
        char p[VX_PATH_MAX];
        snprintf(p, sizeof p, "%s/%s", r->dir,
                 cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "file")));
        int fd = open(p, O_RDONLY | O_CLOEXEC);
        if (fd >= 0) {
            fsync(fd);
            struct stat st;
            if (fstat(fd, &st) == 0) {
                cJSON_DeleteItemFromObjectCaseSensitive(it, "bytes");
                cJSON_AddNumberToObject(it, "bytes", (double)st.st_size);
            }
            close(fd);
        }
    }
}

/* Cluster mode's run_finish: the database hears how the attempt ended
 * (cluster_report), then the job leaves this replica's table. */
static void run_finish_cluster(vx_jobs *j, vx_job_run *r, int ok, const vx_err *e)
{
    job *jb = r->job;
    int requeue = !ok && e->kind == VX_ECANCELED && vx_err_has(e, VX_EF_SHUTDOWN);
    if (ok) sync_outputs(r);
    double run_s = vx_mono() - r->t0;
    cJSON_AddNumberToObject(r->stats, "run_ms", ms_between(0, run_s));
    char state[16];
    cluster_report(j, jb, r, ok, e, requeue, state);
    char kind[64], id[33];
    snprintf(kind, sizeof kind, "%s", jb->kind->name);
    snprintf(id, sizeof id, "%s", jb->id);
    pthread_mutex_lock(&j->lock);
    j->running--;
    int found;
    size_t at = vx_sorted_find(&j->jobs, jb->id, &found);
    if (found && job_at(j, at) == jb) vx_sorted_remove_at(&j->jobs, at);
    pinset pins = jb->pins;
    memset(&jb->pins, 0, sizeof jb->pins);
    pthread_mutex_unlock(&j->lock);
    unpin_job(j, &pins);
    int terminal = state[0] && strcmp(state, "queued") != 0;
    char qm[600];
    vx_log(!strcmp(state, "failed") ? VX_LOG_WARN : VX_LOG_INFO, "job.finished",
           "job=%s kind=%s state=%s attempt=%d run_ms=%.1f code=%s message=%s", id, kind,
           state[0] ? state : "not_ours", jb->attempts, run_s * 1e3, ok ? "-" : e->code,
           vx_log_quote(qm, sizeof qm, ok ? "-" : e->message));
    if (terminal && j->desc.hooks.finished)
        j->desc.hooks.finished(j->desc.hooks.ud, id, kind, state, run_s);
    job_free(jb);
    run_free(r);
    notify(j, id, terminal);
    cluster_wake(j);
    if (ok) vx_store_results_evict(j->desc.store);
}

/* Ends a run: success, failure, cancel, or back to the queue on shutdown. */
static void run_finish(vx_jobs *j, vx_job_run *r, int ok, const vx_err *e)
{
    if (j->cl) {
        run_finish_cluster(j, r, ok, e);
        return;
    }
    job *jb = r->job;
    /* stopped by the shutdown: back to the queue, unless canceled too */
    int requeue =
        !ok && e->kind == VX_ECANCELED && vx_err_has(e, VX_EF_SHUTDOWN) && !jb->cancel_requested;
    vx_err cerr;
    if (!ok && e->kind == VX_ECANCELED && jb->cancel_requested && vx_err_has(e, VX_EF_SHUTDOWN)) {
        vx_err_set(&cerr, VX_ECANCELED, "canceled", "the job was canceled");
        e = &cerr;
    }
    vx_err serr;
    if (ok) {
        sync_outputs(r);
        /* a job without files of its own (summary, brick parents) has no
         * result directory to sync or account. A result the blob store did
         * not take (an S3 outage) fails the job: succeeded would name a
         * result that the next start does not have. */
        if (r->dir[0] && vx_store_result_commit(j->desc.store, jb->id, &serr) != 0) {
            ok = 0;
            e = &serr;
        }
    }
    if (!ok && (r->dir[0] || requeue)) {
        vx_store_result_remove(j->desc.store, jb->id);
    }
    pthread_mutex_lock(&j->lock);
    j->running--;
    double run_s = vx_mono() - r->t0;
    if (requeue) {
        jb->state = ST_QUEUED;
        jb->progress = 0;
        jb->started = 0;
    } else {
        jb->finished = vx_now();
        if (ok) {
            jb->state = ST_SUCCEEDED;
            jb->progress = 1;
            cJSON_Delete(jb->outputs);
            jb->outputs = r->outputs;
            r->outputs = NULL;
        } else {
            jb->state = e->kind == VX_ECANCELED ? ST_CANCELED : ST_FAILED;
            jb->error = *e;
            vx_scrub_path(jb->error.message, vx_store_dir(j->desc.store));
        }
        cJSON_AddNumberToObject(r->stats, "run_ms", ms_between(0, run_s));
        cJSON_Delete(jb->stats);
        jb->stats = r->stats;
        r->stats = NULL;
    }
    vx_err jerr;
    if (journal_locked(j, jb, &jerr))
        VX_ERROR("jobs.journal_failed", "job=%s code=%s", jb->id, jerr.code);
    char kind[64], id[33];
    snprintf(kind, sizeof kind, "%s", jb->kind->name);
    snprintf(id, sizeof id, "%s", jb->id);
    job_state st = jb->state;
    char dropped[16][33];
    size_t nd = 0;
    pinset pins = {0};
    if (!requeue) {
        pins = jb->pins; /* released once the lock is dropped */
        memset(&jb->pins, 0, sizeof jb->pins);
        freeze_locked(j, jb);
        trim_history_locked(j, dropped, &nd, 16);
    }
    pthread_mutex_unlock(&j->lock);
    unpin_job(j, &pins);
    for (size_t i = 0; i < nd; i++)
        vx_store_result_remove(j->desc.store, dropped[i]);
    if (requeue) {
        VX_INFO("job.requeued", "job=%s kind=%s reason=shutdown", id, kind);
    } else {
        char qm[600];
        /* A failed job is worth an operator's look: warn, not info. */
        vx_log(st == ST_FAILED ? VX_LOG_WARN : VX_LOG_INFO, "job.finished",
               "job=%s kind=%s state=%s run_ms=%.1f code=%s message=%s", id, kind, state_names[st],
               run_s * 1e3, ok ? "-" : e->code, vx_log_quote(qm, sizeof qm, ok ? "-" : e->message));
        if (j->desc.hooks.finished)
            j->desc.hooks.finished(j->desc.hooks.ud, id, kind, state_names[st], run_s);
    }
    notify(j, id, !requeue);
    run_free(r);
    if (ok) vx_store_results_evict(j->desc.store);
}

vx_mesh *vx_jobs_read_mesh(vx_jobs *j, const char *id, vx_err *err)
{
    char path[VX_PATH_MAX];
    /* the file read is the one checked, whatever its path holds by then */
    int64_t version[7];
    int fd = vx_store_mesh_open_path(j->desc.store, id, path, sizeof path, version, err);
    if (fd < 0) return NULL;
    vx_mesh_limits lim = {.max_triangles = j->desc.limits.max_triangles};
    vx_mesh *m = vx_mesh_read_fd(fd, path, &lim, err);
    /* a file written in place while it was read (its parse error too) */
    vx_err changed = {0};
    if (vx_store_mesh_still_intact(id, fd, version, &changed)) {
        vx_mesh_free(m);
        m = NULL;
        *err = changed;
    }
    close(fd);
    return m;
}

/* The mesh of the previous job stays loaded: jobs on one mesh often come
 * in a row. GL thread only. */
typedef struct mesh_cache {
    char id[65];
    vx_mesh *mesh;
} mesh_cache;

static const vx_mesh *load_mesh(vx_jobs *j, mesh_cache *mc, const char *id, vx_err *err)
{
    if (mc->mesh && strcmp(mc->id, id) == 0) return mc->mesh;
    vx_mesh_free(mc->mesh);
    mc->mesh = NULL;
    mc->id[0] = 0;
    mc->mesh = vx_jobs_read_mesh(j, id, err);
    if (mc->mesh) snprintf(mc->id, sizeof mc->id, "%s", id);
    return mc->mesh;
}

static void run_job_gl(vx_jobs *j, vx_gl *gl, mesh_cache *mc, job *jb)
{
    pthread_mutex_lock(&j->lock);
    if (jb->state != ST_QUEUED) { /* canceled while queued */
        pthread_mutex_unlock(&j->lock);
        return;
    }
    jb->state = ST_RUNNING;
    jb->started = vx_now();
    jb->progress = 0;
    if (!j->cl) jb->attempts++; /* cluster mode: the claim's attempt */
    j->running++;
    j->in_gl = 1;
    vx_err err;
    vx_err_clear(&err);
    if (journal_locked(j, jb, &err))
        VX_ERROR("jobs.journal_failed", "job=%s code=%s", jb->id, err.code);
    pthread_mutex_unlock(&j->lock);
    notify(j, jb->id, 0);
    VX_INFO("job.started", "job=%s kind=%s mesh=%.12s attempt=%d", jb->id, jb->kind->name, jb->mesh,
            jb->attempts);

    vx_job_run *r = run_new(j, jb);
    if (!r || !r->stats || !r->outputs || !r->paths) {
        /* Out of memory for a few bytes: the job goes back to the queue
         * rather than failing for a reason that is not its own. */
        run_free(r);
        pthread_mutex_lock(&j->lock);
        j->running--;
        j->in_gl = 0;
        jb->state = ST_QUEUED;
        pthread_mutex_unlock(&j->lock);
        vx_queue_push(j->queue, jb, 1);
        return;
    }
    r->gl = gl;
    r->on_gl_thread = 1;
    if (jb->cancel_requested) {
        /* Canceled (or its lease lost) while it waited for this thread. */
        pthread_mutex_lock(&j->lock);
        j->in_gl = 0;
        pthread_mutex_unlock(&j->lock);
        vx_err_set(&err, VX_ECANCELED, "canceled", "the job was canceled");
        run_finish(j, r, 0, &err);
        return;
    }
    /* The params JSON (with its blobs back in place: 2 MB of frames are
     * 14 MB of cJSON) lives only until the kind's struct is read. */
    cJSON *params = inline_params(j, jb->kind, jb->params, &r->big_params, &err);
    if (params) r->typed = vx_kind_read(jb->kind, params, &j->desc.limits, &err);
    cJSON_Delete(params);
    if (r->big_params) malloc_trim(0);
    const vx_mesh *m = r->typed ? load_mesh(j, mc, jb->mesh, &err) : NULL;
    int ok = m != NULL;
    for (int attempt = 0; ok; attempt++) {
        double t = vx_mono();
        ok = jb->kind->run_gl(r, m, r->typed, &r->state, &err) == 0;
        int lost = vx_gl_lost(gl);
        if (j->desc.hooks.lose_context && j->desc.hooks.lose_context(j->desc.hooks.ud)) lost = 1;
        if (!lost) {
            cJSON_AddNumberToObject(r->stats, "gl_ms", ms_between(0, vx_mono() - t));
            break;
        }
        VX_WARN("gl.context_lost", "job=%s attempt=%d", jb->id, attempt + 1);
        __atomic_add_fetch(&j->gl_losses, 1, __ATOMIC_RELAXED);
        if (r->state && jb->kind->free_state) jb->kind->free_state(r->state);
        r->state = NULL;
        /* The retry starts over: what the lost attempt added goes. */
        while (r->stats->child)
            cJSON_DeleteItemFromArray(r->stats, 0);
        vx_err rerr;
        if (vx_gl_rebuild(gl, &rerr)) { /* logged by the GL layer */
            err = rerr;
            ok = 0;
            break;
        }
        cJSON_DeleteItemFromObjectCaseSensitive(r->stats, "context_rebuilds");
        cJSON_AddNumberToObject(r->stats, "context_rebuilds", attempt + 1);
        if (attempt >= 1) {
            vx_err_set(&err, VX_EGPU, "context_lost",
                       "the GL context was lost twice running this job");
            ok = 0;
            break;
        }
        ok = 1; /* retry once on the new context */
    }
    pthread_mutex_lock(&j->lock);
    j->in_gl = 0;
    pthread_mutex_unlock(&j->lock);
    if (!ok) {
        run_finish(j, r, 0, &err);
        return;
    }
    r->handed = vx_mono();
    pthread_mutex_lock(&j->lock);
    jb->waiting = r;
    vx_queue_push(j->cpu, r, 1);
    pthread_mutex_unlock(&j->lock);
}

void jobs_cancel_waiting(vx_jobs *j, const char *jid)
{
    pthread_mutex_lock(&j->lock);
    job *jb = find_job(j, jid);
    vx_job_run *r = jb ? jb->waiting : NULL;
    int took = r && jb->cancel_requested && vx_queue_remove(j->cpu, r);
    if (took) jb->waiting = NULL;
    pthread_mutex_unlock(&j->lock);
    if (!took) return; /* not waiting: its next progress check stops it */
    r->waited += vx_mono() - r->handed;
    cJSON_AddNumberToObject(r->stats, "cpu_wait_ms", ms_between(0, r->waited));
    vx_err err;
    vx_err_set(&err, VX_ECANCELED, "canceled", "the job was canceled");
    run_finish(j, r, 0, &err);
}

void jobs_alive(vx_jobs *j)
{
    if (j->desc.hooks.alive) j->desc.hooks.alive(j->desc.hooks.ud);
}

static void *gl_main(void *arg)
{
    vx_jobs *j = arg;
    vx_err err;
    vx_err_clear(&err);
    vx_gl *gl = vx_gl_new(&j->desc.gl, &err);
    pthread_mutex_lock(&j->lock);
    if (gl) {
        j->gl_info = *vx_gl_get_info(gl);
        j->gl_state = 1;
    } else {
        j->gl_err = err;
        j->gl_state = -1;
    }
    pthread_cond_broadcast(&j->gl_cond);
    pthread_mutex_unlock(&j->lock);
    if (!gl) return NULL;
    mesh_cache mc = {{0}, NULL};
    double last_ping = 0;
    while (!j->stopping) {
        double now = vx_mono();
        if (now - last_ping > 1.0) {
            jobs_alive(j);
            last_ping = now;
        }
        /* The GL stage runs at most one job ahead of the CPU workers: a
         * finished GL stage holds its job's memory until a worker takes
         * it, so while one waits no other starts, and a burst of jobs
         * stays in the job queue (bounded: 429 queue_full) instead of
         * piling up here (at most workers + 2 jobs hold memory at once). */
        if (vx_queue_wait_below(j->cpu, 1, 0.5)) continue;
        job *jb = vx_queue_pop(j->queue, 0.5);
        if (!jb) continue;
        if (j->stopping) { /* popped but not started: stays queued in the journal */
            break;
        }
        run_job_gl(j, gl, &mc, jb);
    }
    vx_mesh_free(mc.mesh);
    vx_gl_free(gl);
    return NULL;
}

static void *worker_main(void *arg)
{
    vx_jobs *j = arg;
    vx_job_run *r;
    while ((r = vx_queue_pop(j->cpu, -1))) {
        pthread_mutex_lock(&j->lock);
        r->job->waiting = NULL;
        pthread_mutex_unlock(&j->lock);
        vx_err err;
        vx_err_clear(&err);
        r->waited += vx_mono() - r->handed;
        cJSON_AddNumberToObject(r->stats, "cpu_wait_ms", ms_between(0, r->waited));
        const vx_kind *k = r->job->kind;
        int ok = 1;
        if (k->run_cpu) ok = k->run_cpu(r, r->typed, r->state, &err) == 0;
        if (ok && k->encode) ok = k->encode(r, r->typed, r->state, &err) == 0;
        run_finish(j, r, ok, &err);
    }
    return NULL;
}

int vx_jobs_start(vx_jobs *j, vx_err *err)
{
    if (pthread_create(&j->gl_thread, NULL, gl_main, j))
        return vx_err_set(err, VX_EINTERNAL, "thread_failed", "cannot start the GL thread");
    pthread_mutex_lock(&j->lock);
    while (j->gl_state == 0)
        pthread_cond_wait(&j->gl_cond, &j->lock);
    int state = j->gl_state;
    if (state < 0 && err) *err = j->gl_err;
    pthread_mutex_unlock(&j->lock);
    if (state < 0) {
        pthread_join(j->gl_thread, NULL);
        return -1;
    }
    j->workers = calloc((size_t)j->desc.workers, sizeof *j->workers);
    for (int i = 0; j->workers && i < j->desc.workers; i++)
        if (pthread_create(&j->workers[i], NULL, worker_main, j) == 0) j->nworkers++;
    j->started = 1;
    if (j->cl && cluster_start(j, err)) return -1;
    return 0;
}

void vx_jobs_stop(vx_jobs *j)
{
    if (!j || !j->started) return;
    cluster_stop_claims(j); /* cluster mode: nothing new is claimed */
    j->stopping = 1;
    pthread_join(j->gl_thread, NULL);
    /* The GL thread has handed over everything it ran: workers finish those
     * (encoding is short) and exit when the queue is empty. */
    vx_queue_close(j->cpu);
    for (int i = 0; i < j->nworkers; i++)
        pthread_join(j->workers[i], NULL);
    free(j->workers);
    j->workers = NULL;
    j->started = 0;
    cluster_release_queued(j); /* claimed here, never started: back to the queue */
    pthread_mutex_lock(&j->lock);
    vx_err err;
    /* the journal as appended stays (complete: replay reads it) */
    if (compact_locked(j, &err)) VX_WARN("journal.compact_skipped", "at=stop code=%s", err.code);
    pthread_mutex_unlock(&j->lock);
    VX_INFO("jobs.stopped", "jobs=%zu queued=%zu", j->jobs.n, vx_queue_depth(j->queue));
}
