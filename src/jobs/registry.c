/* The job registry: job objects, their JSON, the history budget, and the
 * API over the table (submit, get, cancel, list, outputs). jobs_int.h. */
#include "jobs/jobs_int.h"

#include <errno.h>
#include <malloc.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/random.h>

#include "util/fsutil.h"
#include "util/log.h"
#include "util/json.h"

const char *const state_names[5] = {"queued", "running", "succeeded", "failed", "canceled"};

/* ---- job objects ------------------------------------------------------- */

void pinset_free(pinset *ps)
{
    free(ps->mesh);
    free(ps->blob);
    memset(ps, 0, sizeof *ps);
}

/* Frees a job; its pins are released by whoever ends it, never here (a
 * queued job freed at shutdown keeps its mesh for the next start). */
void job_free(job *jb)
{
    if (!jb) return;
    cJSON_Delete(jb->params);
    cJSON_Delete(jb->stats);
    cJSON_Delete(jb->outputs);
    free(jb->frozen);
    free(jb->idem);
    cJSON_Delete(jb->children);
    pinset_free(&jb->pins);
    free(jb);
}

int is_terminal(job_state s)
{
    return s >= ST_SUCCEEDED;
}

int vx_jobs_valid_id(const char *s)
{
    if (!s || strlen(s) != 32) return 0;
    for (int i = 0; i < 32; i++)
        if (!((s[i] >= '0' && s[i] <= '9') || (s[i] >= 'a' && s[i] <= 'f'))) return 0;
    return 1;
}

/* Ids increase: within a millisecond (or a clock stepped back) the next
 * id is the last one plus a random step under 2^32, so that ids sort in
 * the order they were made and stay hard to guess. */
void jobs_new_id(char out[33])
{
    static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
    static unsigned long long last_ms;
    static unsigned char last[10];
    unsigned char rnd[10] = {0};
    if (getrandom(rnd, sizeof rnd, 0) != (ssize_t)sizeof rnd) {
        for (size_t i = 0; i < sizeof rnd; i++)
            rnd[i] = (unsigned char)rand();
    }
    unsigned long long ms = (unsigned long long)(vx_now() * 1000.0) & 0xffffffffffffULL;
    pthread_mutex_lock(&lock);
    if (ms <= last_ms) {
        /* last + 1 + (the random bytes' low 31 bits), carried up the bytes */
        unsigned long long add =
            1 + ((unsigned long long)(rnd[6] & 0x7f) << 24 | rnd[7] << 16 | rnd[8] << 8 | rnd[9]);
        memcpy(rnd, last, sizeof rnd);
        for (int i = 9; i >= 0 && add; i--) {
            add += rnd[i];
            rnd[i] = (unsigned char)add;
            add >>= 8;
        }
        ms = last_ms + (add ? 1 : 0); /* all 80 bits spent: the next millisecond */
    }
    last_ms = ms;
    memcpy(last, rnd, sizeof last);
    pthread_mutex_unlock(&lock);
    snprintf(out, 33, "%012llx", ms);
    for (int i = 0; i < 10; i++)
        snprintf(out + 12 + 2 * i, 3, "%02x", rnd[i]);
}

static void add_time(cJSON *o, const char *name, double t)
{
    if (t > 0) {
        char buf[32];
        vx_rfc3339(t, buf);
        cJSON_AddStringToObject(o, name, buf);
    } else {
        cJSON_AddNullToObject(o, name);
    }
}

double ms_between(double a, double b)
{
    return (double)(long long)((b - a) * 1e6) / 1e3;
}

void job_parts(const job *jb, cJSON **params, cJSON **stats, cJSON **outputs)
{
    cJSON *f = jb->frozen ? cJSON_Parse(jb->frozen) : NULL;
    const cJSON *src[3] = {jb->params, jb->stats, jb->outputs};
    static const char *const names[3] = {"params", "stats", "outputs"};
    cJSON **dst[3] = {params, stats, outputs};
    for (int i = 0; i < 3; i++) {
        if (!dst[i]) continue;
        cJSON *v = f ? cJSON_DetachItemFromObjectCaseSensitive(f, names[i])
                     : (src[i] ? cJSON_Duplicate(src[i], 1) : NULL);
        *dst[i] = v ? v : cJSON_CreateObject();
    }
    cJSON_Delete(f);
}

cJSON *job_json(const vx_jobs *j, const job *jb, int api)
{
    cJSON *params, *stats, *outputs;
    job_parts(jb, &params, &stats, &outputs);
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "id", jb->id);
    cJSON_AddStringToObject(o, "kind", jb->kind->name);
    cJSON_AddStringToObject(o, "mesh", jb->mesh);
    cJSON_AddItemToObject(o, "params", params);
    cJSON_AddStringToObject(o, "state", state_names[jb->state]);
    cJSON_AddNumberToObject(o, "progress", jb->progress);
    cJSON_AddBoolToObject(o, "cancel_requested", jb->cancel_requested);
    cJSON_AddNumberToObject(o, "attempts", jb->attempts);
    if (api) {
        cJSON_AddNumberToObject(o, "attempt", jb->attempts);
        if (jb->attempts > 0)
            cJSON_AddStringToObject(o, "replica", j->replica);
        else
            cJSON_AddNullToObject(o, "replica");
    }
    add_time(o, "created", jb->created);
    add_time(o, "started", jb->started);
    add_time(o, "finished", jb->finished);
    if (jb->error.kind != VX_EOK) {
        cJSON *e = cJSON_AddObjectToObject(o, "error");
        cJSON_AddStringToObject(e, "code", jb->error.code);
        cJSON_AddStringToObject(e, "message", jb->error.message);
        if (!api) cJSON_AddNumberToObject(e, "kind", jb->error.kind);
    } else {
        cJSON_AddNullToObject(o, "error");
    }
    if (api) {
        cJSON *t = cJSON_AddObjectToObject(o, "timings");
        double now = vx_now();
        double qend = jb->started > 0 ? jb->started : (is_terminal(jb->state) ? jb->finished : now);
        cJSON_AddNumberToObject(t, "queue_ms", ms_between(jb->created, qend));
        if (jb->started > 0)
            cJSON_AddNumberToObject(t, "run_ms",
                                    ms_between(jb->started, jb->finished > 0 ? jb->finished : now));
        else
            cJSON_AddNullToObject(t, "run_ms");
        if (jb->finished > 0)
            cJSON_AddNumberToObject(t, "total_ms", ms_between(jb->created, jb->finished));
        else
            cJSON_AddNullToObject(t, "total_ms");
    } else {
        cJSON_AddNumberToObject(o, "seq", (double)jb->seq);
        /* the times in full (the strings above keep milliseconds), so that
         * a replayed job gives the same created and timings */
        const double t[3] = {jb->created, jb->started, jb->finished};
        cJSON_AddItemToObject(o, "times", cJSON_CreateDoubleArray(t, 3));
        if (jb->idem) cJSON_AddStringToObject(o, "idempotency_key", jb->idem);
        if (jb->interruptions) cJSON_AddNumberToObject(o, "interruptions", jb->interruptions);
    }
    cJSON_AddItemToObject(o, "stats", stats);
    if (api) {
        cJSON *outs = cJSON_AddObjectToObject(o, "outputs");
        const cJSON *it;
        if (jb->state == ST_SUCCEEDED) cJSON_ArrayForEach(it, outputs)
            {
                char url[256];
                snprintf(url, sizeof url, "/v1/jobs/%s/result/%s", jb->id, it->string);
                cJSON_AddStringToObject(outs, it->string, url);
            }
        cJSON_Delete(outputs);
    } else {
        cJSON_AddItemToObject(o, "outputs", outputs);
    }
    return o;
}

/* A job reached a finished state: its params, stats and outputs become one
 * compact text (a tree costs several times its text), counted in the
 * history budget. Caller holds the lock. */
void freeze_locked(vx_jobs *j, job *jb)
{
    if (jb->frozen || jb->bytes) return;
    cJSON *o = cJSON_CreateObject();
    char *text = NULL;
    if (o && (!jb->params || cJSON_AddItemReferenceToObject(o, "params", jb->params)) &&
        (!jb->stats || cJSON_AddItemReferenceToObject(o, "stats", jb->stats)) &&
        (!jb->outputs || cJSON_AddItemReferenceToObject(o, "outputs", jb->outputs)))
        text = vx_json_print(o, 0);
    cJSON_Delete(o);
    if (text) {
        cJSON_Delete(jb->params);
        cJSON_Delete(jb->stats);
        cJSON_Delete(jb->outputs);
        jb->params = jb->stats = jb->outputs = NULL;
        jb->frozen = text;
        jb->bytes = sizeof *jb + strlen(text) + 1;
    } else {
        jb->bytes = sizeof *jb + 16384; /* no memory to print it: a guess */
    }
    j->history_bytes += jb->bytes;
}

const char *job_key(const void *item)
{
    return ((const job *)item)->id;
}

job *job_at(const vx_jobs *j, size_t i)
{
    return j->jobs.items[i];
}

job *find_job(vx_jobs *j, const char *id)
{
    return vx_sorted_get(&j->jobs, id);
}

/* Drops the oldest finished jobs beyond the history limits, in count and
 * in bytes (and their results); the byte budget leaves at least one. */
void trim_history_locked(vx_jobs *j, char (*dropped)[33], size_t *ndropped, size_t max)
{
    size_t finished = 0;
    for (size_t i = 0; i < j->jobs.n; i++)
        finished += is_terminal(job_at(j, i)->state);
    size_t w = 0;
    *ndropped = 0;
    for (size_t i = 0; i < j->jobs.n; i++) {
        job *jb = job_at(j, i);
        int over =
            finished > j->desc.history ||
            (j->desc.history_bytes && j->history_bytes > j->desc.history_bytes && finished > 1);
        if (over && is_terminal(jb->state) && *ndropped < max) {
            snprintf(dropped[(*ndropped)++], 33, "%s", jb->id);
            j->history_bytes -= jb->bytes;
            job_free(jb);
            finished--;
            continue;
        }
        j->jobs.items[w++] = jb;
    }
    j->jobs.n = w;
}

void notify(vx_jobs *j, const char *jid, int terminal)
{
    if (j->desc.hooks.changed) j->desc.hooks.changed(j->desc.hooks.ud, jid, terminal);
}

/* ---- API --------------------------------------------------------------- */

cJSON *vx_jobs_submit(vx_jobs *j, const char *mesh, const char *kind, const cJSON *params,
                      vx_err *err)
{
    return vx_jobs_submit_with(j, mesh, kind, params, NULL, NULL, err);
}

/* Grows meta's bbox to hold the further meshes the params name (a render
 * of several meshes frames their union), so check_mesh sees the job's box.
 * A mesh that is not stored is left out: pinning answers 404 for it. */
static void union_bbox(vx_jobs *j, const vx_kind *k, const cJSON *norm, cJSON *meta)
{
    cJSON *bb = cJSON_GetObjectItemCaseSensitive(meta, "bbox");
    cJSON *lo = cJSON_GetObjectItemCaseSensitive(bb, "min");
    cJSON *hi = cJSON_GetObjectItemCaseSensitive(bb, "max");
    if (!k->mesh_refs || cJSON_GetArraySize(lo) != 3 || cJSON_GetArraySize(hi) != 3) return;
    const char *ids[256];
    size_t n = k->mesh_refs(norm, ids, 256);
    for (size_t i = 0; i < n && i < 256; i++) {
        vx_err e;
        cJSON *m = ids[i] && vx_store_valid_mesh_id(ids[i])
                       ? vx_store_mesh_meta(j->desc.store, ids[i], &e)
                       : NULL;
        cJSON *mb = cJSON_GetObjectItemCaseSensitive(m, "bbox");
        cJSON *mlo = cJSON_GetObjectItemCaseSensitive(mb, "min");
        cJSON *mhi = cJSON_GetObjectItemCaseSensitive(mb, "max");
        if (cJSON_GetArraySize(mlo) == 3 && cJSON_GetArraySize(mhi) == 3)
            for (int a = 0; a < 3; a++) {
                cJSON *l = cJSON_GetArrayItem(lo, a), *h = cJSON_GetArrayItem(hi, a);
                double ml = cJSON_GetNumberValue(cJSON_GetArrayItem(mlo, a));
                double mh = cJSON_GetNumberValue(cJSON_GetArrayItem(mhi, a));
                if (ml < cJSON_GetNumberValue(l)) cJSON_SetNumberValue(l, ml);
                if (mh > cJSON_GetNumberValue(h)) cJSON_SetNumberValue(h, mh);
            }
        cJSON_Delete(m);
    }
}

/* A retry under an Idempotency-Key whose mesh is gone (deleted since the
 * first try): the key's job, when it is this request (kind, mesh and
 * normalised params), else NULL. */
static cJSON *idem_retry(vx_jobs *j, const vx_kind *k, const char *mesh, const cJSON *params,
                         const char *key)
{
    if (params && !cJSON_IsObject(params)) return NULL;
    vx_err e;
    vx_err_clear(&e);
    cJSON *norm = vx_params_normalize(k, params, &j->desc.limits, &e);
    /* large inline inputs as the blob references the job holds (the store
     * has them: a put of the same bytes costs a hash) */
    pinset pins = {0};
    if (norm && externalize(j, k, norm, &pins, &e)) {
        cJSON_Delete(norm);
        norm = NULL;
    }
    unpin_job(j, &pins);
    if (!norm) return NULL;
    const uint64_t fp = request_fp(k->name, mesh, norm);
    cJSON *doc = NULL;
    if (j->cl) {
        doc = cluster_find_idem(j, key, fp);
    } else {
        job probe;
        memset(&probe, 0, sizeof probe);
        snprintf(probe.mesh, sizeof probe.mesh, "%s", mesh);
        probe.kind = k;
        probe.params = norm;
        probe.fp = fp;
        probe.idem = (char *)key;
        pthread_mutex_lock(&j->lock);
        const job *prior = find_existing_locked(j, &probe, 0, &e);
        if (prior) doc = job_json(j, prior, 1);
        pthread_mutex_unlock(&j->lock);
    }
    cJSON_Delete(norm);
    return doc;
}

cJSON *vx_jobs_submit_with(vx_jobs *j, const char *mesh, const char *kind, const cJSON *params,
                           const vx_jobs_submit_opts *opts, int *existing, vx_err *err)
{
    if (existing) *existing = 0;
    const vx_kind *k = vx_kinds_find(j->desc.kinds, kind);
    if (!k) {
        vx_err_set(err, VX_EUNPROC, "unknown_kind", "unknown job kind '%.64s'", kind);
        return NULL;
    }
    cJSON *meta = vx_store_mesh_meta(j->desc.store, mesh, err);
    if (!meta) {
        cJSON *doc = opts && opts->idempotency_key && !strcmp(err->code, "mesh_not_found")
                         ? idem_retry(j, k, mesh, params, opts->idempotency_key)
                         : NULL;
        if (doc) {
            vx_err_clear(err);
            if (existing) *existing = 1;
        }
        return doc;
    }
    if (params && !cJSON_IsObject(params)) {
        cJSON_Delete(meta);
        vx_err_set(err, VX_EUNPROC, "invalid_params", "params must be an object");
        return NULL;
    }
    cJSON *norm = vx_params_normalize(k, params, &j->desc.limits, err);
    if (norm && k->check_mesh) {
        union_bbox(j, k, norm, meta);
        void *typed = vx_kind_read(k, norm, &j->desc.limits, err);
        if (!typed || k->check_mesh(typed, meta, &j->desc.limits, err)) {
            cJSON_Delete(norm);
            norm = NULL;
        }
        vx_kind_params_free(k, typed);
    }
    cJSON_Delete(meta);
    if (!norm) return NULL;
    job *jb = calloc(1, sizeof *jb);
    if (!jb) {
        cJSON_Delete(norm);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    jb->params = norm;
    /* The job holds its meshes (a delete keeps their files until it ends)
     * and its large inline inputs are stored as blobs, all before it is
     * acknowledged. */
    if (pin_job(j, mesh, k, norm, 0, &jb->pins, err) || externalize(j, k, norm, &jb->pins, err)) {
        unpin_job(j, &jb->pins);
        job_free(jb);
        return NULL;
    }
    size_t jb_blobs = jb->pins.nblob;
    if (j->cl) {
        /* Cluster mode: the database queues it; the mesh pins were only
         * its check (the replica that claims it pins it there), the blob
         * pins stay (a blob is read by whichever replica runs the job). */
        for (size_t i = 0; i < jb->pins.nmesh; i++)
            vx_store_mesh_unpin(j->desc.store, jb->pins.mesh[i]);
        int dummy = 0;
        cJSON *out = cluster_submit(j, mesh, k, norm, request_fp(k->name, mesh, norm), opts,
                                    existing ? existing : &dummy, err);
        job_free(jb);
        return out;
    }
    snprintf(jb->mesh, sizeof jb->mesh, "%s", mesh);
    jb->kind = k;
    jb->stats = cJSON_CreateObject();
    jb->outputs = cJSON_CreateObject();
    jb->fp = request_fp(k->name, mesh, norm);
    if (opts && opts->idempotency_key && !(jb->idem = strdup(opts->idempotency_key))) {
        unpin_job(j, &jb->pins);
        job_free(jb);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    pthread_mutex_lock(&j->lock);
    cJSON *out = NULL;
    vx_err_clear(err);
    job *prior = (jb->idem || (opts && opts->reuse))
                     ? find_existing_locked(j, jb, opts && opts->reuse, err)
                     : NULL;
    if (prior || err->kind != VX_EOK) {
        /* An answer from the table: the new job was never acknowledged. */
        cJSON *doc = prior ? job_json(j, prior, 1) : NULL;
        pthread_mutex_unlock(&j->lock);
        unpin_job(j, &jb->pins);
        job_free(jb);
        if (doc && existing) *existing = 1;
        return doc;
    }
    if (opts && opts->refuse_new && opts->refuse_new->kind != VX_EOK) {
        pthread_mutex_unlock(&j->lock);
        unpin_job(j, &jb->pins);
        job_free(jb);
        *err = *opts->refuse_new;
        return NULL;
    }
    /* The id is made under the lock: ids increase in the order jobs enter
     * the table, so a list after the newest id seen misses none. */
    jobs_new_id(jb->id);
    jb->created = vx_now(); /* after the id's time: not in a millisecond before it */
    if (j->stopping) {
        vx_err_set(err, VX_EUNAVAIL, "not_ready", "the daemon is shutting down");
    } else if (vx_queue_depth(j->queue) >= vx_queue_capacity(j->queue)) {
        vx_err_set(err, VX_EBUSY, "queue_full", "the job queue is full (%zu queued)",
                   vx_queue_depth(j->queue));
    } else if (vx_sorted_insert(&j->jobs, jb)) {
        vx_err_set(err, VX_EINTERNAL, "id_collision", "job id collision");
    } else if (journal_locked(j, jb, err)) {
        int found;
        vx_sorted_remove_at(&j->jobs, vx_sorted_find(&j->jobs, jb->id, &found));
    } else {
        /* Pushed under the lock, so capacity was checked atomically. */
        vx_queue_push(j->queue, jb, 1);
        out = job_json(j, jb, 1);
    }
    char jid[33];
    snprintf(jid, sizeof jid, "%s", jb->id); /* jb may be run and gone after the unlock */
    pthread_mutex_unlock(&j->lock);
    if (!out) {
        unpin_job(j, &jb->pins);
        job_free(jb);
        return NULL;
    }
    VX_INFO("job.queued", "job=%s kind=%s mesh=%.12s", jid, kind, mesh);
    /* Megabytes of params were parsed and printed here, in many small
     * blocks: hand the pages back rather than keep each thread's peak. */
    if (jb_blobs) malloc_trim(0);
    return out;
}

cJSON *vx_jobs_get(vx_jobs *j, const char *jid, int *terminal, vx_err *err)
{
    if (j->cl) return cluster_get(j, jid, terminal, err);
    pthread_mutex_lock(&j->lock);
    job *jb = vx_jobs_valid_id(jid) ? find_job(j, jid) : NULL;
    cJSON *out = jb ? job_json(j, jb, 1) : NULL;
    if (jb && terminal) *terminal = is_terminal(jb->state);
    pthread_mutex_unlock(&j->lock);
    if (!jb) vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job with id %.64s", jid);
    return out;
}

cJSON *vx_jobs_cancel(vx_jobs *j, const char *jid, int *was_running, vx_err *err)
{
    *was_running = 0;
    if (j->cl) return cluster_cancel(j, jid, was_running, err);
    char kind[64] = "";
    pinset pins = {0};
    char dropped[16][33];
    size_t nd = 0;
    pthread_mutex_lock(&j->lock);
    job *jb = vx_jobs_valid_id(jid) ? find_job(j, jid) : NULL;
    cJSON *out = NULL;
    int changed = 0;
    if (!jb) {
        vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job with id %.64s", jid);
    } else if (is_terminal(jb->state)) {
        vx_err_set(err, VX_ECONFLICT, "job_finished", "job %s already %s", jid,
                   state_names[jb->state]);
    } else if (jb->state == ST_QUEUED) {
        snprintf(kind, sizeof kind, "%s", jb->kind->name);
        vx_queue_remove(j->queue, jb);
        jb->state = ST_CANCELED;
        jb->finished = vx_now();
        jb->cancel_requested = 1;
        vx_err_set(&jb->error, VX_ECANCELED, "canceled", "canceled while queued");
        if (journal_locked(j, jb, err) == 0) {
            out = job_json(j, jb, 1);
            pins = jb->pins;
            memset(&jb->pins, 0, sizeof jb->pins);
            freeze_locked(j, jb);
            /* one more finished job: the history's limits hold (jb
             * itself may go, when it is the oldest) */
            trim_history_locked(j, dropped, &nd, 16);
            changed = 1;
        } else {
            /* Not recorded (a full disk: 507), so not done: the job stays
             * queued, as the journal and a restart would have it. */
            jb->state = ST_QUEUED;
            jb->finished = 0;
            jb->cancel_requested = 0;
            vx_err_clear(&jb->error);
            vx_queue_push(j->queue, jb, 1);
        }
    } else if (!jb->cancel_requested) {
        /* journaled: a restart before the job stops cancels it then */
        jb->cancel_requested = 1;
        if (journal_locked(j, jb, err) == 0) {
            *was_running = 1;
            out = job_json(j, jb, 1);
        } else {
            jb->cancel_requested = 0; /* not recorded (507): not acknowledged */
        }
    } else {
        *was_running = 1;
        out = job_json(j, jb, 1);
    }
    pthread_mutex_unlock(&j->lock);
    unpin_job(j, &pins);
    for (size_t i = 0; i < nd; i++)
        vx_store_result_remove(j->desc.store, dropped[i]);
    if (*was_running) jobs_cancel_waiting(j, jid);
    if (changed) {
        VX_INFO("job.finished", "job=%s state=canceled run_ms=0", jid);
        if (j->desc.hooks.finished)
            j->desc.hooks.finished(j->desc.hooks.ud, jid, kind, "canceled", -1);
        notify(j, jid, 1);
    }
    return out;
}

/* 1 when f keeps jb. */
static int kept(const vx_jobs_filter *f, const job *jb)
{
    return !f || ((!f->state || !strcmp(f->state, state_names[jb->state])) &&
                  (!f->kind || !strcmp(f->kind, jb->kind->name)) &&
                  (!f->mesh || !strcmp(f->mesh, jb->mesh)));
}

cJSON *vx_jobs_list(vx_jobs *j, const char *after, int limit, const vx_jobs_filter *f,
                    char next[40], vx_err *err)
{
    if (j->cl) return cluster_list(j, after, limit, f, next, err);
    cJSON *arr = cJSON_CreateArray();
    next[0] = 0;
    int desc = f && f->desc;
    pthread_mutex_lock(&j->lock);
    /* Ascending: from the first id above `after`. Descending: from the
     * last id below it (i counts down from n, one past the item). */
    size_t i;
    if (!desc) {
        i = vx_sorted_after(&j->jobs, after);
    } else if (after && *after) {
        int found;
        i = vx_sorted_find(&j->jobs, after, &found);
    } else {
        i = j->jobs.n;
    }
    int n = 0;
    const job *last = NULL;
    while (desc ? i > 0 : i < j->jobs.n) {
        job *jb = job_at(j, desc ? i - 1 : i);
        desc ? i-- : i++;
        if (!kept(f, jb)) continue;
        if (n == limit) {
            snprintf(next, 40, "%s", last->id);
            break;
        }
        cJSON_AddItemToArray(arr, job_json(j, jb, 1));
        last = jb;
        n++;
    }
    pthread_mutex_unlock(&j->lock);
    return arr;
}

int vx_jobs_has_kind(vx_jobs *j, const char *kind)
{
    return vx_kinds_find(j->desc.kinds, kind) != NULL;
}

int vx_jobs_delete(vx_jobs *j, const char *jid, vx_err *err)
{
    if (j->cl) return cluster_delete(j, jid, err);
    pthread_mutex_lock(&j->lock);
    int found = 0;
    size_t at = vx_jobs_valid_id(jid) ? vx_sorted_find(&j->jobs, jid, &found) : 0;
    job *jb = found ? job_at(j, at) : NULL;
    int rc = -1;
    if (!jb) {
        vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job with id %.64s", jid);
    } else if (!is_terminal(jb->state)) {
        vx_err_set(err, VX_ECONFLICT, "job_not_finished", "job %s is %s", jid,
                   state_names[jb->state]);
    } else if (journal_delete_locked(j, jb, err) == 0) {
        vx_sorted_remove_at(&j->jobs, at);
        j->history_bytes -= jb->bytes;
        job_free(jb);
        rc = 0;
    }
    pthread_mutex_unlock(&j->lock);
    /* After the tombstone: a crash in between leaves files no job names,
     * which the results budget and the next start clean up. */
    if (rc == 0) {
        vx_store_result_remove(j->desc.store, jid);
        VX_INFO("job.deleted", "job=%s", jid);
    }
    return rc;
}

const cJSON *job_output_entry(const char *jid, const char *state, const char *failure,
                              const cJSON *outputs, const char *name, char file[160],
                              char ctype[64], vx_err *err)
{
    if (!strcmp(state, "queued") || !strcmp(state, "running")) {
        vx_err_set(err, VX_ECONFLICT, "job_not_finished", "job %s is %s", jid, state);
        return NULL;
    }
    if (!strcmp(state, "failed")) {
        vx_err_set(err, VX_ECONFLICT, "job_failed", "job %s failed: %s", jid, failure);
        return NULL;
    }
    if (!strcmp(state, "canceled")) {
        vx_err_set(err, VX_ECONFLICT, "job_canceled", "job %s was canceled", jid);
        return NULL;
    }
    const cJSON *o =
        name ? cJSON_GetObjectItemCaseSensitive(outputs, name) : (outputs ? outputs->child : NULL);
    if (!o && !name) {
        vx_err_set(err, VX_ENOTFOUND, "output_not_found",
                   "job %s wrote no file (a summary): its results are the job's stats", jid);
        return NULL;
    }
    if (!o) {
        vx_err_set(err, VX_ENOTFOUND, "output_not_found", "job %s has no output '%.64s'", jid,
                   name);
        return NULL;
    }
    snprintf(file, 160, "%s",
             cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "file")) ?: "");
    snprintf(ctype, 64, "%s",
             cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "content_type"))
                 ?: "application/octet-stream");
    return o;
}

int job_output_check_size(const char *jid, const char *path, double want, vx_err *err)
{
    struct stat st;
    if (stat(path, &st) != 0) /* in its dir, gone (removed behind the daemon) */
        return errno == ENOENT
                   ? vx_err_set(err, VX_EGONE, "result_evicted",
                                "the result file of job %s is gone: run the job again", jid)
                   : 0;
    if (!(want >= 0) || (double)st.st_size == want) return 0;
    VX_ERROR("job.result_damaged", "job=%s bytes=%lld want=%.0f", jid, (long long)st.st_size, want);
    return vx_err_set(err, VX_EGONE, "result_damaged",
                      "the result file is not the one job %s wrote (%lld of %.0f bytes); run the "
                      "job again",
                      jid, (long long)st.st_size, want);
}

int vx_jobs_output(vx_jobs *j, const char *jid, const char *name, char *path, size_t pathn,
                   char ctype[64], char fname[128], vx_err *err)
{
    if (j->cl) return cluster_output(j, jid, name, path, pathn, ctype, fname, err);
    char file[160] = {0}, id[33];
    double want = -1;
    pthread_mutex_lock(&j->lock);
    job *jb = vx_jobs_valid_id(jid) ? find_job(j, jid) : NULL;
    int rc = -1;
    if (!jb) {
        vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job with id %.64s", jid);
    } else {
        cJSON *outputs = NULL;
        if (jb->state == ST_SUCCEEDED) job_parts(jb, NULL, NULL, &outputs);
        const cJSON *o = job_output_entry(jid, state_names[jb->state], jb->error.message, outputs,
                                          name, file, ctype, err);
        if (o) {
            const cJSON *b = cJSON_GetObjectItemCaseSensitive(o, "bytes");
            if (cJSON_IsNumber(b)) want = b->valuedouble;
            snprintf(fname, 128, "%s-%s", jb->id, file);
            snprintf(id, sizeof id, "%s", jb->id);
            rc = 0;
        }
        cJSON_Delete(outputs);
    }
    pthread_mutex_unlock(&j->lock);
    if (rc) return rc;
    if (vx_store_result_file(j->desc.store, id, file, path, pathn, err)) return -1;
    return job_output_check_size(id, path, want, err);
}

int vx_jobs_ready(vx_jobs *j)
{
    pthread_mutex_lock(&j->lock);
    int up = j->gl_state == 1 && !j->stopping;
    pthread_mutex_unlock(&j->lock);
    return up;
}

vx_gl_info vx_jobs_gl_info(vx_jobs *j)
{
    pthread_mutex_lock(&j->lock);
    vx_gl_info i = j->gl_info;
    pthread_mutex_unlock(&j->lock);
    return i;
}

size_t vx_jobs_queue_depth(vx_jobs *j)
{
    long q = j->cl ? cluster_queued(j) : -1;
    return q >= 0 ? (size_t)q : vx_queue_depth(j->queue);
}

size_t vx_jobs_queue_capacity(vx_jobs *j)
{
    return vx_queue_capacity(j->queue);
}

uint64_t vx_jobs_gl_losses(vx_jobs *j)
{
    return __atomic_load_n(&j->gl_losses, __ATOMIC_RELAXED);
}

size_t vx_jobs_running(vx_jobs *j)
{
    pthread_mutex_lock(&j->lock);
    size_t n = j->running;
    pthread_mutex_unlock(&j->lock);
    return n;
}
