/* PostgreSQL job state and queue (libpq): the tables several voxeld
 * replicas share when --database is given (issue #15); the job layer's
 * cluster mode (src/jobs/cluster.c) calls it.
 *
 * Model: one row per job in vx_jobs (docs/scaling.md has the schema). A
 * replica claims a queued row (FOR UPDATE SKIP LOCKED), which sets
 * replica, attempt + 1 and a lease on the database clock; it renews the
 * lease while it runs and finishes the row with the attempt it claimed as
 * fencing token, so a replica that lost its lease changes nothing. Any
 * replica re-queues rows whose lease expired, with backoff, and fails them
 * after max_attempts. A job queued (submitted or re-queued), finished or
 * asked to cancel sends NOTIFY on channel vx_jobs (a trigger), payload
 * "STATE ID KIND" ("cancel ID KIND" for a running job asked to cancel); a
 * claim sends nothing.
 *
 * Threads: a vx_pg is one connection; its calls are serialized by a mutex,
 * so any thread may call, one at a time. vx_pg_wait holds the connection
 * while it waits: give waiters (and the lease renewer, which must not
 * queue behind slow calls) their own handle.
 *
 * Errors: a database that cannot be reached (down, restarting, refusing
 * connections) is VX_EUNAVAIL database_unavailable: the API answers 503
 * with Retry-After vx_pg_retry_after(). The next call reconnects, with an
 * exponential backoff between tries (0.1 s doubling to reconnect_max_s);
 * reads and renewals are re-run once on a fresh connection, writes are not
 * (the caller cannot know whether a lost COMMIT happened). */
#ifndef VX_JOBS_PG_H
#define VX_JOBS_PG_H

#include <stddef.h>

#include <cjson/cJSON.h>

#include "util/err.h"

/* The schema version this binary creates and understands. */
#define VX_PG_SCHEMA_VERSION 5
/* The NOTIFY channel every state change is sent on. */
#define VX_PG_CHANNEL "vx_jobs"

typedef struct vx_pg vx_pg;

typedef struct vx_pg_desc {
    const char *url;          /* postgresql://… or postgres://… (libpq URI); required */
    const char *replica;      /* this replica's name (claims, errors); NULL = host name */
    double lease_s;           /* lease TTL on the database clock; 0 = 30 */
    int max_attempts;         /* attempts a job gets at submission; 0 = 3 */
    double backoff_s;         /* re-queue delay after attempt 1, doubled per attempt; 0 = 1 */
    double backoff_max_s;     /* its ceiling; 0 = 60 */
    double connect_timeout_s; /* one connection attempt; 0 = 5 (the URL's connect_timeout wins) */
    double reconnect_max_s;   /* ceiling of the wait between reconnection tries; 0 = 5 */
    /* How long a statement may go unanswered before its connection is
     * dropped (a database that hangs without closing: a black-holed link,
     * a stopped server, a held lock); also the server's statement_timeout
     * and lock_timeout. 0 = 10. */
    double statement_timeout_s;
    /* How long a call waits for the handle another thread's statement
     * holds before it answers 503 database_unavailable; 0 = as long as it
     * takes (the API handle sets it: its callers are HTTP threads). */
    double lock_wait_s;
} vx_pg_desc;

/* The connect_timeout a libpq URL sets (seconds, as libpq takes it: 2 at
 * least), 0 when it sets none or does not parse. */
double vx_pg_url_connect_timeout(const char *url);

/* A job row. Times are Unix seconds on the database clock; 0 = not set. */
typedef struct vx_pg_job {
    char id[33]; /* vx_jobs_valid_id */
    char kind[64];
    char mesh[65];     /* "" = none */
    char parent[33];   /* the parent job of a brick; "" = none */
    char state[16];    /* queued, running, succeeded, failed, canceled */
    char replica[128]; /* that claimed the current/last attempt; "" = none yet */
    int attempt;       /* 0 until claimed; the fencing token */
    int max_attempts;
    int cancel_requested;
    double created, started, finished, lease_expires, not_before;
    double progress; /* 0..1, as the running replica last renewed it */
    char idem[201];  /* its Idempotency-Key; "" = none */
    char fp[17];     /* the request's fingerprint (hex); "" = none */
    int children;    /* child jobs it was split into (it runs once they all succeeded) */
    cJSON *params;   /* object (owned) */
    cJSON *result;   /* the result manifest (owned), NULL until succeeded */
    cJSON *errors;   /* array of {attempt, replica, kind, code, message, at} (owned) */
} vx_pg_job;

/* What a submission creates. */
typedef struct vx_pg_new_job {
    const char *id;      /* required, vx_jobs_valid_id */
    const char *kind;    /* required */
    const char *mesh;    /* NULL = none */
    const char *parent;  /* NULL = none (a brick names its parent) */
    const cJSON *params; /* NULL = {} */
    int max_attempts;    /* 0 = the desc's */
    const char *fp;      /* the request's fingerprint (reuse); NULL = none */
    const char *idem;    /* its Idempotency-Key (unique: a taken one is job_exists); NULL = none */
    int children;        /* the child jobs submitted with it (they name it as parent) */
} vx_pg_new_job;

/* What a list keeps: NULL fields keep every job. */
typedef struct vx_pg_filter {
    const char *state, *kind, *parent, *mesh;
    int desc; /* newest first: `after` then means older than it */
} vx_pg_filter;

/* Jobs in one state of one kind. */
typedef struct vx_pg_count {
    char state[16];
    char kind[64];
    long n;
} vx_pg_count;

/* Connects (url checked: VX_EINVAL invalid_database_url; unreachable:
 * VX_EUNAVAIL database_unavailable). Owned; does not touch the schema. */
vx_pg *vx_pg_open(const vx_pg_desc *desc, vx_err *err);
/* Closes the connection and frees (NULL is fine). */
void vx_pg_close(vx_pg *pg);
/* Creates or migrates the schema to VX_PG_SCHEMA_VERSION in one
 * transaction under an advisory lock (replicas may start together); a
 * no-op when current. A newer schema than this binary knows is
 * VX_ECONFLICT database_schema_newer (refuse to start). Returns the version. */
int vx_pg_migrate(vx_pg *pg, vx_err *err);
/* The cluster's blob-store id (vx_settings.store_id), decided under a
 * session advisory lock, so that replicas starting together take turns:
 * check gets the database's id (NULL: none yet) and returns 0 with the id
 * to keep in out (stored when the database had none), 1 to leave it
 * undecided, or -1 with err (the replica's store is not the cluster's).
 * 0, or -1 with err. */
#define VX_PG_STORE_ID 65
int vx_pg_store_id(vx_pg *pg,
                   int (*check)(void *ud, const char *have, char out[VX_PG_STORE_ID], vx_err *err),
                   void *ud, vx_err *err);
/* Seconds a caller should wait before retrying after VX_EUNAVAIL (>= 1). */
int vx_pg_retry_after(vx_pg *pg);
/* This handle's replica name. */
const char *vx_pg_replica(const vx_pg *pg);

/* Inserts n queued jobs (a parent and its bricks) in one transaction;
 * returns 0 only once it is committed. VX_ECONFLICT job_exists for a taken
 * id, VX_ENOTFOUND parent_not_found, VX_EUNPROC invalid_params for a bad id. */
int vx_pg_submit(vx_pg *pg, const vx_pg_new_job *jobs, size_t n, vx_err *err);
/* Inserts one queued job with an Idempotency-Key (job->idem; none: as
 * vx_pg_submit): 0 when inserted (committed), 1 when the key's job was
 * there already with the same fingerprint (*existing filled: clear it),
 * -1 with VX_EUNPROC idempotency_key_reused (another fingerprint) or the
 * database's error. */
int vx_pg_submit_idem(vx_pg *pg, const vx_pg_new_job *job, vx_pg_job *existing, vx_err *err);
/* The newest succeeded job of fingerprint fp into *out: 1 found, 0 none,
 * -1 err. */
int vx_pg_find_done(vx_pg *pg, const char *fp, vx_pg_job *out, vx_err *err);
/* Of job id's child jobs: how many succeeded, how many there are. */
int vx_pg_child_counts(vx_pg *pg, const char *id, int *done, int *total, vx_err *err);
/* The job holding Idempotency-Key key into *out: 1 found, 0 none, -1 err. */
int vx_pg_find_idem(vx_pg *pg, const char *key, vx_pg_job *out, vx_err *err);
/* Deletes a finished job (its results index rows go with it).
 * VX_ENOTFOUND job_not_found, VX_ECONFLICT job_not_finished. */
int vx_pg_delete(vx_pg *pg, const char *id, vx_err *err);
/* Queued jobs in the whole table, or -1 with err. */
long vx_pg_queued(vx_pg *pg, vx_err *err);
/* One round trip (a read of vx_jobs: a lock held on the table fails it
 * at lock_timeout), reconnecting first when needed: /readyz. */
int vx_pg_ping(vx_pg *pg, vx_err *err);
/* Reads a job into *out (vx_pg_job_clear it). VX_ENOTFOUND job_not_found. */
int vx_pg_get(vx_pg *pg, const char *id, vx_pg_job *out, vx_err *err);
/* Frees what a vx_pg_job owns and zeroes it. */
void vx_pg_job_clear(vx_pg_job *jb);
/* Up to limit (1..1000) jobs by id (creation order) after `after` (NULL =
 * from the start; may be next) that f keeps (f may be NULL) into *out (owned array:
 * vx_pg_jobs_free); next = the last id when more follow, else "". */
int vx_pg_list(vx_pg *pg, const vx_pg_filter *f, const char *after, int limit, vx_pg_job **out,
               size_t *n, char next[33], vx_err *err);
/* Frees an array vx_pg_list returned. */
void vx_pg_jobs_free(vx_pg_job *jobs, size_t n);

/* Claims the oldest queued job whose backoff has passed, of one of kinds
 * (comma-separated names; NULL = any): running, replica = ours, attempt +
 * 1, lease = now() + lease_s. Returns 1 with *out filled, 0 when there is
 * none, -1 with err. */
int vx_pg_claim(vx_pg *pg, const char *kinds, vx_pg_job *out, vx_err *err);
/* Extends the lease of (id, attempt) held by this replica to now() +
 * lease_s and records the run's progress (0..1). Returns 0 held (*cancel =
 * 1 when a cancel was requested), 1 lost (the row moved on: re-queued,
 * finished or claimed again: stop the run), -1 with err (the lease may
 * still be held: try again). */
int vx_pg_renew(vx_pg *pg, const char *id, int attempt, double progress, int *cancel, vx_err *err);
/* Seconds between the renewals a runner should make: a third of the TTL
 * (10 s of the default 30 s), so that two can fail before the lease goes. */
double vx_pg_renew_interval(const vx_pg *pg);
/* Marks (id, attempt) of this replica succeeded with its result manifest
 * (an object; members of its "outputs" object, {"location", "bytes",
 * "content_type"}, are indexed in vx_results) in one statement. Returns 0
 * done, 1 stale (another attempt owns the row: nothing changed), -1 err. */
int vx_pg_complete(vx_pg *pg, const char *id, int attempt, const cJSON *result, vx_err *err);
/* Records why (id, attempt) of this replica failed in its errors, then:
 * canceled when why is VX_ECANCELED by a client, queued again after the
 * backoff when retry is set and attempts are left, else failed. Returns 0
 * done (*state_out, may be NULL, gets the new state), 1 stale, -1 err. */
int vx_pg_fail(vx_pg *pg, const char *id, int attempt, const vx_err *why, int retry,
               char state_out[16], vx_err *err);
/* Hands (id, attempt) back unrun (shutdown): queued at once, and the
 * attempt it used is given back to max_attempts. 0, 1 stale, -1 err. */
int vx_pg_release(vx_pg *pg, const char *id, int attempt, vx_err *err);
/* Re-queues up to max (0 = 100) running jobs whose lease has expired, with
 * the backoff, recording lease_expired in their errors; a job out of
 * attempts fails, a job with a cancel request is canceled. Any replica
 * calls it. Returns how many it moved; *requeued / *failed (may be NULL). */
int vx_pg_requeue_expired(vx_pg *pg, int max, int *requeued, int *failed, vx_err *err);
/* Cancels: a queued job at once (*was_running = 0), a running one by its
 * cancel request, which its replica's renew sees (*was_running = 1).
 * VX_ENOTFOUND job_not_found, VX_ECONFLICT job_finished. */
int vx_pg_cancel(vx_pg *pg, const char *id, int *was_running, vx_err *err);

/* LISTEN on VX_PG_CHANNEL (again after each reconnection). */
int vx_pg_listen(vx_pg *pg, vx_err *err);
/* Waits up to timeout_s for a notification; 1 with its payload, 0 on
 * timeout or while the database is unreachable (the caller then re-reads
 * what it waits for: the polling fallback), -1 when not listening. */
int vx_pg_wait(vx_pg *pg, double timeout_s, char *payload, size_t payload_n, vx_err *err);

/* The mesh catalog (pg_mesh.c): which meshes exist, for every replica.
 * An upload holds its id's lock (shared) from before its bytes go into
 * the blob store until its row is written, so that a purge never takes
 * the bytes of a mesh that is coming back. */
int vx_pg_mesh_lock(vx_pg *pg, const char *id, vx_err *err);
void vx_pg_mesh_unlock(vx_pg *pg, const char *id);
/* Writes mesh id's row from its metadata (an object with format, bytes,
 * triangles): *existed = 1 when a live row was there (it stays as it was),
 * else the row is new or a deleted one is back; *stored (may be NULL) =
 * the row's metadata now (owned). 0 or -1 with err. */
int vx_pg_mesh_put(vx_pg *pg, const char *id, const cJSON *meta, int *existed, cJSON **stored,
                   vx_err *err);
/* A live mesh's metadata into *meta (owned): 1, 0 when there is none
 * (absent or deleted), -1 with err. */
int vx_pg_mesh_get(vx_pg *pg, const char *id, cJSON **meta, vx_err *err);
/* Marks a live mesh deleted (gone for the API at once; its bytes stay for
 * the jobs that name it). VX_ENOTFOUND mesh_not_found. */
int vx_pg_mesh_delete(vx_pg *pg, const char *id, vx_err *err);
/* Up to limit (1..1000) live meshes' metadata by id after `after` (NULL =
 * first): an owned array, next = the last id when more follow, else "";
 * NULL with err. */
cJSON *vx_pg_mesh_list(vx_pg *pg, const char *after, int limit, char next[65], vx_err *err);
/* Live meshes, or -1 with err. */
long vx_pg_mesh_count(vx_pg *pg, vx_err *err);
/* Adds the meshes of an array of metadata objects that have no row (a
 * store that held meshes before the catalog did); rows that exist, live or
 * deleted, stay. Returns how many it added, or -1. */
int vx_pg_mesh_add_missing(vx_pg *pg, const cJSON *metas, vx_err *err);
/* Removes the bytes of one purged mesh (format: its metadata's) from the
 * blob store: 0, or -1 to keep its row for a later purge. */
typedef int (*vx_pg_purge_fn)(void *ud, const char *id, const char *format);
/* For up to max (0 = 100) deleted meshes that no queued or running job
 * names: under the mesh's lock, deletes the row and calls fn, in one
 * transaction. Returns how many went, or -1 with err. */
int vx_pg_mesh_purge(vx_pg *pg, int max, vx_pg_purge_fn fn, void *ud, vx_err *err);

/* Jobs per (state, kind), every state (owned array, free()). The KEDA
 * trigger's query is in docs/scaling.md. */
int vx_pg_counts(vx_pg *pg, vx_pg_count **out, size_t *n, vx_err *err);

#endif
