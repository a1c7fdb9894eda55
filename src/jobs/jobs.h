/* The job table and its runners.
 *
 * Jobs are created by HTTP threads (vx_jobs_submit), journaled before they
 * are acknowledged, queued, run by the one GL thread (the only thread that
 * owns the EGL context) and finished by CPU workers (encoding, writing
 * outputs). On open, the journal is replayed: jobs that were queued or
 * running are queued again. All functions are thread-safe unless noted. */
#ifndef VX_JOBS_H
#define VX_JOBS_H

#include <stddef.h>
#include <stdint.h>

#include <cjson/cJSON.h>

#include "gl/gl.h"
#include "jobs/kind.h"
#include "jobs/pg.h"
#include "jobs/state.h"
#include "store/store.h"

typedef struct vx_jobs vx_jobs;

typedef struct vx_jobs_hooks {
    /* A job reached succeeded / failed / canceled (run_s < 0: never ran). */
    void (*finished)(void *ud, const char *jid, const char *kind, const char *state, double run_s);
    /* A job changed state; terminal = it has finished (wakes ?wait). */
    void (*changed)(void *ud, const char *jid, int terminal);
    /* The GL thread is alive: called from it about once a second, and from
     * a long GL stage's progress checks (the daemon pings the systemd
     * watchdog). NULL = nothing. */
    void (*alive)(void *ud);
    /* Test hook, GL thread, after each GL stage: nonzero = handle the
     * context as lost (exercises the retry). NULL = never. */
    int (*lose_context)(void *ud);
    void *ud;
} vx_jobs_hooks;

typedef struct vx_jobs_desc {
    vx_store *store;              /* required; not owned */
    const vx_kinds *kinds;        /* required: the kinds it runs (daemon/kinds.c); not owned */
    const char *journal;          /* where the job state is: for the local journal a path,
                                     default DATA/journal.log */
    const vx_jobstate_ops *state; /* the job state's backend; NULL = the local journal */
    const char *cache_dir;        /* handed to kinds (vx_run_cache_dir); NULL = none */
    vx_limits limits;
    size_t max_queued;      /* queued jobs before 429; default 64 */
    size_t history;         /* finished jobs kept; default 10000 */
    uint64_t history_bytes; /* and the memory they may take; 0 = no budget */
    int workers;            /* CPU workers; default 2 */
    /* Starts a job may have that the daemon did not live through (a crash,
     * kill -9, the out-of-memory killer): at the next start past this many
     * it fails `interrupted` instead of running again; default 3. */
    int max_interruptions;
    vx_gl_desc gl;
    vx_jobs_hooks hooks;
    /* Cluster mode (issue 15; src/jobs/cluster.c): the job state and queue
     * in PostgreSQL, shared by every replica: jobs are submitted there,
     * claimed one at a time when the GL thread is free, leased, completed
     * with their attempt as fencing token; results go to the store under
     * results/JOB/ATTEMPT. NULL = the local journal (`journal`, `state`).
     * Its replica name names this daemon in either mode. */
    const vx_pg_desc *database;
    const char *replica; /* this daemon's name in job resources; NULL = host name */
} vx_jobs_desc;

/* Opens the journal and replays it. Owned. Does not start threads. */
vx_jobs *vx_jobs_open(const vx_jobs_desc *desc, vx_err *err);
/* Starts the GL thread (creating the context) and the workers; returns
 * once the context is up, or -1 with the reason it could not be made. */
int vx_jobs_start(vx_jobs *j, vx_err *err);
/* Stops taking jobs; a running job that does not finish at its next progress
 * check is queued again; joins the threads and compacts the journal. */
void vx_jobs_stop(vx_jobs *j);
void vx_jobs_free(vx_jobs *j);
/* Housekeeping, called periodically: compacts the journal once it is
 * larger than max_journal_bytes. */
void vx_jobs_maintain(vx_jobs *j, long max_journal_bytes);

/* Validates (vx_params_normalize: defaults included) and queues a job;
 * before it is journaled the job pins its meshes (a delete then keeps
 * their files until it ends) and stores its large inline params as blobs.
 * Returns its API JSON (owned). Errors: VX_ENOTFOUND mesh_not_found,
 * VX_EUNPROC unknown_kind / invalid_params, VX_EBUSY queue_full, VX_EIO
 * journal or blob store. */
cJSON *vx_jobs_submit(vx_jobs *j, const char *mesh, const char *kind, const cJSON *params,
                      vx_err *err);
/* How a submission may be answered with a job that exists already. */
typedef struct vx_jobs_submit_opts {
    /* An Idempotency-Key (NULL = none; vx_jobs_valid_idem_key): the job
     * submitted with this key and the same request (mesh, kind and
     * normalised params) is answered instead of a new one, as long as it
     * is in the history; the same key with another request is VX_EUNPROC
     * idempotency_key_reused. The key is journaled with the job. */
    const char *idempotency_key;
    /* 1: a succeeded job with the same request whose results are still
     * there is answered instead of a new one. */
    int reuse;
    /* Set (kind not VX_EOK): the error a submission that would make a new
     * job fails with (a full disk); one answered by an existing job is
     * answered still. Local mode. */
    const vx_err *refuse_new;
} vx_jobs_submit_opts;
/* vx_jobs_submit with options; *existing = 1 when the answer is a job that
 * was there already (nothing was queued). */
cJSON *vx_jobs_submit_with(vx_jobs *j, const char *mesh, const char *kind, const cJSON *params,
                           const vx_jobs_submit_opts *opts, int *existing, vx_err *err);
/* 1 when s can be an Idempotency-Key: 1 to 200 visible ASCII characters. */
int vx_jobs_valid_idem_key(const char *s);
/* Deletes a finished job: it leaves the table (404 from then on; a
 * tombstone is journaled) and its results are removed from disk.
 * VX_ENOTFOUND job_not_found; VX_ECONFLICT job_not_finished is never given
 * (an unfinished job is canceled by vx_jobs_cancel instead). 0 or -1. */
int vx_jobs_delete(vx_jobs *j, const char *jid, vx_err *err);
/* API JSON of a job (owned) or NULL (VX_ENOTFOUND job_not_found);
 * *terminal = 1 when it has finished. */
cJSON *vx_jobs_get(vx_jobs *j, const char *jid, int *terminal, vx_err *err);
/* Cancels: a queued job at once (*was_running = 0), a running one at its
 * next progress check (*was_running = 1). VX_ECONFLICT job_finished. */
cJSON *vx_jobs_cancel(vx_jobs *j, const char *jid, int *was_running, vx_err *err);
/* What a job list keeps: NULL fields keep every job. */
typedef struct vx_jobs_filter {
    const char *state, *kind, *mesh;
    int desc; /* newest first: `after` then means older than it */
} vx_jobs_filter;
/* Page of jobs by id (= creation order) after `after` (in f's order), the
 * jobs f keeps (f may be NULL); next = the last id when more follow. NULL
 * with err only in cluster mode (the database unreachable). */
cJSON *vx_jobs_list(vx_jobs *j, const char *after, int limit, const vx_jobs_filter *f,
                    char next[40], vx_err *err);
/* 1 when a kind of this name runs here. */
int vx_jobs_has_kind(vx_jobs *j, const char *kind);
/* Where an output of a finished job is: path, content type and the file name
 * for Content-Disposition. name NULL = the primary output. Errors:
 * job_not_found, job_not_finished / job_failed / job_canceled (VX_ECONFLICT),
 * output_not_found, result_evicted (VX_EGONE). */
int vx_jobs_output(vx_jobs *j, const char *jid, const char *name, char *path, size_t pathn,
                   char ctype[64], char fname[128], vx_err *err);

int vx_jobs_ready(vx_jobs *j);
/* Copy of the GL info taken when the context came up (zeroed before). */
vx_gl_info vx_jobs_gl_info(vx_jobs *j);
/* Jobs queued: this daemon's queue, or in cluster mode the database's
 * (every replica's: what a submission's 429 counts; the local queue while
 * the database does not answer). */
size_t vx_jobs_queue_depth(vx_jobs *j);
/* --max-queued-jobs. */
size_t vx_jobs_queue_capacity(vx_jobs *j);
size_t vx_jobs_running(vx_jobs *j);
/* GL contexts lost during jobs since the table was opened. */
uint64_t vx_jobs_gl_losses(vx_jobs *j);
/* 1 when s is a well-formed job id. */
int vx_jobs_valid_id(const char *s);

/* Cluster mode. Counters of this replica since it started. */
typedef struct vx_jobs_cluster_stats {
    uint64_t claims;            /* jobs claimed */
    uint64_t lease_losses;      /* runs stopped because their lease moved on */
    uint64_t stale_completions; /* results another attempt had already won */
    uint64_t retries;           /* failed attempts handed back for another try */
    uint64_t requeued_expired;  /* other replicas' expired leases re-queued here */
} vx_jobs_cluster_stats;
/* 1 in cluster mode (and *out filled when not NULL), 0 otherwise. */
int vx_jobs_cluster(vx_jobs *j, vx_jobs_cluster_stats *out);
/* Cluster mode: 1 when the database answers now, 0 when not (err says
 * why); 1 in local mode. */
int vx_jobs_database_ok(vx_jobs *j, vx_err *err);
/* 1 while the job state takes records a restart reads (0: the journal was
 * removed or replaced under the daemon; submissions answer 500). */
int vx_jobs_state_intact(vx_jobs *j);
/* Cluster mode: jobs per (state, kind) in the whole database (owned
 * array, free()); -1 with err, or in local mode (VX_ENOTIMPL). */
int vx_jobs_cluster_counts(vx_jobs *j, vx_pg_count **out, size_t *n, vx_err *err);
/* This daemon's replica name. */
const char *vx_jobs_replica(vx_jobs *j);

#endif
