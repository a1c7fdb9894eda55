/* Private to src/jobs: the job table, a run, and the functions the
 * registry (registry.c, pins.c), the snapshots (snapshot.c), the runner
 * (runner.c) and the run service (run.c) share. Locking: "_locked" functions
 * and the fields of vx_jobs marked so need vx_jobs.lock held. */
#ifndef VX_JOBS_INT_H
#define VX_JOBS_INT_H

#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "jobs/jobs.h"
#include "jobs/queue.h"
#include "jobs/state.h"
#include "util/path.h"
#include "util/sorted.h"

typedef enum job_state { ST_QUEUED, ST_RUNNING, ST_SUCCEEDED, ST_FAILED, ST_CANCELED } job_state;
extern const char *const state_names[5];

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
    /* its run, while its finished GL stage waits in the CPU workers' queue
     * (a cancel takes it out of there: no worker may be free for long) */
    struct vx_job_run *waiting;
    int attempts;
    int interruptions;                 /* starts the daemon did not live through (journal only) */
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
    uint64_t fp;    /* fingerprint of kind, mesh and normalised params (dedup.c) */
    char *idem;     /* its Idempotency-Key (owned), or NULL */
    int lease_lost; /* cluster mode: the attempt is no longer ours (renewal said so) */
    int reporting;  /* cluster mode: its end is being reported (still renewed) */
    /* cluster mode, a job split into child jobs (kind.h split): each child
     * as {id, attempt, params, result}, read when it was claimed */
    cJSON *children;
} job;

struct vx_job_run {
    vx_jobs *jobs;
    job *job;
    const vx_kind *kind;
    vx_gl *gl;
    double t0;        /* monotonic start of this attempt */
    double handed;    /* when the GL stage handed it to the CPU workers */
    double waited;    /* seconds it waited for a worker (not held to the timeout) */
    double last_ping; /* watchdog */
    cJSON *stats;
    cJSON *outputs;
    char rid[48];          /* result id: the job id, or (cluster mode) "ID/ATTEMPT" */
    char dir[VX_PATH_MAX]; /* result dir, made at the first output */
    cJSON *paths;          /* strings: every path handed out, valid until the run ends */
    int big_params;        /* its params came from blobs */
    void *typed;           /* the params as the kind's struct, read once per run */
    void *state;
    int on_gl_thread;
};

struct vx_jobs {
    vx_jobs_desc desc;
    const vx_jobstate_ops *st_ops; /* the job state's backend (state.h) */
    void *st;                      /* its handle */
    vx_queue *queue;               /* queued jobs, for the GL thread */
    vx_queue *cpu;                 /* runs that finished their GL stage */
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
    uint64_t gl_losses;    /* contexts lost (atomic) */
    int in_gl;             /* a job is in its GL stage (lock held) */
    char replica[128];     /* desc.replica, or the host name */
    struct vx_cluster *cl; /* cluster mode (desc.database), else NULL */
    /* Jobs the replay saw deleted, sorted once it is done: their result
     * dirs are a cut-short delete's leftovers (vx_jobs_open only). */
    char (*gone)[33];
    size_t ngone, capgone;
};

/* registry.c */
void pinset_free(pinset *ps);
void job_free(job *jb);
int is_terminal(job_state s);
double ms_between(double a, double b);
/* api = 1: the API resource (with the replica's name); api = 0: the
 * journal snapshot. Caller holds the lock. */
cJSON *job_json(const vx_jobs *j, const job *jb, int api);
/* A new time-ordered job id: 48 bits of milliseconds, then 80 random bits. */
void jobs_new_id(char out[33]);
void freeze_locked(vx_jobs *j, job *jb);
const char *job_key(const void *item);
job *job_at(const vx_jobs *j, size_t i);
job *find_job(vx_jobs *j, const char *id);
void trim_history_locked(vx_jobs *j, char (*dropped)[33], size_t *ndropped, size_t max);
void notify(vx_jobs *j, const char *jid, int terminal);
/* Output name (NULL = the primary: the first) of job jid in state (a
 * state name; failure = why it failed): its entry in outputs, with its file
 * name and content type; NULL with err (job_not_finished, job_failed,
 * job_canceled, output_not_found). */
const cJSON *job_output_entry(const char *jid, const char *state, const char *failure,
                              const cJSON *outputs, const char *name, char file[160],
                              char ctype[64], vx_err *err);
/* Owned copies of a job's params, stats and outputs (empty objects where
 * there are none; NULL: not wanted): from its trees, or from the text of a
 * finished job. */
void job_parts(const job *jb, cJSON **params, cJSON **stats, cJSON **outputs);
/* 0, or -1 with VX_EGONE result_damaged when the file at path is not the
 * want bytes its job recorded (want < 0: not recorded, as before), or
 * result_evicted when it is not there at all. */
int job_output_check_size(const char *jid, const char *path, double want, vx_err *err);

/* pins.c */
void unpin_job(vx_jobs *j, pinset *ps);
int pin_job(vx_jobs *j, const char *mesh, const vx_kind *k, const cJSON *params, int replay,
            pinset *ps, vx_err *err);
int externalize(vx_jobs *j, const vx_kind *k, cJSON *params, pinset *ps, vx_err *err);
cJSON *inline_params(vx_jobs *j, const vx_kind *k, const cJSON *params, int *big, vx_err *err);

/* runner.c */
/* Reads mesh id from the store: the file the store checked, read through
 * its fd, and still that version once read (a write in place meanwhile:
 * VX_EGONE mesh_damaged). An owned mesh, or NULL with err. Any thread. */
vx_mesh *vx_jobs_read_mesh(vx_jobs *j, const char *id, vx_err *err);
/* Calls the desc's alive hook (the daemon's watchdog ping). */
void jobs_alive(vx_jobs *j);
/* After a cancel was recorded for job jid: a run of it waiting for a CPU
 * worker ends canceled now instead of when a worker takes it. Without the
 * lock. */
void jobs_cancel_waiting(vx_jobs *j, const char *jid);

/* dedup.c */
/* The fingerprint of a request: kind, mesh and its params as journaled. */
uint64_t request_fp(const char *kind, const char *mesh, const cJSON *params);
/* The job that answers a submission instead of jb (fp, idem and params
 * filled), or NULL; VX_EUNPROC idempotency_key_reused in err (and NULL) for
 * a key of another request. Caller holds the lock. */
job *find_existing_locked(vx_jobs *j, const job *jb, int reuse, vx_err *err);

/* cluster.c: cluster mode (desc.database). */
/* The job state in cluster mode: keeps nothing (the database does). */
extern const vx_jobstate_ops cluster_state;
/* Connects (three connections), migrates the schema, and replaces the
 * local journal by a state that keeps nothing: called by vx_jobs_open
 * before the replay. */
int cluster_open(vx_jobs *j, vx_err *err);
/* Starts the claimer, the lease renewer and the listener (after the GL
 * thread is up). */
int cluster_start(vx_jobs *j, vx_err *err);
/* Stops claiming, then (after the GL thread has stopped) hands back what
 * was claimed but not run. */
void cluster_stop_claims(vx_jobs *j);
void cluster_release_queued(vx_jobs *j);
void cluster_free(vx_jobs *j);
/* The table's API in cluster mode (registry.c hands over). params are the
 * normalised ones, pins what the submission holds (released here). */
cJSON *cluster_submit(vx_jobs *j, const char *mesh, const vx_kind *k, cJSON *params, uint64_t fp,
                      const vx_jobs_submit_opts *opts, int *existing, vx_err *err);
/* The job an Idempotency-Key names, when it is the request of fingerprint
 * fp; NULL otherwise (none, another request, or the database not
 * answering). */
cJSON *cluster_find_idem(vx_jobs *j, const char *key, uint64_t fp);
cJSON *cluster_get(vx_jobs *j, const char *jid, int *terminal, vx_err *err);
cJSON *cluster_cancel(vx_jobs *j, const char *jid, int *was_running, vx_err *err);
cJSON *cluster_list(vx_jobs *j, const char *after, int limit, const vx_jobs_filter *f,
                    char next[40], vx_err *err);
int cluster_delete(vx_jobs *j, const char *jid, vx_err *err);
int cluster_output(vx_jobs *j, const char *jid, const char *name, char *path, size_t pathn,
                   char ctype[64], char fname[128], vx_err *err);
/* Reports how run r of jb ended to the database (with retries while it is
 * unreachable and the lease may still hold): ok = succeeded (its outputs
 * are in the store under r->rid), requeue = shutdown (handed back),
 * else failed or canceled by e. Writes the state the job is in now into
 * state ("" when the attempt was no longer ours: nothing changed). */
void cluster_report(vx_jobs *j, job *jb, vx_job_run *r, int ok, const vx_err *e, int requeue,
                    char state[16]);
/* Wakes the claimer (a job finished: the GL thread is free). */
void cluster_wake(vx_jobs *j);
/* Jobs queued in the database, every replica's (what a submission's 429
 * counts); -1 when it does not answer. */
long cluster_queued(vx_jobs *j);

/* snapshot.c */
/* Journals that jb is deleted (a record replay drops it on). */
int journal_delete_locked(vx_jobs *j, job *jb, vx_err *err);
int journal_locked(vx_jobs *j, job *jb, vx_err *err);
int compact_locked(vx_jobs *j, vx_err *err);

#endif
