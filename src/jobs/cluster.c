/* Cluster mode (jobs.h, desc.database): the job table and its queue live in
 * PostgreSQL (pg.h), shared by every replica; this replica's own table
 * holds only the jobs it has claimed and not yet finished.
 *
 *   submit    normalised as in local mode, then INSERTed: acknowledged only
 *             once PostgreSQL has committed it (vx_pg_submit);
 *   claim     the claimer thread takes the oldest runnable job of a kind
 *             this replica runs (FOR UPDATE SKIP LOCKED) whenever the GL
 *             thread is free, one at a time, and queues it locally;
 *   lease     the renewer thread (its own connection, never the GL thread)
 *             renews every claimed job's lease every third of its TTL,
 *             writing its progress; a lease that moved on (this replica
 *             stalled past it) stops the run, a cancel request cancels it;
 *             it also re-queues any replica's expired leases;
 *   finish    the runner reports through cluster_report: results in the
 *             store under results/JOB/ATTEMPT, then one fenced UPDATE (a
 *             stale attempt changes nothing and its results are removed);
 *   wake      the listener thread LISTENs on the jobs channel: a queued job
 *             wakes the claimer, a state change wakes ?wait and event
 *             streams (jobs hooks.changed), a cancel reaches the run; every
 *             wait also times out (1 s), the polling fallback.
 * The API reads (get, list) come from the database; a job running here
 * shows its live progress. Connections: api (HTTP threads), work (claims,
 * reports), lease (renewals), listen. */
#include "jobs/jobs_int.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "util/clock.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/stop.h"

typedef struct vx_cluster vx_cluster;

struct vx_cluster {
    vx_pg *api, *work, *lease, *listen;
    pthread_t claimer, renewer, listener;
    int nthreads;
    pthread_mutex_t lock; /* after j->lock, never before */
    pthread_cond_t cond;  /* on CLOCK_MONOTONIC: wakes the claimer and the renewer */
    int wake;
    int stopping;
    char kinds[1024]; /* comma-separated: what the claimer asks for */
    double renew_s;
    vx_jobs_cluster_stats stats; /* atomics */
    vx_mesh_catalog catalog;     /* the store's view of meshes: vx_meshes */
    /* Completions whose answer never came (the database out past the
     * report's patience, or the row no longer ours meanwhile): they may
     * have committed, so their results stay until the database says whose
     * the row is (check_unsure, by the renewer). Under lock. */
    struct unsure {
        char id[33];
        int attempt;
        char rid[48];
    } unsure[64];
    int nunsure;
};

/* ---- a job state that keeps nothing: the database is the state ---------- */

static void *none_open(const char *where, vx_err *err)
{
    (void)where;
    (void)err;
    static int handle;
    return &handle;
}

static void none_close(void *st)
{
    (void)st;
}

static long none_replay(void *st, void (*fn)(const cJSON *rec, void *ud), void *ud, vx_err *err)
{
    (void)st, (void)fn, (void)ud, (void)err;
    return 0;
}

static int none_append(void *st, const cJSON *rec, size_t owed, vx_err *err)
{
    (void)st, (void)rec, (void)owed, (void)err;
    return 0;
}

static int none_compact(void *st, cJSON *const *recs, size_t n, vx_err *err)
{
    (void)st, (void)recs, (void)n, (void)err;
    return 0;
}

static long none_size(void *st)
{
    (void)st;
    return -1;
}

const vx_jobstate_ops cluster_state = {.name = "database",
                                       .open = none_open,
                                       .close = none_close,
                                       .replay = none_replay,
                                       .append = none_append,
                                       .compact = none_compact,
                                       .size = none_size};

/* ---- life --------------------------------------------------------------- */

static void nap(double s)
{
    struct timespec ts = {(time_t)s, (long)((s - (double)(time_t)s) * 1e9)};
    nanosleep(&ts, NULL);
}

/* Waits on c->cond up to s seconds or until woken; c->lock held. */
static void wait_locked(vx_cluster *c, double s)
{
    if (!c->wake && !c->stopping) {
        struct timespec ts;
        vx_mono_deadline(s, &ts);
        pthread_cond_timedwait(&c->cond, &c->lock, &ts);
    }
    c->wake = 0;
}

void cluster_wake(vx_jobs *j)
{
    vx_cluster *c = j->cl;
    if (!c) return;
    pthread_mutex_lock(&c->lock);
    c->wake = 1;
    pthread_cond_broadcast(&c->cond);
    pthread_mutex_unlock(&c->lock);
}

/* ---- the mesh catalog: vx_meshes, through the API's connection ----------- */

static int cat_lock(void *ud, const char *id, vx_err *err)
{
    return vx_pg_mesh_lock(ud, id, err);
}

static void cat_unlock(void *ud, const char *id)
{
    vx_pg_mesh_unlock(ud, id);
}

static int cat_put(void *ud, const char *id, const cJSON *meta, int *existed, vx_err *err)
{
    return vx_pg_mesh_put(ud, id, meta, existed, NULL, err);
}

static int cat_get(void *ud, const char *id, cJSON **meta, vx_err *err)
{
    return vx_pg_mesh_get(ud, id, meta, err);
}

static int cat_remove(void *ud, const char *id, vx_err *err)
{
    return vx_pg_mesh_delete(ud, id, err);
}

static cJSON *cat_list(void *ud, const char *after, int limit, char next[65], vx_err *err)
{
    return vx_pg_mesh_list(ud, after, limit, next, err);
}

static long cat_count(void *ud, vx_err *err)
{
    return vx_pg_mesh_count(ud, err);
}

static int purge_bytes(void *ud, const char *id, const char *format)
{
    return vx_store_mesh_purge(ud, id, format);
}

/* The catalog takes over the store's view of meshes, after adding the
 * meshes the store holds that it lacks (stored before the catalog was). */
static int catalog_start(vx_jobs *j, vx_err *err)
{
    vx_cluster *c = j->cl;
    cJSON *all = vx_store_mesh_local(j->desc.store), *batch = cJSON_CreateArray();
    int added = 0, rc = 0, left = cJSON_GetArraySize(all), inbatch = 0;
    while (!rc && all && batch && left > 0) {
        cJSON_AddItemToArray(batch, cJSON_DetachItemFromArray(all, 0));
        left--;
        if (++inbatch < 1000 && left > 0) continue;
        inbatch = 0;
        int n = vx_pg_mesh_add_missing(c->api, batch, err);
        if (n < 0) rc = -1;
        added += n > 0 ? n : 0;
        cJSON_Delete(batch);
        batch = cJSON_CreateArray();
    }
    if (!all || !batch) rc = vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    cJSON_Delete(all);
    cJSON_Delete(batch);
    if (rc) return -1;
    if (added) VX_INFO("cluster.meshes_cataloged", "added=%d", added);
    c->catalog = (vx_mesh_catalog){.ud = c->api,
                                   .lock = cat_lock,
                                   .unlock = cat_unlock,
                                   .put = cat_put,
                                   .get = cat_get,
                                   .remove = cat_remove,
                                   .list = cat_list,
                                   .count = cat_count};
    vx_store_set_catalog(j->desc.store, &c->catalog);
    return 0;
}

/* vx_pg_store_id's check: the replica's blob store must be the one the
 * cluster's database names (an id written into the store by the first
 * replica). A replica given another store (its data dir, another bucket)
 * claimed jobs whose bytes it could not read. */
static int store_id_check(void *ud, const char *have, char out[VX_PG_STORE_ID], vx_err *err)
{
    vx_store *s = ud;
    char mark[65] = "";
    vx_err e;
    vx_err_clear(&e);
    int got = vx_store_id_read(s, mark, &e);
    if (got < 0) { /* an outage: not the place to decide; uses will tell */
        VX_WARN("cluster.store_id_unread", "code=%s", e.code);
        return 1;
    }
    if (got && have && strcmp(mark, have) != 0)
        return vx_err_set(err, VX_ECONFLICT, "blob_store_mismatch",
                          "the blob store (--blob-store) belongs to another cluster: its id is "
                          "%.64s, the database's %.64s (every replica needs the same store)",
                          mark, have);
    if (!got && have)
        return vx_err_set(err, VX_ECONFLICT, "blob_store_mismatch",
                          "the blob store (--blob-store) is not the cluster's: it holds no "
                          "id, the database's is %.64s (every replica needs the same store)",
                          have);
    if (got) {
        snprintf(out, VX_PG_STORE_ID, "%s", mark);
        return 0;
    }
    /* The first replica of a cluster: the id goes into the store first,
     * then (the caller) into the database. */
    unsigned char r[16];
    if (getrandom(r, sizeof r, 0) != (ssize_t)sizeof r)
        return vx_err_set(err, VX_EINTERNAL, "random_failed", "no random bytes for the store id");
    for (int i = 0; i < 16; i++)
        snprintf(out + 2 * i, 3, "%02x", r[i]);
    if (vx_store_id_write(s, out, err)) return -1;
    VX_INFO("cluster.store_id", "id=%s action=written", out);
    return 0;
}

#define API_LOCK_WAIT_S 2.0

int cluster_open(vx_jobs *j, vx_err *err)
{
    vx_cluster *c = calloc(1, sizeof *c);
    if (!c) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    pthread_mutex_init(&c->lock, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&c->cond, &ca);
    pthread_condattr_destroy(&ca);
    j->cl = c;
    vx_pg_desc d = *j->desc.database;
    d.replica = j->replica;
    /* A database that is not up yet (replicas and PostgreSQL starting
     * together): wait for it a while, then give up (the service manager
     * restarts the daemon). */
    double ct = vx_pg_url_connect_timeout(d.url);
    if (ct <= 0) ct = d.connect_timeout_s;
    double give_up = vx_mono() + (ct > 0 ? 6 * ct : 30);
    /* HTTP threads share the API handle: one that waits on a database
     * that does not answer (up to the statement timeout) holds the others
     * back 2 s at most, so some thread is left for /livez */
    vx_pg_desc api = d;
    api.lock_wait_s = API_LOCK_WAIT_S;
    for (;;) {
        vx_err_clear(err);
        c->api = vx_pg_open(&api, err);
        if (c->api && vx_pg_migrate(c->api, err) >= 0 &&
            vx_pg_store_id(c->api, store_id_check, j->desc.store, err) == 0)
            break;
        vx_pg_close(c->api);
        c->api = NULL;
        if (err->kind != VX_EUNAVAIL || vx_mono() > give_up) return -1;
        VX_WARN("cluster.database_wait", "code=%s", err->code);
        /* a second between tries; a stop (SIGTERM at start-up) ends it */
        for (int i = 0; i < 20; i++) {
            if (vx_stop_poll(err)) return -1;
            nap(0.05);
        }
    }
    if (!(c->work = vx_pg_open(&d, err)) || !(c->lease = vx_pg_open(&d, err)) ||
        !(c->listen = vx_pg_open(&d, err)) || vx_pg_listen(c->listen, err) || catalog_start(j, err))
        return -1;
    size_t n = 0;
    for (size_t i = 0; i < j->desc.kinds->n && n + 1 < sizeof c->kinds; i++)
        n += (size_t)snprintf(c->kinds + n, sizeof c->kinds - n, "%s%s", n ? "," : "",
                              j->desc.kinds->rows[i]->name);
    c->renew_s = vx_pg_renew_interval(c->lease);
    VX_INFO("cluster.open", "replica=%s kinds=%s renew_s=%.1f", VX_Q(j->replica), c->kinds,
            c->renew_s);
    return 0;
}

static void *claimer_main(void *arg);
static void *renewer_main(void *arg);
static void *listener_main(void *arg);

int cluster_start(vx_jobs *j, vx_err *err)
{
    vx_cluster *c = j->cl;
    pthread_t *t[3] = {&c->claimer, &c->renewer, &c->listener};
    void *(*fn[3])(void *) = {claimer_main, renewer_main, listener_main};
    for (int i = 0; i < 3; i++) {
        if (pthread_create(t[i], NULL, fn[i], j))
            return vx_err_set(err, VX_EINTERNAL, "thread_failed", "cannot start cluster threads");
        c->nthreads = i + 1;
    }
    return 0;
}

void cluster_stop_claims(vx_jobs *j)
{
    vx_cluster *c = j->cl;
    if (!c || !c->nthreads) return;
    pthread_mutex_lock(&c->lock);
    c->stopping = 1;
    pthread_cond_broadcast(&c->cond);
    pthread_mutex_unlock(&c->lock);
    /* The claimer first: nothing new is claimed while the runs end. */
    pthread_join(c->claimer, NULL);
}

/* A claimed job that never started goes back to the queue as it was. */
static void release_one(vx_jobs *j, job *jb)
{
    vx_err err;
    if (vx_pg_release(j->cl->work, jb->id, jb->attempts, &err) < 0)
        VX_WARN("cluster.release_failed", "job=%s code=%s", jb->id, err.code);
    else
        VX_INFO("job.requeued", "job=%s kind=%s reason=shutdown", jb->id, jb->kind->name);
}

void cluster_release_queued(vx_jobs *j)
{
    vx_cluster *c = j->cl;
    if (!c) return;
    pthread_mutex_lock(&j->lock);
    size_t w = 0;
    for (size_t i = 0; i < j->jobs.n; i++) {
        job *jb = job_at(j, i);
        if (jb->state == ST_QUEUED) {
            vx_queue_remove(j->queue, jb);
            release_one(j, jb);
            unpin_job(j, &jb->pins);
            job_free(jb);
            continue;
        }
        j->jobs.items[w++] = jb;
    }
    j->jobs.n = w;
    pthread_mutex_unlock(&j->lock);
    /* The runs have ended: the renewer and the listener go too. */
    if (c->nthreads >= 2) pthread_join(c->renewer, NULL);
    if (c->nthreads >= 3) pthread_join(c->listener, NULL);
    c->nthreads = 0;
}

void cluster_free(vx_jobs *j)
{
    vx_cluster *c = j->cl;
    if (!c) return;
    if (c->catalog.ud) vx_store_set_catalog(j->desc.store, NULL);
    vx_pg_close(c->api);
    vx_pg_close(c->work);
    vx_pg_close(c->lease);
    vx_pg_close(c->listen);
    pthread_mutex_destroy(&c->lock);
    pthread_cond_destroy(&c->cond);
    free(c);
    j->cl = NULL;
}

/* ---- job resources from rows ---------------------------------------------- */

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

static int row_terminal(const vx_pg_job *row)
{
    return !strcmp(row->state, "succeeded") || !strcmp(row->state, "failed") ||
           !strcmp(row->state, "canceled");
}

/* The API resource of a row (the shape job_json gives in local mode, with
 * attempt and replica); a job running here shows its live progress. */
static cJSON *row_json(vx_jobs *j, const vx_pg_job *row, int live)
{
    double progress = row->progress;
    if (live && row->children > 0 && !strcmp(row->state, "queued")) {
        /* waiting for its child jobs: their share of the work (the merge
         * comes after) */
        int done = 0, total = 0;
        vx_err e;
        if (vx_pg_child_counts(j->cl->api, row->id, &done, &total, &e) == 0 && total > 0)
            progress = 0.9 * done / total;
    }
    if (!strcmp(row->state, "running")) {
        pthread_mutex_lock(&j->lock);
        job *jb = find_job(j, row->id);
        if (jb && jb->attempts == row->attempt && jb->progress > progress) progress = jb->progress;
        pthread_mutex_unlock(&j->lock);
    }
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "id", row->id);
    cJSON_AddStringToObject(o, "kind", row->kind);
    cJSON_AddStringToObject(o, "mesh", row->mesh);
    cJSON_AddItemToObject(o, "params",
                          row->params ? cJSON_Duplicate(row->params, 1) : cJSON_CreateObject());
    cJSON_AddStringToObject(o, "state", row->state);
    cJSON_AddNumberToObject(o, "progress", progress);
    cJSON_AddBoolToObject(o, "cancel_requested", row->cancel_requested);
    cJSON_AddNumberToObject(o, "attempts", row->attempt);
    cJSON_AddNumberToObject(o, "attempt", row->attempt);
    if (row->children > 0) cJSON_AddNumberToObject(o, "child_jobs", row->children);
    if (row->parent[0]) cJSON_AddStringToObject(o, "parent", row->parent);
    if (row->replica[0])
        cJSON_AddStringToObject(o, "replica", row->replica);
    else
        cJSON_AddNullToObject(o, "replica");
    /* queued again for a later attempt: not started, as the contract says
     * of a queued job (the row keeps the last attempt's start) */
    const double started = strcmp(row->state, "queued") ? row->started : 0;
    add_time(o, "created", row->created);
    add_time(o, "started", started);
    add_time(o, "finished", row->finished);
    /* The last attempt's error, for a job that ended without success. */
    const cJSON *last = NULL, *it;
    cJSON_ArrayForEach(it, row->errors) last = it;
    if (!strcmp(row->state, "failed") || !strcmp(row->state, "canceled")) {
        cJSON *e = cJSON_AddObjectToObject(o, "error");
        const char *code = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(last, "code"));
        const char *msg = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(last, "message"));
        int canceled = !strcmp(row->state, "canceled");
        if (canceled && (!code || strcmp(code, "canceled"))) {
            /* started is the last attempt's: one that ended in an error
             * left the job queued for its retry */
            const cJSON *la = cJSON_GetObjectItemCaseSensitive(last, "attempt");
            int retrying = cJSON_IsNumber(la) && la->valuedouble == row->attempt;
            code = "canceled";
            msg =
                row->started > 0 && !retrying ? "canceled while running" : "canceled while queued";
        }
        cJSON_AddStringToObject(e, "code", code ? code : "failed");
        cJSON_AddStringToObject(e, "message", msg ? msg : "");
    } else {
        cJSON_AddNullToObject(o, "error");
    }
    if (row->errors && cJSON_GetArraySize(row->errors) > 0)
        cJSON_AddItemToObject(o, "attempt_errors", cJSON_Duplicate(row->errors, 1));
    cJSON *t = cJSON_AddObjectToObject(o, "timings");
    double now = vx_now(), end = row->finished > 0 ? row->finished : now;
    cJSON_AddNumberToObject(t, "queue_ms", ms_between(row->created, started > 0 ? started : end));
    if (started > 0)
        cJSON_AddNumberToObject(t, "run_ms", ms_between(started, end));
    else
        cJSON_AddNullToObject(t, "run_ms");
    if (row->finished > 0)
        cJSON_AddNumberToObject(t, "total_ms", ms_between(row->created, row->finished));
    else
        cJSON_AddNullToObject(t, "total_ms");
    const cJSON *stats = cJSON_GetObjectItemCaseSensitive(row->result, "stats");
    cJSON_AddItemToObject(o, "stats",
                          cJSON_IsObject(stats) ? cJSON_Duplicate(stats, 1) : cJSON_CreateObject());
    cJSON *outs = cJSON_AddObjectToObject(o, "outputs");
    const cJSON *outputs = cJSON_GetObjectItemCaseSensitive(row->result, "outputs");
    if (!strcmp(row->state, "succeeded")) cJSON_ArrayForEach(it, outputs)
        {
            char url[256];
            snprintf(url, sizeof url, "/v1/jobs/%s/result/%s", row->id, it->string);
            cJSON_AddStringToObject(outs, it->string, url);
        }
    return o;
}

/* ---- the API ---------------------------------------------------------------- */

/* The kind's split of a submission (kind.h): *kids = the child jobs'
 * normalised params, or NULL when it runs as one. */
static int split(vx_jobs *j, const char *mesh, const vx_kind *k, const cJSON *params, cJSON **kids,
                 vx_err *err)
{
    *kids = NULL;
    void *typed = vx_kind_read(k, params, &j->desc.limits, err);
    if (!typed) return -1;
    cJSON *meta = vx_store_mesh_meta(j->desc.store, mesh, err);
    vx_err_clear(err);
    cJSON *raw = meta ? k->split(typed, meta, &j->desc.limits, err) : NULL;
    cJSON_Delete(meta);
    vx_kind_params_free(k, typed);
    if (!raw) return err->kind == VX_EOK ? 0 : -1;
    cJSON *norm = cJSON_CreateArray(), *it;
    cJSON_ArrayForEach(it, raw)
    {
        cJSON *n = vx_params_normalize(k, it, &j->desc.limits, err);
        if (!n || !cJSON_AddItemToArray(norm, n)) {
            cJSON_Delete(n);
            cJSON_Delete(norm);
            cJSON_Delete(raw);
            if (err->kind == VX_EOK) vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
            return -1;
        }
    }
    cJSON_Delete(raw);
    *kids = norm;
    return 0;
}

/* Submits parent (children set here) and its child jobs in one transaction:
 * 0 committed; 1 the parent's Idempotency-Key was taken by the same request
 * (*existing filled); -1 with err. */
static int submit_split(vx_jobs *j, vx_pg_new_job *parent, const cJSON *kids, vx_pg_job *existing,
                        vx_err *err)
{
    vx_cluster *c = j->cl;
    size_t n = (size_t)cJSON_GetArraySize(kids);
    vx_pg_new_job *all = calloc(n + 1, sizeof *all);
    char(*ids)[33] = calloc(n + 1, sizeof *ids);
    char(*fps)[17] = calloc(n + 1, sizeof *fps);
    if (!all || !ids || !fps) {
        free(all), free(ids), free(fps);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    }
    all[0] = *parent;
    all[0].children = (int)n;
    size_t i = 1;
    const cJSON *it;
    cJSON_ArrayForEach(it, kids)
    {
        jobs_new_id(ids[i]);
        snprintf(fps[i], sizeof fps[i], "%016llx",
                 (unsigned long long)request_fp(parent->kind, parent->mesh, it));
        all[i] = (vx_pg_new_job){.id = ids[i],
                                 .kind = parent->kind,
                                 .mesh = parent->mesh,
                                 .parent = parent->id,
                                 .params = it,
                                 .fp = fps[i]};
        i++;
    }
    int rc = vx_pg_submit(c->api, all, n + 1, err);
    free(all), free(ids), free(fps);
    if (rc == 0) return 0;
    if (err->kind != VX_ECONFLICT || !parent->idem) return -1;
    /* The key was taken: by the same request, or by another. */
    vx_err_clear(err);
    int got = vx_pg_find_idem(c->api, parent->idem, existing, err);
    if (got <= 0) return got < 0 ? -1 : vx_err_set(err, VX_ECONFLICT, "job_exists", "id taken");
    if (strcmp(existing->fp, parent->fp ? parent->fp : "")) {
        vx_pg_job_clear(existing);
        return vx_err_set(err, VX_EUNPROC, "idempotency_key_reused",
                          "the Idempotency-Key was used for another request");
    }
    return 1;
}

static int row_output(vx_jobs *j, const vx_pg_job *row, const char *name, char *path, size_t pathn,
                      char ctype[64], char fname[128], vx_err *err);

cJSON *cluster_find_idem(vx_jobs *j, const char *key, uint64_t fp)
{
    char fps[17];
    snprintf(fps, sizeof fps, "%016llx", (unsigned long long)fp);
    vx_pg_job row;
    memset(&row, 0, sizeof row);
    vx_err err;
    vx_err_clear(&err);
    cJSON *out = NULL;
    if (vx_pg_find_idem(j->cl->api, key, &row, &err) > 0 && !strcmp(row.fp, fps))
        out = row_json(j, &row, 1);
    vx_pg_job_clear(&row);
    return out;
}

cJSON *cluster_submit(vx_jobs *j, const char *mesh, const vx_kind *k, cJSON *params, uint64_t fp,
                      const vx_jobs_submit_opts *opts, int *existing, vx_err *err)
{
    vx_cluster *c = j->cl;
    char fps[17];
    snprintf(fps, sizeof fps, "%016llx", (unsigned long long)fp);
    vx_pg_job row;
    memset(&row, 0, sizeof row);
    cJSON *out = NULL;
    int got = 0;
    if (opts && opts->reuse && !(opts->idempotency_key && *opts->idempotency_key)) {
        got = vx_pg_find_done(c->api, fps, &row, err);
        if (got < 0) return NULL;
        const cJSON *outs = cJSON_GetObjectItemCaseSensitive(row.result, "outputs"), *o;
        if (got && cJSON_IsObject(outs) && outs->child) {
            /* only a job whose results are still there (every output, at
             * the size it was written; else a new job) */
            char path[VX_PATH_MAX], ct[64], fn[128];
            vx_err oerr = {0};
            int bad = 0;
            cJSON_ArrayForEach(o, outs)
            {
                if (o->string && row_output(j, &row, o->string, path, sizeof path, ct, fn, &oerr)) {
                    bad = 1;
                    break;
                }
            }
            if (bad) {
                got = 0;
                vx_pg_job_clear(&row);
                if (oerr.kind != VX_EGONE) {
                    *err = oerr;
                    return NULL;
                }
            }
        }
        if (got) {
            *existing = 1;
            out = row_json(j, &row, 1);
            vx_pg_job_clear(&row);
            return out;
        }
    }
    if (j->stopping) {
        vx_err_set(err, VX_EUNAVAIL, "not_ready", "the daemon is shutting down");
        return NULL;
    }
    long queued = vx_pg_queued(c->api, err);
    if (queued < 0) return NULL;
    if ((size_t)queued >= vx_queue_capacity(j->queue)) {
        vx_err_set(err, VX_EBUSY, "queue_full", "the job queue is full (%ld queued)", queued);
        return NULL;
    }
    char id[33];
    jobs_new_id(id);
    vx_pg_new_job nj = {.id = id,
                        .kind = k->name,
                        .mesh = mesh,
                        .params = params,
                        .fp = fps,
                        .idem = opts ? opts->idempotency_key : NULL};
    cJSON *kids = NULL;
    if (k->split && split(j, mesh, k, params, &kids, err)) return NULL;
    /* a split job queues its children with it: they count against the
     * queue's capacity (25,600 bricks had gone in past a limit of 64) */
    long nkids = kids ? (long)cJSON_GetArraySize(kids) : 0;
    if (nkids && (size_t)nkids + 1 > vx_queue_capacity(j->queue)) {
        cJSON_Delete(kids);
        vx_err_set(err, VX_EUNPROC, "invalid_params",
                   "params.bricks makes %ld bricks, each a job, and the job itself: %ld, more "
                   "than the queue holds (max_queued_jobs %zu); use larger bricks, or a larger "
                   "--max-queued-jobs",
                   nkids, nkids + 1, vx_queue_capacity(j->queue));
        return NULL;
    }
    if (nkids && (size_t)(queued + 1 + nkids) > vx_queue_capacity(j->queue)) {
        cJSON_Delete(kids);
        vx_err_set(err, VX_EBUSY, "queue_full",
                   "the job queue is full: %ld queued, and this job queues %ld bricks with it",
                   queued, nkids);
        return NULL;
    }
    if (kids) {
        got = submit_split(j, &nj, kids, &row, err);
        cJSON_Delete(kids);
    } else {
        got = vx_pg_submit_idem(c->api, &nj, &row, err);
    }
    if (got < 0) return NULL;
    if (got == 1) {
        *existing = 1;
    } else if (!vx_pg_get(c->api, id, &row, err)) {
        /* The 202 answers the job as committed, queued: a replica may have
         * claimed it between the commit and this read. */
        if (!strcmp(row.state, "running")) {
            snprintf(row.state, sizeof row.state, "queued");
            row.replica[0] = 0;
            row.attempt = 0;
            row.started = row.lease_expires = row.progress = 0;
        }
    } else {
        /* Committed, but not read back: answer from what was sent. */
        snprintf(row.id, sizeof row.id, "%s", id);
        snprintf(row.kind, sizeof row.kind, "%s", k->name);
        snprintf(row.mesh, sizeof row.mesh, "%s", mesh);
        snprintf(row.state, sizeof row.state, "queued");
        row.created = vx_now();
        row.params = cJSON_Duplicate(params, 1);
        vx_err_clear(err);
    }
    out = row_json(j, &row, 1);
    vx_pg_job_clear(&row);
    if (!*existing) VX_INFO("job.queued", "job=%s kind=%s mesh=%.12s", id, k->name, mesh);
    return out;
}

cJSON *cluster_get(vx_jobs *j, const char *jid, int *terminal, vx_err *err)
{
    vx_pg_job row;
    if (vx_pg_get(j->cl->api, jid, &row, err)) return NULL;
    if (terminal) *terminal = row_terminal(&row);
    cJSON *o = row_json(j, &row, 1);
    vx_pg_job_clear(&row);
    return o;
}

/* A claimed job's local cancel: running, it stops at its next progress
 * check; still queued here, it ends now. */
static void cancel_local(vx_jobs *j, const char *jid);

cJSON *cluster_cancel(vx_jobs *j, const char *jid, int *was_running, vx_err *err)
{
    if (vx_pg_cancel(j->cl->api, jid, was_running, err)) return NULL;
    if (*was_running) {
        cancel_local(j, jid);
        jobs_cancel_waiting(j, jid); /* one waiting for a CPU worker ends now */
    }
    return cluster_get(j, jid, NULL, err);
}

cJSON *cluster_list(vx_jobs *j, const char *after, int limit, const vx_jobs_filter *f,
                    char next[40], vx_err *err)
{
    vx_pg_filter pf = {0};
    if (f) {
        pf.state = f->state;
        pf.kind = f->kind;
        pf.mesh = f->mesh;
        pf.desc = f->desc;
    }
    vx_pg_job *rows = NULL;
    size_t n = 0;
    char nx[33];
    next[0] = 0;
    if (vx_pg_list(j->cl->api, &pf, after, limit, &rows, &n, nx, err)) return NULL;
    cJSON *arr = cJSON_CreateArray();
    for (size_t i = 0; i < n; i++)
        cJSON_AddItemToArray(arr, row_json(j, &rows[i], 0));
    snprintf(next, 40, "%s", nx);
    vx_pg_jobs_free(rows, n);
    return arr;
}

static cJSON *children_of(vx_jobs *j, vx_pg *pg, const char *id, vx_err *err);

int cluster_delete(vx_jobs *j, const char *jid, vx_err *err)
{
    vx_pg_job row;
    if (vx_pg_get(j->cl->api, jid, &row, err)) return -1;
    int children = row.children;
    char parent[33];
    snprintf(parent, sizeof parent, "%s", row.parent);
    vx_pg_job_clear(&row);
    if (parent[0] && !vx_pg_get(j->cl->api, parent, &row, NULL)) {
        /* its files are its parent's outputs (a brick of a bricked voxelize) */
        vx_pg_job_clear(&row);
        return vx_err_set(err, VX_ECONFLICT, "job_has_parent",
                          "job %s is a part of job %s: deleting that deletes it", jid, parent);
    }
    /* the rows of its children go with it (ON DELETE CASCADE), their files here */
    cJSON *kids = children > 0 ? children_of(j, j->cl->api, jid, err) : NULL;
    if (children > 0 && !kids) return -1;
    if (vx_pg_delete(j->cl->api, jid, err)) {
        cJSON_Delete(kids);
        return -1;
    }
    /* every attempt's files and the job's own dir (a dir per job had been
     * left behind, empty, at each delete) */
    vx_store_result_remove(j->desc.store, jid);
    const cJSON *it;
    cJSON_ArrayForEach(it, kids)
    {
        const char *kid = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "id"));
        if (kid) vx_store_result_remove(j->desc.store, kid);
    }
    cJSON_Delete(kids);
    VX_INFO("job.deleted", "job=%s children=%d", jid, children > 0 ? children : 0);
    return 0;
}

/* Output name (NULL: the primary) of the job in row: its file in path,
 * checked to be there at the size it was written, or -1 with err. */
static int row_output(vx_jobs *j, const vx_pg_job *row, const char *name, char *path, size_t pathn,
                      char ctype[64], char fname[128], vx_err *err)
{
    char file[160] = "", rid[48];
    const cJSON *last = NULL, *it;
    cJSON_ArrayForEach(it, row->errors) last = it;
    const cJSON *o = job_output_entry(
        row->id, row->state,
        cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(last, "message")) ?: "unknown error",
        cJSON_GetObjectItemCaseSensitive(row->result, "outputs"), name, file, ctype, err);
    if (!o) return -1;
    double want = -1;
    const cJSON *b = cJSON_GetObjectItemCaseSensitive(o, "bytes");
    if (cJSON_IsNumber(b) && b->valuedouble > 0) want = b->valuedouble;
    const char *of = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "rid"));
    if (of) { /* a child job's output, under this job's name for it */
        const char *ext = strrchr(file, '.');
        snprintf(fname, 128, "%s-%s%s", row->id, o->string, ext ? ext : "");
        snprintf(rid, sizeof rid, "%s", of);
    } else {
        snprintf(fname, 128, "%s-%s", row->id, file);
        snprintf(rid, sizeof rid, "%s/%d", row->id, row->attempt);
    }
    if (vx_store_result_file(j->desc.store, rid, file, path, pathn, err)) return -1;
    return job_output_check_size(row->id, path, want, err);
}

int cluster_output(vx_jobs *j, const char *jid, const char *name, char *path, size_t pathn,
                   char ctype[64], char fname[128], vx_err *err)
{
    vx_pg_job row;
    if (vx_pg_get(j->cl->api, jid, &row, err)) return -1;
    int rc = row_output(j, &row, name, path, pathn, ctype, fname, err);
    vx_pg_job_clear(&row);
    return rc;
}

/* ---- claims ------------------------------------------------------------------- */

/* 1 when the GL thread has nothing to start: no claimed job waits here and
 * none is in its GL stage (a job encoding on a CPU worker leaves the GL
 * thread free for the next). */
static int gl_free(vx_jobs *j)
{
    pthread_mutex_lock(&j->lock);
    int busy = j->in_gl;
    for (size_t i = 0; i < j->jobs.n && !busy; i++)
        busy = job_at(j, i)->state == ST_QUEUED;
    pthread_mutex_unlock(&j->lock);
    return !busy;
}

/* The child jobs of a claimed parent, as vx_run_child reads them:
 * [{id, attempt, params, result}], or NULL with err. */
static cJSON *children_of(vx_jobs *j, vx_pg *pg, const char *id, vx_err *err)
{
    cJSON *arr = cJSON_CreateArray();
    vx_pg_filter f = {.parent = id};
    char after[33] = "", next[33];
    do {
        vx_pg_job *rows = NULL;
        size_t n = 0;
        if (vx_pg_list(pg, &f, after[0] ? after : NULL, 1000, &rows, &n, next, err)) {
            cJSON_Delete(arr);
            return NULL;
        }
        for (size_t i = 0; i < n; i++) {
            cJSON *o = cJSON_CreateObject();
            cJSON_AddStringToObject(o, "id", rows[i].id);
            cJSON_AddNumberToObject(o, "attempt", rows[i].attempt);
            cJSON_AddItemToObject(o, "params", rows[i].params);
            cJSON_AddItemToObject(o, "result",
                                  rows[i].result ? rows[i].result : cJSON_CreateObject());
            rows[i].params = rows[i].result = NULL;
            cJSON_AddItemToArray(arr, o);
        }
        vx_pg_jobs_free(rows, n);
        snprintf(after, sizeof after, "%s", next);
    } while (after[0]);
    return arr;
}

/* Makes a claimed row a local job and queues it for the GL thread; what
 * cannot run here is reported failed at once. */
static void adopt(vx_jobs *j, vx_pg_job *row)
{
    vx_cluster *c = j->cl;
    vx_err err;
    vx_err_clear(&err);
    const vx_kind *k = vx_kinds_find(j->desc.kinds, row->kind);
    job *jb = k ? calloc(1, sizeof *jb) : NULL;
    int retry = 0;
    if (!k) {
        vx_err_set(&err, VX_EUNPROC, "unknown_kind", "replica %s does not run kind %s", j->replica,
                   row->kind);
    } else if (!jb) {
        vx_err_set(&err, VX_EINTERNAL, "out_of_memory", "no memory");
        retry = 1;
    } else {
        snprintf(jb->id, sizeof jb->id, "%s", row->id);
        snprintf(jb->mesh, sizeof jb->mesh, "%s", row->mesh);
        jb->kind = k;
        jb->params = row->params ? cJSON_Duplicate(row->params, 1) : cJSON_CreateObject();
        jb->stats = cJSON_CreateObject();
        jb->outputs = cJSON_CreateObject();
        jb->attempts = row->attempt;
        jb->created = row->created;
        jb->state = ST_QUEUED;
        if (row->children > 0 && !(jb->children = children_of(j, j->cl->work, row->id, &err))) {
            job_free(jb);
            jb = NULL;
            retry = 1;
            goto report;
        }
        /* The job holds its meshes (and blobs) here while it runs; one
         * that is gone from the store fails when it runs. */
        pin_job(j, jb->mesh, k, jb->params, 1, &jb->pins, NULL);
        pthread_mutex_lock(&j->lock);
        int taken = find_job(j, jb->id) != NULL || vx_sorted_insert(&j->jobs, jb) != 0;
        if (!taken) vx_queue_push(j->queue, jb, 1);
        pthread_mutex_unlock(&j->lock);
        if (!taken) {
            __atomic_add_fetch(&c->stats.claims, 1, __ATOMIC_RELAXED);
            VX_INFO("job.claimed", "job=%s kind=%s attempt=%d replica=%s", row->id, row->kind,
                    row->attempt, VX_Q(j->replica));
            notify(j, row->id, 0);
            return;
        }
        /* An earlier attempt of it still ends here (its lease moved on):
         * this attempt goes back for another replica. */
        unpin_job(j, &jb->pins);
        job_free(jb);
        jb = NULL;
        vx_err_set(&err, VX_EBUSY, "replica_busy", "replica %s still holds an earlier attempt",
                   j->replica);
        retry = 1;
    }
    free(jb);
report:;
    char state[16] = "";
    if (vx_pg_fail(c->work, row->id, row->attempt, &err, retry, state, NULL) == 0)
        notify(j, row->id, strcmp(state, "queued") != 0);
}

static void *claimer_main(void *arg)
{
    vx_jobs *j = arg;
    vx_cluster *c = j->cl;
    double quiet_until = 0;
    pthread_mutex_lock(&c->lock);
    while (!c->stopping) {
        pthread_mutex_unlock(&c->lock);
        int claimed = 0;
        if (!j->stopping && gl_free(j)) {
            vx_pg_job row;
            vx_err err;
            int got = vx_pg_claim(c->work, c->kinds, &row, &err);
            if (got == 1) {
                adopt(j, &row);
                vx_pg_job_clear(&row);
                claimed = 1;
            } else if (got < 0 && vx_mono() > quiet_until) {
                VX_WARN("cluster.claim_failed", "code=%s", err.code);
                quiet_until = vx_mono() + 10;
            }
        }
        pthread_mutex_lock(&c->lock);
        /* Claimed: straight on once the GL thread takes it; else until a
         * job is queued or one here finishes, at most a second (polling
         * fallback for lost notifications). */
        if (!claimed) wait_locked(c, 1.0);
    }
    pthread_mutex_unlock(&c->lock);
    return NULL;
}

/* ---- leases ------------------------------------------------------------------- */

static void cancel_local(vx_jobs *j, const char *jid)
{
    pthread_mutex_lock(&j->lock);
    job *jb = find_job(j, jid);
    if (jb) jb->cancel_requested = 1;
    pthread_mutex_unlock(&j->lock);
    /* A claimed job still waiting for the GL thread: the GL thread finds
     * cancel_requested when it takes it and reports it canceled. */
}

/* The attempt is no longer ours: stop it without reporting. */
static void lose(vx_jobs *j, const char *jid, int attempt)
{
    vx_cluster *c = j->cl;
    pthread_mutex_lock(&j->lock);
    job *jb = find_job(j, jid);
    int hit = jb && jb->attempts == attempt && !jb->lease_lost && !jb->reporting;
    if (hit) {
        jb->lease_lost = 1;
        jb->cancel_requested = 1;
    }
    pthread_mutex_unlock(&j->lock);
    if (hit) {
        __atomic_add_fetch(&c->stats.lease_losses, 1, __ATOMIC_RELAXED);
        VX_WARN("job.lease_lost", "job=%s attempt=%d replica=%s", jid, attempt, VX_Q(j->replica));
    }
}

typedef struct held {
    char id[33];
    int attempt;
    double progress;
} held;

static void renew_all(vx_jobs *j)
{
    vx_cluster *c = j->cl;
    held h[64];
    size_t n = 0;
    pthread_mutex_lock(&j->lock);
    for (size_t i = 0; i < j->jobs.n && n < 64; i++) {
        job *jb = job_at(j, i);
        /* a job reporting is renewed too: storing its results can take
         * longer than the lease (a big result, a slow store), and another
         * replica then ran it again and this attempt was thrown away (its
         * completion, once recorded, makes the renewal a no-op) */
        if (jb->lease_lost || is_terminal(jb->state)) continue;
        snprintf(h[n].id, sizeof h[n].id, "%s", jb->id);
        h[n].attempt = jb->attempts;
        h[n].progress = jb->progress;
        n++;
    }
    pthread_mutex_unlock(&j->lock);
    for (size_t i = 0; i < n; i++) {
        int cancel = 0;
        vx_err err;
        int rc = vx_pg_renew(c->lease, h[i].id, h[i].attempt, h[i].progress, &cancel, &err);
        if (rc == 1)
            lose(j, h[i].id, h[i].attempt);
        else if (rc == 0 && cancel)
            cancel_local(j, h[i].id);
        else if (rc < 0)
            VX_WARN("cluster.renew_failed", "job=%s code=%s", h[i].id, err.code);
    }
}

/* The completions cluster_report could not confirm: a row succeeded by
 * that attempt keeps its results; a row another attempt has, or gone,
 * has them removed; a database still out, or the row still running by
 * that attempt (the lease not yet expired), asks again at the next turn. */
static void check_unsure(vx_jobs *j)
{
    vx_cluster *c = j->cl;
    struct unsure todo[sizeof c->unsure / sizeof c->unsure[0]];
    pthread_mutex_lock(&c->lock);
    int n = c->nunsure;
    memcpy(todo, c->unsure, (size_t)n * sizeof todo[0]);
    pthread_mutex_unlock(&c->lock);
    /* a third of a renewal period a turn at most: the leases come first */
    const double until = vx_mono() + c->renew_s / 3;
    for (int i = 0; i < n && vx_mono() < until; i++) {
        vx_pg_job row;
        vx_err err;
        vx_err_clear(&err);
        int rc = vx_pg_get(c->lease, todo[i].id, &row, &err);
        int gone = rc < 0 && err.kind == VX_ENOTFOUND;
        if (rc < 0 && !gone) break; /* still out: the next turn (one wait a turn) */
        int ours = !gone && row.attempt == todo[i].attempt;
        int done = gone || !ours || strcmp(row.state, "running") != 0;
        int keep = ours && !strcmp(row.state, "succeeded");
        vx_pg_job_clear(&row);
        if (!done) continue;
        if (keep) {
            VX_INFO("cluster.report_confirmed", "job=%s attempt=%d", todo[i].id, todo[i].attempt);
        } else {
            VX_WARN("job.stale_attempt", "job=%s attempt=%d", todo[i].id, todo[i].attempt);
            __atomic_add_fetch(&c->stats.stale_completions, 1, __ATOMIC_RELAXED);
            vx_store_result_remove(j->desc.store, todo[i].rid);
        }
        pthread_mutex_lock(&c->lock);
        for (int k = 0; k < c->nunsure; k++)
            if (!strcmp(c->unsure[k].id, todo[i].id) && c->unsure[k].attempt == todo[i].attempt) {
                c->unsure[k] = c->unsure[--c->nunsure];
                break;
            }
        pthread_mutex_unlock(&c->lock);
    }
}

static void *renewer_main(void *arg)
{
    vx_jobs *j = arg;
    vx_cluster *c = j->cl;
    double next_requeue = 0;
    pthread_mutex_lock(&c->lock);
    while (!c->stopping || j->running > 0) {
        pthread_mutex_unlock(&c->lock);
        renew_all(j);
        check_unsure(j);
        if (vx_mono() >= next_requeue && !c->stopping) {
            /* Any replica re-queues the leases that expired (a replica that
             * died or stalled): the one whose claim is oldest goes first. */
            int requeued = 0, failed = 0;
            vx_err err;
            int moved = vx_pg_requeue_expired(c->lease, 100, &requeued, &failed, &err);
            if (moved > 0)
                __atomic_add_fetch(&c->stats.requeued_expired, (uint64_t)moved, __ATOMIC_RELAXED);
            if (requeued > 0) cluster_wake(j);
            /* and purges the bytes of deleted meshes no job needs now */
            if (vx_pg_mesh_purge(c->work, 100, purge_bytes, j->desc.store, &err) < 0)
                VX_DEBUG("cluster.mesh_purge_failed", "code=%s", err.code);
            next_requeue = vx_mono() + c->renew_s;
        }
        pthread_mutex_lock(&c->lock);
        struct timespec ts;
        vx_mono_deadline(c->stopping ? 0.2 : c->renew_s, &ts);
        pthread_cond_timedwait(&c->cond, &c->lock, &ts);
    }
    pthread_mutex_unlock(&c->lock);
    return NULL;
}

/* ---- notifications ------------------------------------------------------------- */

static void *listener_main(void *arg)
{
    vx_jobs *j = arg;
    vx_cluster *c = j->cl;
    for (;;) {
        pthread_mutex_lock(&c->lock);
        int stop = c->stopping;
        pthread_mutex_unlock(&c->lock);
        if (stop && !j->running) break;
        char payload[160];
        vx_err err;
        int rc = vx_pg_wait(c->listen, 1.0, payload, sizeof payload, &err);
        if (rc != 1) continue;
        /* "STATE ID KIND", "cancel ID KIND", or "" (notifications were lost
         * while reconnecting: whoever waits re-reads). */
        char state[16] = "", id[40] = "";
        if (sscanf(payload, "%15s %39s", state, id) != 2) {
            cluster_wake(j);
            continue;
        }
        if (!strcmp(state, "queued")) {
            cluster_wake(j);
        } else if (!strcmp(state, "cancel")) {
            cancel_local(j, id);
            /* (not from the renewer: its report could hold the renewals
             * up while the database is out) */
            jobs_cancel_waiting(j, id);
        }
        int terminal =
            !strcmp(state, "succeeded") || !strcmp(state, "failed") || !strcmp(state, "canceled");
        if (terminal) cluster_wake(j);
        notify(j, id, terminal);
    }
    return NULL;
}

/* ---- reports ------------------------------------------------------------------- */

/* 1 when an attempt that failed this way may succeed on another try (on
 * this or another replica): the GPU, the store or the database, not the
 * request. */
static int retryable(const vx_err *e)
{
    switch (e->kind) {
    case VX_EGPU:
    case VX_EIO:
    case VX_EUNAVAIL:
    case VX_EOVERLOAD:
    case VX_ENOSPC:
    case VX_EBUSY:
        return 1;
    default:
        return !strcmp(e->code, "out_of_memory");
    }
}

/* The result manifest: the run's outputs with their place in the store
 * and size, and its stats. */
static cJSON *manifest(vx_jobs *j, vx_job_run *r)
{
    cJSON *m = cJSON_CreateObject();
    cJSON *outs = cJSON_AddObjectToObject(m, "outputs");
    const cJSON *it;
    cJSON_ArrayForEach(it, r->outputs)
    {
        const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "file"));
        /* rid: a child job's output, in its place (vx_run_output_of_child) */
        const char *rid = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "rid"));
        cJSON *o = cJSON_AddObjectToObject(outs, it->string);
        cJSON_AddStringToObject(o, "file", file ? file : "");
        cJSON_AddStringToObject(
            o, "content_type",
            cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "content_type")) ?: "");
        char loc[256], path[VX_PATH_MAX];
        snprintf(loc, sizeof loc, "results/%s/%s", rid ? rid : r->rid, file ? file : "");
        cJSON_AddStringToObject(o, "location", loc);
        struct stat st;
        snprintf(path, sizeof path, "%s/%s", r->dir, file ? file : "");
        double bytes = rid ? cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(it, "bytes"))
                       : stat(path, &st) == 0 ? (double)st.st_size
                                              : 0;
        cJSON_AddNumberToObject(o, "bytes", bytes == bytes ? bytes : 0);
        if (rid) cJSON_AddStringToObject(o, "rid", rid);
    }
    (void)j;
    cJSON_AddItemReferenceToObject(m, "stats", r->stats);
    return m;
}

void cluster_report(vx_jobs *j, job *jb, vx_job_run *r, int ok, const vx_err *e, int requeue,
                    char state[16])
{
    vx_cluster *c = j->cl;
    state[0] = 0;
    pthread_mutex_lock(&j->lock);
    int lost = jb->lease_lost;
    jb->reporting = 1; /* its end is told below (lose() lets it be) */
    pthread_mutex_unlock(&j->lock);
    if (lost) {
        /* Another attempt owns the job now: nothing to say. */
        if (r->dir[0]) vx_store_result_remove(j->desc.store, r->rid);
        return;
    }
    /* Results another replica cannot read are not results: an attempt
     * whose outputs did not reach the shared store failed (retryable). */
    vx_err serr;
    vx_err_clear(&serr);
    if (ok && r->dir[0] && vx_store_result_commit(j->desc.store, r->rid, &serr)) {
        ok = 0;
        char why[sizeof serr.message]; /* not formatted into itself (it doubled) */
        snprintf(why, sizeof why, "%s", serr.message);
        /* (a result over the whole budget fails as it is: no retry helps) */
        if (strcmp(serr.code, "result_too_large") != 0)
            vx_err_set(&serr, serr.kind == VX_EUNAVAIL ? VX_EUNAVAIL : VX_EIO, "store_failed",
                       "the results could not be stored: %s", why);
        e = &serr;
    }
    cJSON *m = ok ? manifest(j, r) : NULL;
    /* While the database is unreachable the lease may still hold: keep
     * trying for one lease period (the renewer keeps it alive meanwhile). */
    double give_up = vx_mono() + 3 * c->renew_s;
    int rc;
    for (;;) {
        vx_err err;
        if (ok) {
            rc = vx_pg_complete(c->work, jb->id, jb->attempts, m, &err);
            if (rc == 0) snprintf(state, 16, "succeeded");
        } else if (requeue) {
            rc = vx_pg_release(c->work, jb->id, jb->attempts, &err);
            if (rc == 0) snprintf(state, 16, "queued");
        } else {
            int retry = retryable(e);
            rc = vx_pg_fail(c->work, jb->id, jb->attempts, e, retry, state, &err);
            if (rc == 0 && !strcmp(state, "queued"))
                __atomic_add_fetch(&c->stats.retries, 1, __ATOMIC_RELAXED);
        }
        if (rc >= 0) break;
        if (err.kind != VX_EUNAVAIL || vx_mono() > give_up) {
            VX_ERROR("cluster.report_failed", "job=%s attempt=%d code=%s", jb->id, jb->attempts,
                     err.code);
            break;
        }
        nap(0.5);
        pthread_mutex_lock(&j->lock);
        lost = jb->lease_lost;
        pthread_mutex_unlock(&j->lock);
        if (lost) break;
    }
    cJSON_Delete(m);
    if (rc < 0 && ok) {
        /* No answer: the completion may have committed (its answer lost
         * with the connection). Its results stay until the database tells
         * (check_unsure): removed now, a committed row would point at
         * nothing, 410 forever. */
        pthread_mutex_lock(&c->lock);
        int kept = c->nunsure < (int)(sizeof c->unsure / sizeof c->unsure[0]);
        if (kept) {
            struct unsure *u = &c->unsure[c->nunsure++];
            snprintf(u->id, sizeof u->id, "%s", jb->id);
            u->attempt = jb->attempts;
            snprintf(u->rid, sizeof u->rid, "%s", r->rid);
        }
        pthread_mutex_unlock(&c->lock);
        VX_WARN("cluster.report_unknown", "job=%s attempt=%d results=kept%s", jb->id, jb->attempts,
                kept ? "" : " unchecked=1");
        state[0] = 0;
    } else if (rc != 0) {
        /* Stale (another attempt won), or a failure never recorded: this
         * attempt's results are nobody's. */
        if (rc == 1) {
            __atomic_add_fetch(&c->stats.stale_completions, 1, __ATOMIC_RELAXED);
            VX_WARN("job.stale_attempt", "job=%s attempt=%d", jb->id, jb->attempts);
        }
        if (r->dir[0] || ok) vx_store_result_remove(j->desc.store, r->rid);
        state[0] = 0;
    } else if (!ok && r->dir[0]) {
        vx_store_result_remove(j->desc.store, r->rid);
    }
    /* The job has ended: what earlier attempts left (a replica killed
     * mid-job wrote part of its outputs, and no one came back for them)
     * is nobody's; only a delete of the job had removed it. */
    if (rc == 0 && (ok || !strcmp(state, "failed")))
        for (int a = 1; a < jb->attempts; a++) {
            char rid[48];
            snprintf(rid, sizeof rid, "%s/%d", jb->id, a);
            vx_store_result_remove(j->desc.store, rid);
        }
}

/* ---- status --------------------------------------------------------------------- */

int vx_jobs_cluster(vx_jobs *j, vx_jobs_cluster_stats *out)
{
    if (!j->cl) return 0;
    if (out) {
        vx_jobs_cluster_stats *s = &j->cl->stats;
        out->claims = __atomic_load_n(&s->claims, __ATOMIC_RELAXED);
        out->lease_losses = __atomic_load_n(&s->lease_losses, __ATOMIC_RELAXED);
        out->stale_completions = __atomic_load_n(&s->stale_completions, __ATOMIC_RELAXED);
        out->retries = __atomic_load_n(&s->retries, __ATOMIC_RELAXED);
        out->requeued_expired = __atomic_load_n(&s->requeued_expired, __ATOMIC_RELAXED);
    }
    return 1;
}

long cluster_queued(vx_jobs *j)
{
    vx_err err;
    vx_err_clear(&err);
    return vx_pg_queued(j->cl->api, &err);
}

int vx_jobs_database_ok(vx_jobs *j, vx_err *err)
{
    if (!j->cl) return 1;
    return vx_pg_ping(j->cl->api, err) == 0;
}

int vx_jobs_cluster_counts(vx_jobs *j, vx_pg_count **out, size_t *n, vx_err *err)
{
    if (!j->cl) {
        *out = NULL;
        *n = 0;
        return vx_err_set(err, VX_ENOTIMPL, "not_clustered", "no --database");
    }
    return vx_pg_counts(j->cl->api, out, n, err);
}

const char *vx_jobs_replica(vx_jobs *j)
{
    return j->replica;
}
