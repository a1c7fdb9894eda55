/* The job state on disk: a snapshot of a job per change, compaction to one
 * snapshot per job, and the replay that rebuilds the table at open.
 * jobs_int.h. */
#include "jobs/jobs_int.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "util/clock.h"
#include "util/log.h"

/* Journals a snapshot; caller holds the lock (so seq and file order agree). */
int journal_locked(vx_jobs *j, job *jb, vx_err *err)
{
    /* A new job's first record: the jobs not yet finished (the queued and
     * the running ones, this one too) each still write a start and an end. */
    const size_t owed =
        jb->seq ? 0 : 2 * (vx_queue_depth(j->queue) + vx_queue_depth(j->cpu) + j->running + 1);
    jb->seq++;
    cJSON *rec = cJSON_CreateObject();
    cJSON_AddItemToObject(rec, "job", job_json(j, jb, 0));
    int rc = j->st_ops->append(j->st, rec, owed, err);
    cJSON_Delete(rec);
    return rc;
}

int journal_delete_locked(vx_jobs *j, job *jb, vx_err *err)
{
    jb->seq++;
    cJSON *rec = cJSON_CreateObject();
    cJSON *o = cJSON_AddObjectToObject(rec, "job");
    cJSON_AddStringToObject(o, "id", jb->id);
    cJSON_AddNumberToObject(o, "seq", (double)jb->seq);
    cJSON_AddBoolToObject(o, "deleted", 1);
    int rc = j->st_ops->append(j->st, rec, 0, err);
    cJSON_Delete(rec);
    if (rc) jb->seq--;
    return rc;
}

/* Rewrites the journal as one snapshot per job. Caller holds the lock (or
 * runs before any thread starts). */
int compact_locked(vx_jobs *j, vx_err *err)
{
    cJSON **recs = calloc(j->jobs.n + 1, sizeof *recs);
    if (!recs) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    for (size_t i = 0; i < j->jobs.n; i++) {
        recs[i] = cJSON_CreateObject();
        cJSON_AddItemToObject(recs[i], "job", job_json(j, job_at(j, i), 0));
    }
    int rc = j->st_ops->compact(j->st, recs, j->jobs.n, err);
    for (size_t i = 0; i < j->jobs.n; i++)
        cJSON_Delete(recs[i]);
    free(recs);
    return rc;
}

static void replay_one(const cJSON *rec, void *ud)
{
    vx_jobs *j = ud;
    const cJSON *o = cJSON_GetObjectItemCaseSensitive(rec, "job");
    const char *id = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "id"));
    const char *kind = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "kind"));
    const char *mesh = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "mesh"));
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "state"));
    if (vx_jobs_valid_id(id) && cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(o, "deleted"))) {
        int found;
        size_t at = vx_sorted_find(&j->jobs, id, &found);
        if (found) job_free(vx_sorted_remove_at(&j->jobs, at));
        if (j->ngone == j->capgone) {
            size_t cap = j->capgone ? 2 * j->capgone : 64;
            char(*n)[33] = realloc(j->gone, cap * sizeof *n);
            if (!n) return; /* its results are then moved aside, not removed */
            j->gone = n;
            j->capgone = cap;
        }
        snprintf(j->gone[j->ngone++], sizeof *j->gone, "%s", id);
        return;
    }
    if (!vx_jobs_valid_id(id) || !kind || !mesh || !state) {
        VX_WARN("journal.bad_job", "reason=missing_fields");
        return;
    }
    const vx_kind *k = vx_kinds_find(j->desc.kinds, kind);
    if (!k) {
        VX_WARN("journal.unknown_kind", "job=%s kind=%s", id, kind);
        return;
    }
    long seq = (long)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(o, "seq"));
    job *jb = find_job(j, id);
    if (jb && seq <= jb->seq) return;
    if (!jb) {
        jb = calloc(1, sizeof *jb);
        if (!jb) return;
        snprintf(jb->id, sizeof jb->id, "%s", id);
        if (vx_sorted_insert(&j->jobs, jb)) {
            free(jb);
            return;
        }
    }
    jb->kind = k;
    snprintf(jb->mesh, sizeof jb->mesh, "%s", mesh);
    jb->seq = seq;
    jb->state = ST_QUEUED;
    for (int s = 0; s < 5; s++)
        if (strcmp(state, state_names[s]) == 0) jb->state = (job_state)s;
    jb->progress = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(o, "progress"));
    if (jb->progress != jb->progress) jb->progress = 0;
    jb->attempts = (int)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(o, "attempts"));
    jb->cancel_requested = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(o, "cancel_requested"));
    jb->interruptions =
        (int)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(o, "interruptions"));
    if (jb->interruptions < 0) jb->interruptions = 0;
    double t[3] = {0, 0, 0};
    const char *tn[3] = {"created", "started", "finished"};
    for (int i = 0; i < 3; i++) {
        const char *s = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, tn[i]));
        if (!s) continue;
        struct tm tm = {0};
        int ms = 0;
        if (sscanf(s, "%d-%d-%dT%d:%d:%d.%dZ", &tm.tm_year, &tm.tm_mon, &tm.tm_mday, &tm.tm_hour,
                   &tm.tm_min, &tm.tm_sec, &ms) >= 6) {
            tm.tm_year -= 1900;
            tm.tm_mon -= 1;
            t[i] = (double)timegm(&tm) + ms / 1000.0;
        }
    }
    const cJSON *full = cJSON_GetObjectItemCaseSensitive(o, "times"); /* journals since 47 */
    if (cJSON_GetArraySize(full) == 3)
        for (int i = 0; i < 3; i++) {
            const double v = cJSON_GetNumberValue(cJSON_GetArrayItem(full, i));
            if (v >= 0 && v < 253402300800.0) t[i] = v; /* to year 9999; not NaN */
        }
    jb->created = t[0];
    jb->started = t[1];
    jb->finished = t[2];
    cJSON_Delete(jb->params);
    cJSON_Delete(jb->stats);
    cJSON_Delete(jb->outputs);
    jb->params = cJSON_Duplicate(cJSON_GetObjectItemCaseSensitive(o, "params"), 1);
    jb->stats = cJSON_Duplicate(cJSON_GetObjectItemCaseSensitive(o, "stats"), 1);
    jb->outputs = cJSON_Duplicate(cJSON_GetObjectItemCaseSensitive(o, "outputs"), 1);
    if (!jb->params) jb->params = cJSON_CreateObject();
    jb->fp = request_fp(k->name, jb->mesh, jb->params);
    const char *idem = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "idempotency_key"));
    free(jb->idem);
    jb->idem = vx_jobs_valid_idem_key(idem) ? strdup(idem) : NULL;
    vx_err_clear(&jb->error);
    const cJSON *e = cJSON_GetObjectItemCaseSensitive(o, "error");
    if (cJSON_IsObject(e)) {
        jb->error.kind =
            (vx_err_kind)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(e, "kind"));
        if (jb->error.kind == VX_EOK) jb->error.kind = VX_EINTERNAL;
        snprintf(jb->error.code, sizeof jb->error.code, "%s",
                 cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "code")) ?: "unknown");
        snprintf(jb->error.message, sizeof jb->error.message, "%s",
                 cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "message")) ?: "");
    }
}

/* An unfinished job found at start: canceled when its cancel was asked
 * for, failed `interrupted` when the daemon died during it (its journal
 * says running) for the max_interruptions-th time. 1 when it ended so. */
static int end_at_start(vx_jobs *j, job *jb)
{
    if (jb->state == ST_RUNNING) jb->interruptions++;
    if (jb->cancel_requested) {
        jb->state = ST_CANCELED;
        vx_err_set(&jb->error, VX_ECANCELED, "canceled",
                   "canceled (the daemon stopped before the job did)");
    } else if (jb->state == ST_RUNNING && jb->interruptions >= j->desc.max_interruptions) {
        jb->state = ST_FAILED;
        vx_err_set(&jb->error, VX_EINTERNAL, "interrupted",
                   "the daemon stopped during this job %d times (a crash, kill -9 or the "
                   "out-of-memory killer?): it is not run again",
                   jb->interruptions);
    } else {
        return 0;
    }
    jb->finished = vx_now();
    VX_WARN("job.finished", "job=%s kind=%s state=%s code=%s at=start", jb->id, jb->kind->name,
            state_names[jb->state], jb->error.code);
    return 1;
}

static int cmp_id(const void *a, const void *b)
{
    return strcmp(a, b);
}

/* vx_store_results_prune's test at open (one thread): a succeeded job's
 * results stay; those of a job the journal names otherwise (not
 * succeeded, or deleted) are a crash's leftovers; those of a job it never
 * names are results it lost (emptied, removed, damaged): moved aside. */
static int keep_result(void *ud, const char *jid)
{
    vx_jobs *j = ud;
    const job *jb = find_job(j, jid);
    if (jb) return jb->state == ST_SUCCEEDED;
    if (j->ngone && bsearch(jid, j->gone, j->ngone, sizeof *j->gone, cmp_id)) return 0;
    return -1;
}

vx_jobs *vx_jobs_open(const vx_jobs_desc *desc, vx_err *err)
{
    vx_jobs *j = calloc(1, sizeof *j);
    if (!j) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    j->desc = *desc;
    if (!j->desc.max_queued) j->desc.max_queued = 64;
    if (!j->desc.history) j->desc.history = 10000;
    if (j->desc.workers <= 0) j->desc.workers = 2;
    if (j->desc.max_interruptions <= 0) j->desc.max_interruptions = 3;
    vx_sorted_init(&j->jobs, job_key);
    pthread_mutex_init(&j->lock, NULL);
    pthread_cond_init(&j->gl_cond, NULL);
    j->queue = vx_queue_new(j->desc.max_queued);
    j->cpu = vx_queue_new(0);
    char path[VX_PATH_MAX];
    if (!j->desc.journal) {
        snprintf(path, sizeof path, "%s/journal.log", vx_store_dir(desc->store));
        j->desc.journal = path;
    }
    if (j->desc.replica && *j->desc.replica)
        snprintf(j->replica, sizeof j->replica, "%s", j->desc.replica);
    else if (gethostname(j->replica, sizeof j->replica - 1) != 0)
        snprintf(j->replica, sizeof j->replica, "voxeld");
    j->desc.replica = NULL; /* the caller's string */
    j->st_ops = j->desc.database ? &cluster_state
                : j->desc.state  ? j->desc.state
                                 : &vx_jobstate_local;
    if (j->desc.database && cluster_open(j, err)) {
        vx_jobs_free(j);
        return NULL;
    }
    j->desc.database = NULL; /* the caller's; cluster_open took what it needs */
    j->st = j->st_ops->open(j->desc.journal, err);
    if (!j->st || !j->queue || !j->cpu) {
        if (j->st || err->kind == VX_EOK)
            vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        vx_jobs_free(j);
        return NULL;
    }
    j->desc.journal = NULL; /* path was on our stack */
    long n = j->st_ops->replay(j->st, replay_one, j, err);
    if (n < 0) {
        vx_jobs_free(j);
        return NULL;
    }
    /* Jobs that never finished run again, oldest first, whatever the
     * queue limit: they were acknowledged. But not one whose cancel was
     * acknowledged (canceled now), nor one the daemon died during too many
     * times: run again, a job that crashes it (or is killed for its memory)
     * would at every start. */
    size_t requeued = 0, ended = 0;
    for (size_t i = 0; i < j->jobs.n; i++) {
        job *jb = job_at(j, i);
        if (!is_terminal(jb->state) && end_at_start(j, jb)) ended++;
        if (jb->state == ST_QUEUED || jb->state == ST_RUNNING) {
            jb->state = ST_QUEUED;
            jb->progress = 0;
            jb->started = 0;
            vx_queue_push(j->queue, jb, 1);
            requeued++;
        } else if (jb->state == ST_SUCCEEDED && !jb->outputs) {
            jb->outputs = cJSON_CreateObject();
        }
        /* Unfinished jobs hold their meshes and blobs again; finished ones
         * shrink to their text. */
        if (is_terminal(jb->state))
            freeze_locked(j, jb);
        else
            pin_job(j, jb->mesh, jb->kind, jb->params, 1, &jb->pins, NULL);
    }
    char dropped[256][33];
    size_t nd;
    do { /* a history of any length down to a lower limit */
        trim_history_locked(j, dropped, &nd, 256);
        for (size_t i = 0; i < nd; i++)
            vx_store_result_remove(desc->store, dropped[i]);
    } while (nd == 256);
    /* Results no succeeded job names: a job killed mid-write (it runs
     * again from nothing, or was canceled), a delete a crash cut short;
     * and results of jobs the journal does not know at all (lost). */
    if (j->ngone) qsort(j->gone, j->ngone, sizeof *j->gone, cmp_id);
    vx_store_results_prune(desc->store, keep_result, j);
    free(j->gone);
    j->gone = NULL;
    j->ngone = j->capgone = 0;
    /* What no unfinished job holds: meshes deleted while jobs used them,
     * blobs of jobs that finished or were never acknowledged. */
    vx_store_collect(desc->store);
    if (compact_locked(j, err)) {
        /* The journal as replayed is complete (replay cut any torn tail):
         * on a full disk the daemon starts on it uncompacted and serves
         * reads, and writes answer 507 until there is room again. */
        if (err->kind != VX_ENOSPC) {
            vx_jobs_free(j);
            return NULL;
        }
        VX_WARN("journal.compact_skipped", "reason=disk_full");
        vx_err_clear(err);
    }
    VX_INFO("jobs.replayed", "records=%ld jobs=%zu requeued=%zu ended=%zu", n, j->jobs.n, requeued,
            ended);
    return j;
}

int vx_jobs_state_intact(vx_jobs *j)
{
    return !j->st_ops->intact || j->st_ops->intact(j->st);
}

void vx_jobs_maintain(vx_jobs *j, long max_journal_bytes)
{
    long size = j->st_ops->size(j->st);
    if (size < 0 || size <= max_journal_bytes) return;
    vx_err err;
    pthread_mutex_lock(&j->lock);
    int rc = compact_locked(j, &err);
    pthread_mutex_unlock(&j->lock);
    if (rc)
        VX_ERROR("journal.compact_failed", "code=%s", err.code);
    else
        VX_INFO("journal.compacted", "bytes=%ld", j->st_ops->size(j->st));
}

void vx_jobs_free(vx_jobs *j)
{
    if (!j) return;
    vx_jobs_stop(j);
    for (size_t i = 0; i < j->jobs.n; i++)
        job_free(job_at(j, i));
    vx_sorted_free(&j->jobs);
    vx_queue_free(j->queue);
    vx_queue_free(j->cpu);
    free(j->gone);
    if (j->st) j->st_ops->close(j->st);
    cluster_free(j);
    pthread_mutex_destroy(&j->lock);
    pthread_cond_destroy(&j->gl_cond);
    free(j);
}
