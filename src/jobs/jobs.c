/* Job table, journal replay, the GL thread and the CPU workers (jobs.h). */
#include "jobs/jobs.h"

#include <errno.h>
#include <fcntl.h>
#include <malloc.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "jobs/journal.h"
#include "jobs/queue.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/sorted.h"

typedef enum job_state { ST_QUEUED, ST_RUNNING, ST_SUCCEEDED, ST_FAILED, ST_CANCELED } job_state;
static const char *state_names[] = {"queued", "running", "succeeded", "failed", "canceled"};

/* What an unfinished job holds in the store (vx_store_mesh_pin,
 * vx_store_blob_put/pin): released when it finishes. */
typedef struct pinset {
    char (*mesh)[65];
    size_t nmesh;
    char (*blob)[65];
    size_t nblob;
} pinset;

typedef struct job {
    char id[33];
    char mesh[65];
    const vx_kind *kind;
    cJSON *params;
    job_state state;
    double progress;
    int cancel_requested;
    int attempts;
    double created, started, finished; /* wall clock; 0 = not yet */
    long seq;                          /* journal order of this job's snapshots */
    vx_err error;
    cJSON *stats;   /* object */
    cJSON *outputs; /* name -> {"file","content_type"}, in declaration order */
    /* A finished job keeps params, stats and outputs only as this compact
     * JSON text {"params","stats","outputs"} (the three trees are NULL). */
    char *frozen;
    size_t bytes; /* what a finished job costs the history budget */
    pinset pins;
} job;

struct vx_job_run {
    vx_jobs *jobs;
    job *job;
    const vx_kind *kind;
    vx_gl *gl;
    double t0;        /* monotonic start of this attempt */
    double last_ping; /* watchdog */
    cJSON *stats;
    cJSON *outputs;
    char dir[2200]; /* result dir, made at the first output */
    cJSON *paths;   /* strings: every path handed out, valid until the run ends */
    cJSON *params;  /* the job's params with its blobs back in place */
    int big_params; /* some came from blobs */
    void *state;
    int on_gl_thread;
};

struct vx_jobs {
    vx_jobs_desc desc;
    vx_journal *journal;
    vx_queue *queue; /* queued jobs, for the GL thread */
    vx_queue *cpu;   /* runs that finished their GL stage */
    pthread_mutex_t lock;
    vx_sorted jobs;         /* job *, sorted by id = creation order */
    uint64_t history_bytes; /* sum of bytes of the finished jobs */
    size_t running;
    pthread_t gl_thread;
    pthread_t *workers;
    int nworkers, started;
    volatile int stopping;
    int gl_state; /* 0 starting, 1 up, -1 failed */
    pthread_cond_t gl_cond;
    vx_err gl_err;
    vx_gl_info gl_info;
    int fake_context_loss; /* VOXELD_TEST_LOSE_CONTEXT: exercise the retry path */
};

/* ---- job objects ---------------------------------------------------- */

static void pinset_free(pinset *ps)
{
    free(ps->mesh);
    free(ps->blob);
    memset(ps, 0, sizeof *ps);
}

/* Frees a job; its pins are released by whoever ends it, never here (a
 * queued job freed at shutdown keeps its mesh for the next start). */
static void job_free(job *jb)
{
    if (!jb) return;
    cJSON_Delete(jb->params);
    cJSON_Delete(jb->stats);
    cJSON_Delete(jb->outputs);
    free(jb->frozen);
    pinset_free(&jb->pins);
    free(jb);
}

static int is_terminal(job_state s)
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

/* Time-ordered ids: 48 bits of milliseconds, then 80 random bits. */
static void new_id(char out[33])
{
    unsigned char rnd[10] = {0};
    if (getrandom(rnd, sizeof rnd, 0) != (ssize_t)sizeof rnd) {
        for (size_t i = 0; i < sizeof rnd; i++)
            rnd[i] = (unsigned char)rand();
    }
    unsigned long long ms = (unsigned long long)(vx_now() * 1000.0);
    snprintf(out, 33, "%012llx", ms & 0xffffffffffffULL);
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

static double ms_between(double a, double b)
{
    return (double)(long long)((b - a) * 1e6) / 1e3;
}

/* Owned copies of a job's params, stats and outputs (empty objects where
 * there are none): from its trees, or from the text of a finished job. */
static void job_parts(const job *jb, cJSON **params, cJSON **stats, cJSON **outputs)
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

/* api = 1: the API resource; api = 0: the journal snapshot. Caller holds the lock. */
static cJSON *job_json(const job *jb, int api)
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
static void freeze_locked(vx_jobs *j, job *jb)
{
    if (jb->frozen || jb->bytes) return;
    cJSON *o = cJSON_CreateObject();
    char *text = NULL;
    if (o && (!jb->params || cJSON_AddItemReferenceToObject(o, "params", jb->params)) &&
        (!jb->stats || cJSON_AddItemReferenceToObject(o, "stats", jb->stats)) &&
        (!jb->outputs || cJSON_AddItemReferenceToObject(o, "outputs", jb->outputs)))
        text = cJSON_PrintUnformatted(o);
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

static const char *job_key(const void *item)
{
    return ((const job *)item)->id;
}

static job *job_at(const vx_jobs *j, size_t i)
{
    return j->jobs.items[i];
}

static job *find_job(vx_jobs *j, const char *id)
{
    return vx_sorted_get(&j->jobs, id);
}

/* Drops the oldest finished jobs beyond the history limits, in count and
 * in bytes (and their results); the byte budget leaves at least one. */
static void trim_history_locked(vx_jobs *j, char (*dropped)[33], size_t *ndropped, size_t max)
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

/* Journals a snapshot; caller holds the lock (so seq and file order agree). */
static int journal_locked(vx_jobs *j, job *jb, vx_err *err)
{
    jb->seq++;
    cJSON *rec = cJSON_CreateObject();
    cJSON_AddItemToObject(rec, "job", job_json(jb, 0));
    int rc = vx_journal_append(j->journal, rec, err);
    cJSON_Delete(rec);
    return rc;
}

static void notify(vx_jobs *j, const char *jid, int terminal)
{
    if (j->desc.hooks.changed) j->desc.hooks.changed(j->desc.hooks.ud, jid, terminal);
}

/* Rewrites the journal as one snapshot per job. Caller holds the lock (or
 * runs before any thread starts). */
static int compact_locked(vx_jobs *j, vx_err *err)
{
    cJSON **recs = calloc(j->jobs.n + 1, sizeof *recs);
    if (!recs) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    for (size_t i = 0; i < j->jobs.n; i++) {
        recs[i] = cJSON_CreateObject();
        cJSON_AddItemToObject(recs[i], "job", job_json(job_at(j, i), 0));
    }
    int rc = vx_journal_compact(j->journal, recs, j->jobs.n, err);
    for (size_t i = 0; i < j->jobs.n; i++)
        cJSON_Delete(recs[i]);
    free(recs);
    return rc;
}

/* ---- pins and blobs ------------------------------------------------- */

static int pinset_add(char (**arr)[65], size_t *n, const char *id)
{
    char(*a)[65] = realloc(*arr, (*n + 1) * sizeof *a);
    if (!a) return -1;
    snprintf(a[*n], 65, "%s", id);
    *arr = a;
    (*n)++;
    return 0;
}

/* Releases what a job held: a deleted mesh or a blob may go now. */
static void unpin_job(vx_jobs *j, pinset *ps)
{
    for (size_t i = 0; i < ps->nmesh; i++)
        vx_store_mesh_unpin(j->desc.store, ps->mesh[i]);
    for (size_t i = 0; i < ps->nblob; i++)
        vx_store_blob_unpin(j->desc.store, ps->blob[i]);
    pinset_free(ps);
}

/* A blob reference in normalised params: {"blob": SHA-256, ...}. */
static const char *blob_ref(const cJSON *it)
{
    const char *id = cJSON_IsObject(it)
                         ? cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "blob"))
                         : NULL;
    return id && vx_store_valid_mesh_id(id) ? id : NULL;
}

/* Pins the job's mesh and those its params name, and (replay) the blobs its
 * params reference. At submission (replay = 0) a mesh that is not there is
 * 404 and nothing stays pinned; at replay a deleted mesh still counts, and
 * what is gone is left out (the job fails when it runs). */
static int pin_job(vx_jobs *j, const char *mesh, const vx_kind *k, const cJSON *params, int replay,
                   pinset *ps, vx_err *err)
{
    const char *ids[257] = {mesh};
    size_t n = 1;
    if (k->mesh_refs) {
        size_t m = k->mesh_refs(params, ids + 1, 256);
        n += m < 256 ? m : 256;
    }
    for (size_t i = 0; i < n; i++) {
        vx_err e;
        if (!ids[i] || !vx_store_valid_mesh_id(ids[i])) continue;
        if (vx_store_mesh_pin(j->desc.store, ids[i], replay, &e) == 0) {
            if (pinset_add(&ps->mesh, &ps->nmesh, ids[i]) == 0) continue;
            vx_store_mesh_unpin(j->desc.store, ids[i]);
            vx_err_set(&e, VX_EINTERNAL, "out_of_memory", "no memory");
        } else if (replay) {
            VX_WARN("jobs.mesh_gone", "mesh=%s", ids[i]);
            continue;
        }
        if (err) *err = e;
        unpin_job(j, ps);
        return -1;
    }
    for (size_t f = 0; replay && k->blob_fields && k->blob_fields[f]; f++) {
        const char *id = blob_ref(cJSON_GetObjectItemCaseSensitive(params, k->blob_fields[f]));
        vx_err e;
        if (!id) continue;
        if (vx_store_blob_pin(j->desc.store, id, &e) == 0) {
            if (pinset_add(&ps->blob, &ps->nblob, id)) vx_store_blob_unpin(j->desc.store, id);
        } else {
            VX_WARN("jobs.blob_gone", "blob=%s", id);
        }
    }
    return 0;
}

/* Moves the large inline fields of normalised params (kind->blob_fields)
 * into blobs, stored and pinned (ps) before the job is acknowledged, and
 * puts references in their place. */
static int externalize(vx_jobs *j, const vx_kind *k, cJSON *params, pinset *ps, vx_err *err)
{
    for (size_t f = 0; k->blob_fields && k->blob_fields[f]; f++) {
        const char *name = k->blob_fields[f];
        cJSON *it = cJSON_GetObjectItemCaseSensitive(params, name);
        if (!cJSON_IsArray(it) && !cJSON_IsObject(it)) continue;
        if (k->mesh_refs) { /* mesh ids stay visible: pins and replay read them */
            cJSON *probe = cJSON_CreateObject();
            const char *ids[1];
            size_t m = probe && cJSON_AddItemReferenceToObject(probe, name, it)
                           ? k->mesh_refs(probe, ids, 1)
                           : 1;
            cJSON_Delete(probe);
            if (m) continue;
        }
        char *text = cJSON_PrintUnformatted(it);
        if (!text) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        size_t len = strlen(text);
        if (len < VX_BLOB_MIN_BYTES) {
            free(text);
            continue;
        }
        char id[65];
        int rc = vx_store_blob_put(j->desc.store, text, len, id, err);
        free(text);
        if (rc) return -1;
        if (pinset_add(&ps->blob, &ps->nblob, id)) {
            vx_store_blob_unpin(j->desc.store, id);
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        }
        cJSON *ref = cJSON_CreateObject();
        if (!ref || !cJSON_AddStringToObject(ref, "blob", id) ||
            !cJSON_AddNumberToObject(ref, "bytes", (double)len) ||
            !cJSON_AddNumberToObject(ref, "count", cJSON_GetArraySize(it)) ||
            !cJSON_ReplaceItemInObjectCaseSensitive(params, name, ref)) {
            cJSON_Delete(ref);
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        }
    }
    return 0;
}

/* The params the stages get: an owned copy with every blob read back. */
static cJSON *inline_params(vx_jobs *j, const vx_kind *k, const cJSON *params, int *big,
                            vx_err *err)
{
    cJSON *p = cJSON_Duplicate(params, 1);
    if (!p) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the params");
        return NULL;
    }
    for (size_t f = 0; k->blob_fields && k->blob_fields[f]; f++) {
        const char *id = blob_ref(cJSON_GetObjectItemCaseSensitive(p, k->blob_fields[f]));
        if (!id) continue;
        if (big) *big = 1;
        size_t n = 0;
        char *text = vx_store_blob_read(j->desc.store, id, &n, err);
        cJSON *v = text ? cJSON_ParseWithLength(text, n) : NULL;
        free(text);
        if (!v || !cJSON_ReplaceItemInObjectCaseSensitive(p, k->blob_fields[f], v)) {
            if (text && !v)
                vx_err_set(err, VX_EINTERNAL, "blob_corrupt",
                           "the job's inline data (params.%s) cannot be read back",
                           k->blob_fields[f]);
            cJSON_Delete(v);
            cJSON_Delete(p);
            return NULL;
        }
    }
    return p;
}

/* ---- replay --------------------------------------------------------- */

static void replay_one(const cJSON *rec, void *ud)
{
    vx_jobs *j = ud;
    const cJSON *o = cJSON_GetObjectItemCaseSensitive(rec, "job");
    const char *id = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "id"));
    const char *kind = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "kind"));
    const char *mesh = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "mesh"));
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "state"));
    if (!vx_jobs_valid_id(id) || !kind || !mesh || !state) {
        VX_WARN("journal.bad_job", "reason=missing_fields");
        return;
    }
    const vx_kind *k = vx_kind_find(kind);
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
    vx_sorted_init(&j->jobs, job_key);
    pthread_mutex_init(&j->lock, NULL);
    pthread_cond_init(&j->gl_cond, NULL);
    j->queue = vx_queue_new(j->desc.max_queued);
    j->cpu = vx_queue_new(0);
    const char *env = getenv("VOXELD_TEST_LOSE_CONTEXT");
    j->fake_context_loss = env && atoi(env) > 0 ? atoi(env) : 0;
    char path[2300];
    if (!j->desc.journal) {
        snprintf(path, sizeof path, "%s/journal.log", vx_store_dir(desc->store));
        j->desc.journal = path;
    }
    j->journal = vx_journal_open(j->desc.journal, err);
    if (!j->journal || !j->queue || !j->cpu) {
        if (j->journal || err->kind == VX_EOK)
            vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        vx_jobs_free(j);
        return NULL;
    }
    j->desc.journal = NULL; /* path was on our stack */
    long n = vx_journal_replay(j->journal, replay_one, j, err);
    if (n < 0) {
        vx_jobs_free(j);
        return NULL;
    }
    /* Jobs that never finished run again, oldest first, whatever the
     * queue limit: they were acknowledged. */
    size_t requeued = 0;
    for (size_t i = 0; i < j->jobs.n; i++) {
        job *jb = job_at(j, i);
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
    trim_history_locked(j, dropped, &nd, 256);
    for (size_t i = 0; i < nd; i++)
        vx_store_result_remove(desc->store, dropped[i]);
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
    VX_INFO("jobs.replayed", "records=%ld jobs=%zu requeued=%zu", n, j->jobs.n, requeued);
    return j;
}

/* ---- runs ----------------------------------------------------------- */

int vx_run_progress(vx_job_run *r, double fraction, vx_err *err)
{
    vx_jobs *j = r->jobs;
    if (fraction < 0) fraction = 0;
    if (fraction > 1) fraction = 1;
    pthread_mutex_lock(&j->lock);
    if (fraction > r->job->progress) r->job->progress = fraction;
    int cancel = r->job->cancel_requested;
    pthread_mutex_unlock(&j->lock);
    double now = vx_mono();
    if (r->on_gl_thread && now - r->last_ping > 1.0) {
        sd_notify(0, "WATCHDOG=1");
        r->last_ping = now;
    }
    if (cancel) return vx_err_set(err, VX_ECANCELED, "canceled", "the job was canceled");
    if (j->stopping)
        return vx_err_set(err, VX_ECANCELED, "shutdown", "the daemon is shutting down");
    double limit = j->desc.limits.job_timeout_s;
    if (limit > 0 && now - r->t0 > limit)
        return vx_err_set(err, VX_ETIMEOUT, "job_timeout", "the job ran longer than %g s", limit);
    return 0;
}

vx_gl *vx_run_gl(vx_job_run *r)
{
    return r->gl;
}
const vx_limits *vx_run_limits(const vx_job_run *r)
{
    return &r->jobs->desc.limits;
}
const char *vx_run_cache_dir(const vx_job_run *r)
{
    return r->jobs->desc.cache_dir;
}
const char *vx_run_mesh_id(const vx_job_run *r)
{
    return r->job->mesh;
}

vx_mesh *vx_run_load_mesh(vx_job_run *r, const char *id, vx_err *err)
{
    char path[2300];
    if (vx_store_mesh_path(r->jobs->desc.store, id, path, sizeof path, err)) return NULL;
    vx_mesh_limits lim = {.max_triangles = r->jobs->desc.limits.max_triangles};
    return vx_mesh_read_path(path, &lim, err);
}
cJSON *vx_run_stats(vx_job_run *r)
{
    return r->stats;
}

const char *vx_run_output(vx_job_run *r, const char *name, const char *file_ext,
                          const char *content_type, vx_err *err)
{
    if (!r->dir[0] &&
        vx_store_result_dir(r->jobs->desc.store, r->job->id, r->dir, sizeof r->dir, err))
        return NULL;
    char file[160];
    snprintf(file, sizeof file, "%s.%s", name, file_ext);
    cJSON_DeleteItemFromObjectCaseSensitive(r->outputs, name);
    cJSON *o = cJSON_AddObjectToObject(r->outputs, name);
    cJSON_AddStringToObject(o, "file", file);
    cJSON_AddStringToObject(o, "content_type", content_type);
    char path[2400];
    snprintf(path, sizeof path, "%s/%s", r->dir, file);
    cJSON *s = cJSON_CreateString(path);
    if (!s || !cJSON_AddItemToArray(r->paths, s)) {
        cJSON_Delete(s);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    return s->valuestring;
}

static vx_job_run *run_new(vx_jobs *j, job *jb)
{
    vx_job_run *r = calloc(1, sizeof *r);
    if (!r) return NULL;
    r->jobs = j;
    r->job = jb;
    r->kind = jb->kind;
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
    cJSON_Delete(r->params);
    int big = r->big_params;
    free(r);
    if (big) malloc_trim(0); /* as at submission */
}

static void sync_outputs(vx_job_run *r)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, r->outputs)
    {
        char p[2400];
        snprintf(p, sizeof p, "%s/%s", r->dir,
                 cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "file")));
        int fd = open(p, O_RDONLY | O_CLOEXEC);
        if (fd >= 0) {
            fsync(fd);
            close(fd);
        }
    }
}

/* Ends a run: success, failure, cancel, or back to the queue on shutdown. */
static void run_finish(vx_jobs *j, vx_job_run *r, int ok, const vx_err *e)
{
    job *jb = r->job;
    int requeue = !ok && e->kind == VX_ECANCELED && strcmp(e->code, "shutdown") == 0;
    if (ok) {
        sync_outputs(r);
        vx_store_result_added(j->desc.store, jb->id);
    } else if (r->dir[0] || requeue) {
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
        VX_INFO("job.finished", "job=%s kind=%s state=%s run_ms=%.1f code=%s message=%s", id, kind,
                state_names[st], run_s * 1e3, ok ? "-" : e->code,
                vx_log_quote(qm, sizeof qm, ok ? "-" : e->message));
        if (j->desc.hooks.finished)
            j->desc.hooks.finished(j->desc.hooks.ud, id, kind, state_names[st], run_s);
    }
    notify(j, id, !requeue);
    run_free(r);
    if (ok) vx_store_results_evict(j->desc.store);
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
    char path[2300];
    if (vx_store_mesh_path(j->desc.store, id, path, sizeof path, err)) return NULL;
    vx_mesh_limits lim = {.max_triangles = j->desc.limits.max_triangles};
    mc->mesh = vx_mesh_read_path(path, &lim, err);
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
    jb->attempts++;
    j->running++;
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
        jb->state = ST_QUEUED;
        pthread_mutex_unlock(&j->lock);
        vx_queue_push(j->queue, jb, 1);
        return;
    }
    r->gl = gl;
    r->on_gl_thread = 1;
    r->params = inline_params(j, jb->kind, jb->params, &r->big_params, &err);
    const vx_mesh *m = r->params ? load_mesh(j, mc, jb->mesh, &err) : NULL;
    int ok = m != NULL;
    for (int attempt = 0; ok; attempt++) {
        double t = vx_mono();
        ok = jb->kind->run_gl(r, m, r->params, &r->state, &err) == 0;
        int lost = vx_gl_lost(gl);
        if (j->fake_context_loss > 0) {
            j->fake_context_loss--;
            lost = 1;
        }
        if (!lost) {
            cJSON_AddNumberToObject(r->stats, "gl_ms", ms_between(0, vx_mono() - t));
            break;
        }
        VX_WARN("gl.context_lost", "job=%s attempt=%d", jb->id, attempt + 1);
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
    if (!ok) {
        run_finish(j, r, 0, &err);
        return;
    }
    vx_queue_push(j->cpu, r, 1);
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
            sd_notify(0, "WATCHDOG=1");
            last_ping = now;
        }
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
        vx_err err;
        vx_err_clear(&err);
        const vx_kind *k = r->job->kind;
        int ok = 1;
        if (k->run_cpu) ok = k->run_cpu(r, r->params, r->state, &err) == 0;
        if (ok && k->encode) ok = k->encode(r, r->params, r->state, &err) == 0;
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
    return 0;
}

void vx_jobs_stop(vx_jobs *j)
{
    if (!j || !j->started) return;
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
    pthread_mutex_lock(&j->lock);
    vx_err err;
    compact_locked(j, &err);
    pthread_mutex_unlock(&j->lock);
    VX_INFO("jobs.stopped", "jobs=%zu queued=%zu", j->jobs.n, vx_queue_depth(j->queue));
}

void vx_jobs_maintain(vx_jobs *j, long max_journal_bytes)
{
    if (vx_journal_size(j->journal) <= max_journal_bytes) return;
    vx_err err;
    pthread_mutex_lock(&j->lock);
    int rc = compact_locked(j, &err);
    pthread_mutex_unlock(&j->lock);
    if (rc)
        VX_ERROR("journal.compact_failed", "code=%s", err.code);
    else
        VX_INFO("journal.compacted", "bytes=%ld", vx_journal_size(j->journal));
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
    vx_journal_close(j->journal);
    pthread_mutex_destroy(&j->lock);
    pthread_cond_destroy(&j->gl_cond);
    free(j);
}

/* ---- API ------------------------------------------------------------ */

cJSON *vx_jobs_submit(vx_jobs *j, const char *mesh, const char *kind, const cJSON *params,
                      vx_err *err)
{
    const vx_kind *k = vx_kind_find(kind);
    if (!k) {
        vx_err_set(err, VX_EUNPROC, "unknown_kind", "unknown job kind '%.64s'", kind);
        return NULL;
    }
    cJSON *meta = vx_store_mesh_meta(j->desc.store, mesh, err);
    if (!meta) return NULL;
    cJSON_Delete(meta);
    if (params && !cJSON_IsObject(params)) {
        vx_err_set(err, VX_EUNPROC, "invalid_params", "params must be an object");
        return NULL;
    }
    cJSON *norm = vx_params_normalize(k, params, &j->desc.limits, err);
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
    new_id(jb->id);
    snprintf(jb->mesh, sizeof jb->mesh, "%s", mesh);
    jb->kind = k;
    jb->created = vx_now();
    jb->stats = cJSON_CreateObject();
    jb->outputs = cJSON_CreateObject();
    pthread_mutex_lock(&j->lock);
    cJSON *out = NULL;
    if (j->stopping) {
        vx_err_set(err, VX_EBUSY, "not_ready", "the daemon is shutting down");
    } else if (vx_queue_depth(j->queue) >= vx_queue_capacity(j->queue)) {
        vx_err_set(err, VX_EBUSY, "queue_full", "the job queue is full (%zu queued)",
                   vx_queue_capacity(j->queue));
    } else if (vx_sorted_insert(&j->jobs, jb)) {
        vx_err_set(err, VX_EINTERNAL, "id_collision", "job id collision");
    } else if (journal_locked(j, jb, err)) {
        int found;
        vx_sorted_remove_at(&j->jobs, vx_sorted_find(&j->jobs, jb->id, &found));
    } else {
        /* Pushed under the lock, so capacity was checked atomically. */
        vx_queue_push(j->queue, jb, 1);
        out = job_json(jb, 1);
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
    pthread_mutex_lock(&j->lock);
    job *jb = vx_jobs_valid_id(jid) ? find_job(j, jid) : NULL;
    cJSON *out = jb ? job_json(jb, 1) : NULL;
    if (jb && terminal) *terminal = is_terminal(jb->state);
    pthread_mutex_unlock(&j->lock);
    if (!jb) vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job with id %.64s", jid);
    return out;
}

cJSON *vx_jobs_cancel(vx_jobs *j, const char *jid, int *was_running, vx_err *err)
{
    *was_running = 0;
    char kind[64] = "";
    pinset pins = {0};
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
        vx_err_set(&jb->error, VX_ECANCELED, "canceled", "canceled while queued");
        if (journal_locked(j, jb, err) == 0) {
            out = job_json(jb, 1);
            pins = jb->pins;
            memset(&jb->pins, 0, sizeof jb->pins);
            freeze_locked(j, jb);
            changed = 1;
        } else {
            /* Not recorded (a full disk: 507), so not done: the job stays
             * queued, as the journal and a restart would have it. */
            jb->state = ST_QUEUED;
            jb->finished = 0;
            vx_err_clear(&jb->error);
            vx_queue_push(j->queue, jb, 1);
        }
    } else {
        jb->cancel_requested = 1;
        *was_running = 1;
        out = job_json(jb, 1);
    }
    pthread_mutex_unlock(&j->lock);
    unpin_job(j, &pins);
    if (changed) {
        VX_INFO("job.finished", "job=%s state=canceled run_ms=0", jid);
        if (j->desc.hooks.finished)
            j->desc.hooks.finished(j->desc.hooks.ud, jid, kind, "canceled", -1);
        notify(j, jid, 1);
    }
    return out;
}

cJSON *vx_jobs_list(vx_jobs *j, const char *after, int limit, const char *state, char next[40])
{
    cJSON *arr = cJSON_CreateArray();
    next[0] = 0;
    pthread_mutex_lock(&j->lock);
    size_t i = vx_sorted_after(&j->jobs, after);
    int n = 0;
    for (; i < j->jobs.n; i++) {
        job *jb = job_at(j, i);
        if (state && strcmp(state, state_names[jb->state]) != 0) continue;
        if (n == limit) {
            snprintf(next, 40, "%s", job_at(j, i - 1)->id);
            break;
        }
        cJSON_AddItemToArray(arr, job_json(jb, 1));
        n++;
    }
    pthread_mutex_unlock(&j->lock);
    return arr;
}

int vx_jobs_output(vx_jobs *j, const char *jid, const char *name, char *path, size_t pathn,
                   char ctype[64], char fname[128], vx_err *err)
{
    char file[160] = {0}, id[33];
    pthread_mutex_lock(&j->lock);
    job *jb = vx_jobs_valid_id(jid) ? find_job(j, jid) : NULL;
    int rc = -1;
    if (!jb) {
        vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job with id %.64s", jid);
    } else if (jb->state == ST_QUEUED || jb->state == ST_RUNNING) {
        vx_err_set(err, VX_ECONFLICT, "job_not_finished", "job %s is %s", jid,
                   state_names[jb->state]);
    } else if (jb->state == ST_FAILED) {
        vx_err_set(err, VX_ECONFLICT, "job_failed", "job %s failed: %s", jid, jb->error.message);
    } else if (jb->state == ST_CANCELED) {
        vx_err_set(err, VX_ECONFLICT, "job_canceled", "job %s was canceled", jid);
    } else {
        cJSON *outputs = NULL;
        job_parts(jb, NULL, NULL, &outputs);
        const cJSON *o = name ? cJSON_GetObjectItemCaseSensitive(outputs, name)
                              : (outputs ? outputs->child : NULL);
        if (!o) {
            vx_err_set(err, VX_ENOTFOUND, "output_not_found", "job %s has no output '%.64s'", jid,
                       name ? name : "");
        } else {
            snprintf(file, sizeof file, "%s",
                     cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "file")) ?: "");
            snprintf(ctype, 64, "%s",
                     cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "content_type"))
                         ?: "application/octet-stream");
            snprintf(fname, 128, "%s-%s", jb->id, file);
            snprintf(id, sizeof id, "%s", jb->id);
            rc = 0;
        }
        cJSON_Delete(outputs);
    }
    pthread_mutex_unlock(&j->lock);
    if (rc) return rc;
    return vx_store_result_file(j->desc.store, id, file, path, pathn, err);
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
    return vx_queue_depth(j->queue);
}
size_t vx_jobs_queue_capacity(vx_jobs *j)
{
    return vx_queue_capacity(j->queue);
}

size_t vx_jobs_running(vx_jobs *j)
{
    pthread_mutex_lock(&j->lock);
    size_t n = j->running;
    pthread_mutex_unlock(&j->lock);
    return n;
}
