/* PostgreSQL job state and queue (pg.h): schema, submission, claims,
 * leases, fenced completion, re-queueing, cancel, LISTEN/NOTIFY, counts. */
#include "jobs/pg.h"

#include <errno.h>
#include <poll.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <libpq-fe.h>

#include "jobs/jobs.h"
#include "jobs/pg_int.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/json.h"

/* Schema migrations: migrations[v - 1] brings version v - 1 to v. Each is
 * applied in the transaction that records it in vx_schema. */
static const char *const migrations[] = {
    /* 1: jobs (with bricks' parents), the results index, mesh metadata, the
     * NOTIFY trigger. Claims notify nobody: a NOTIFY serializes commits (a
     * global lock at commit), which halved the claim rate with 4 claimers
     * (bench/RESULTS.md); who waits wants a job queued, finished or
     * canceled. */
    "CREATE TABLE vx_jobs ("
    " id text COLLATE \"C\" PRIMARY KEY,"
    " kind text NOT NULL,"
    " mesh text,"
    " parent_id text COLLATE \"C\" REFERENCES vx_jobs(id) ON DELETE CASCADE,"
    " params jsonb NOT NULL DEFAULT '{}',"
    " state text NOT NULL DEFAULT 'queued'"
    "  CHECK (state IN ('queued','running','succeeded','failed','canceled')),"
    " attempt integer NOT NULL DEFAULT 0,"
    " max_attempts integer NOT NULL CHECK (max_attempts >= 1),"
    " replica text,"
    " lease_expires timestamptz,"
    " not_before timestamptz NOT NULL DEFAULT now(),"
    " cancel_requested boolean NOT NULL DEFAULT false,"
    " errors jsonb NOT NULL DEFAULT '[]',"
    " result jsonb,"
    " created timestamptz NOT NULL DEFAULT now(),"
    " started timestamptz,"
    " finished timestamptz,"
    " updated timestamptz NOT NULL DEFAULT now());"
    /* Claims scan only queued rows (finished ones stay out of the index). */
    "CREATE INDEX vx_jobs_queued ON vx_jobs (id) WHERE state = 'queued';"
    "CREATE INDEX vx_jobs_leases ON vx_jobs (lease_expires) WHERE state = 'running';"
    "CREATE INDEX vx_jobs_parent ON vx_jobs (parent_id, id) WHERE parent_id IS NOT NULL;"
    "CREATE INDEX vx_jobs_state_kind ON vx_jobs (state, kind, id);"
    "CREATE TABLE vx_results ("
    " job_id text COLLATE \"C\" NOT NULL REFERENCES vx_jobs(id) ON DELETE CASCADE,"
    " attempt integer NOT NULL,"
    " name text NOT NULL,"
    " location text,"
    " bytes bigint,"
    " content_type text,"
    " created timestamptz NOT NULL DEFAULT now(),"
    " PRIMARY KEY (job_id, attempt, name));"
    "CREATE TABLE vx_meshes ("
    " id text COLLATE \"C\" PRIMARY KEY CHECK (id ~ '^[0-9a-f]{64}$'),"
    " format text,"
    " bytes bigint NOT NULL,"
    " triangles bigint,"
    " meta jsonb NOT NULL DEFAULT '{}',"
    " created timestamptz NOT NULL DEFAULT now());"
    "CREATE FUNCTION vx_jobs_notify() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN"
    " IF TG_OP = 'INSERT' OR (NEW.state <> OLD.state AND NEW.state <> 'running')"
    "  OR (NEW.cancel_requested AND NOT OLD.cancel_requested) THEN"
    "  PERFORM pg_notify('" VX_PG_CHANNEL "', CASE WHEN NEW.state = 'running' THEN 'cancel'"
    "   ELSE NEW.state END || ' ' || NEW.id || ' ' || NEW.kind);"
    " END IF; RETURN NULL; END $$;"
    "CREATE TRIGGER vx_jobs_notify AFTER INSERT OR UPDATE ON vx_jobs"
    " FOR EACH ROW EXECUTE FUNCTION vx_jobs_notify();",
    /* 2: what the daemon's job resource needs: progress (written with each
     * lease renewal), the Idempotency-Key and the request's fingerprint
     * (reuse of a succeeded job), and lists by mesh. */
    "ALTER TABLE vx_jobs ADD COLUMN progress double precision NOT NULL DEFAULT 0,"
    " ADD COLUMN idem_key text, ADD COLUMN fp text,"
    /* json keeps the text as sent: params in their spec's order, outputs
     * in declaration order (the first is the primary one). */
    " ALTER COLUMN params TYPE json USING params::json,"
    " ALTER COLUMN params SET DEFAULT '{}', ALTER COLUMN result TYPE json USING result::json;"
    "CREATE UNIQUE INDEX vx_jobs_idem ON vx_jobs (idem_key) WHERE idem_key IS NOT NULL;"
    "CREATE INDEX vx_jobs_fp ON vx_jobs (fp, id) WHERE state = 'succeeded';"
    "CREATE INDEX vx_jobs_mesh ON vx_jobs (mesh, id);",
    /* 3: jobs split into child jobs (bricks): `children` counts them; the
     * parent is claimable once they all succeeded (vx_pg_claim); a child
     * that fails or is canceled fails its waiting parent and cancels its
     * siblings (this trigger, so that it holds whoever ends the child: its
     * replica, the re-queue of an expired lease, a cancel). */
    "ALTER TABLE vx_jobs ADD COLUMN children integer NOT NULL DEFAULT 0;"
    "CREATE FUNCTION vx_jobs_child_ended() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN"
    " IF NEW.state IN ('failed', 'canceled') AND OLD.state IN ('queued', 'running') THEN"
    "  UPDATE vx_jobs SET state = 'failed', finished = now(), updated = now(),"
    "   errors = errors || jsonb_build_array(jsonb_build_object('attempt', attempt,"
    "    'replica', NEW.replica, 'kind', 'unproc', 'code', 'child_' || NEW.state,"
    "    'message', 'child job ' || NEW.id || ' ' || NEW.state"
    "     || coalesce(': ' || (NEW.errors -> -1 ->> 'message'), ''), 'at', now()))"
    "   WHERE id = NEW.parent_id AND state = 'queued';"
    "  UPDATE vx_jobs SET cancel_requested = true,"
    "   state = CASE WHEN state = 'queued' THEN 'canceled' ELSE state END,"
    "   finished = CASE WHEN state = 'queued' THEN now() ELSE finished END, updated = now()"
    "   WHERE parent_id = NEW.parent_id AND state IN ('queued', 'running')"
    "   AND NOT cancel_requested;"
    " END IF; RETURN NULL; END $$;"
    "CREATE TRIGGER vx_jobs_child_ended AFTER UPDATE OF state ON vx_jobs FOR EACH ROW"
    " WHEN (NEW.parent_id IS NOT NULL) EXECUTE FUNCTION vx_jobs_child_ended();",
    /* 4: the mesh catalog (pg_mesh.c): a deleted mesh keeps its row, marked,
     * until no unfinished job names it; metadata keeps its key order. */
    "ALTER TABLE vx_meshes ALTER COLUMN meta TYPE json USING meta::json,"
    " ALTER COLUMN meta SET DEFAULT '{}'::json, ADD COLUMN deleted timestamptz;"
    "CREATE INDEX vx_meshes_deleted ON vx_meshes (deleted) WHERE deleted IS NOT NULL;",
    /* 5: settings the replicas share: the blob store's id (vx_pg_store_id). */
    "CREATE TABLE vx_settings (key text PRIMARY KEY, value text NOT NULL);",
};
_Static_assert(sizeof migrations / sizeof migrations[0] == VX_PG_SCHEMA_VERSION,
               "one migration per schema version");

/* The columns read_row reads, in its order. */
#define JOB_COLS                                                                                   \
    "id, kind, coalesce(mesh, ''), coalesce(parent_id, ''), state, coalesce(replica, ''),"         \
    " attempt, max_attempts, cancel_requested, extract(epoch from created),"                       \
    " coalesce(extract(epoch from started), 0), coalesce(extract(epoch from finished), 0),"        \
    " coalesce(extract(epoch from lease_expires), 0), extract(epoch from not_before),"             \
    " params::text, result::text, errors::text, progress, coalesce(idem_key, ''),"                 \
    " coalesce(fp, ''), children"

/* The backoff before attempt + 1, from the desc's base ($B) and ceiling ($M). */
#define BACKOFF(B, M)                                                                              \
    "make_interval(secs => least(" M "::float8, " B "::float8 * power(2, attempt - 1)))"

static double dflt(double v, double d)
{
    return v > 0 ? v : d;
}

static void quiet_notice(void *arg, const char *msg)
{
    (void)arg;
    vx_log(VX_LOG_DEBUG, "pg.notice", "message=%.200s", msg);
}

/* First line of a libpq message, for an error's text. */
static void first_line(char *dst, size_t n, const char *msg)
{
    snprintf(dst, n, "%s", msg && *msg ? msg : "unknown error");
    dst[strcspn(dst, "\n")] = 0;
}

/* Drops the connection; the next call reconnects at once. */
static void drop_locked(vx_pg *pg)
{
    if (pg->conn) PQfinish(pg->conn);
    pg->conn = NULL;
    if (pg->listening) pg->missed = 1;
}

/* libpq's reason goes to the log only: it names the server's socket path
 * or host, which answers to clients never do (the header Retry-After says
 * when to try again). */
static int unavailable(vx_pg *pg, vx_err *err, const char *what)
{
    char line[400];
    first_line(line, sizeof line, what);
    if (strcmp(what, "waiting to reconnect")) /* logged once a failure, not per request */
        VX_WARN("pg.unavailable", "reason=%s retry_in_s=%d",
                vx_log_quote((char[480]){0}, 480, line), vx_pg_retry_after(pg));
    return vx_err_set(err, VX_EUNAVAIL, "database_unavailable",
                      "the database is unreachable; try again shortly");
}

/* Makes sure there is a connection; VX_EUNAVAIL (without trying) while the
 * backoff after a failed attempt runs. */
static int connect_locked(vx_pg *pg, vx_err *err)
{
    if (pg->conn && PQstatus(pg->conn) == CONNECTION_OK) return 0;
    if (pg->conn) drop_locked(pg);
    if (vx_mono() < pg->next_try) return unavailable(pg, err, "waiting to reconnect");
    char timeout[32], options[128], user_timeout[32];
    snprintf(timeout, sizeof timeout, "%d", (int)(pg->desc.connect_timeout_s + 0.999));
    int st_ms = (int)(pg->desc.statement_timeout_s * 1000);
    snprintf(options, sizeof options, "-c statement_timeout=%d -c lock_timeout=%d", st_ms,
             st_ms / 2);
    snprintf(user_timeout, sizeof user_timeout, "%d", st_ms);
    /* Earlier keywords are defaults the URL (expanded at dbname) overrides:
     * keepalives and tcp_user_timeout find a peer that vanished, the
     * server's timeouts a statement that waits on a lock or runs away. */
    const char *keys[] = {"connect_timeout",
                          "application_name",
                          "keepalives",
                          "keepalives_idle",
                          "keepalives_interval",
                          "keepalives_count",
                          "tcp_user_timeout",
                          "options",
                          "dbname",
                          NULL};
    const char *vals[] = {timeout, "voxeld",     "1",     "5",     "2",
                          "3",     user_timeout, options, pg->url, NULL};
    PGconn *c = PQconnectdbParams(keys, vals, 1);
    if (!c || PQstatus(c) != CONNECTION_OK) {
        char msg[400];
        first_line(msg, sizeof msg, c ? PQerrorMessage(c) : "out of memory");
        if (c) PQfinish(c);
        pg->next_try = vx_mono() + pg->backoff;
        pg->backoff =
            pg->backoff * 2 < pg->desc.reconnect_max_s ? pg->backoff * 2 : pg->desc.reconnect_max_s;
        vx_log(VX_LOG_WARN, "pg.connect_failed", "retry_s=%.1f", pg->next_try - vx_mono());
        return unavailable(pg, err, msg);
    }
    PQsetNoticeProcessor(c, quiet_notice, NULL);
    pg->conn = c;
    pg->backoff = 0.1;
    pg->next_try = 0;
    if (pg->listening) {
        PGresult *r = PQexec(c, "LISTEN " VX_PG_CHANNEL);
        int ok = PQresultStatus(r) == PGRES_COMMAND_OK;
        PQclear(r);
        if (!ok) {
            drop_locked(pg);
            return unavailable(pg, err, "LISTEN failed");
        }
    }
    vx_log(VX_LOG_INFO, "pg.connected", "replica=%s", pg->replica);
    return 0;
}

/* Maps a failed statement to a vx_err by its SQLSTATE. */
static int map_error(vx_pg *pg, const PGresult *r, int lost, vx_err *err)
{
    const char *state = r ? PQresultErrorField(r, PG_DIAG_SQLSTATE) : NULL;
    char msg[400];
    first_line(msg, sizeof msg,
               r && *PQresultErrorMessage(r) ? PQresultErrorMessage(r)
                                             : (pg->conn ? PQerrorMessage(pg->conn) : NULL));
    if (!state) state = "";
    /* 57014: statement_timeout; 55P03: lock_timeout */
    if (lost || !strncmp(state, "08", 2) || !strncmp(state, "57P", 3) || !strcmp(state, "57014") ||
        !strcmp(state, "55P03"))
        return unavailable(pg, err, msg);
    if (!strcmp(state, "53100"))
        return vx_err_set(err, VX_ENOSPC, "database_full", "the database is full: %s", msg);
    if (!strncmp(state, "53", 2) || !strcmp(state, "40001") || !strcmp(state, "40P01"))
        return vx_err_set(err, VX_EOVERLOAD, "database_overloaded", "%s", msg);
    if (!strcmp(state, "23505"))
        return vx_err_set(err, VX_ECONFLICT, "job_exists", "a job with this id exists: %s", msg);
    if (!strcmp(state, "23503"))
        return vx_err_set(err, VX_ENOTFOUND, "parent_not_found", "%s", msg);
    vx_log(VX_LOG_ERR, "pg.error", "sqlstate=%s", state);
    return vx_err_set(err, VX_EINTERNAL, "database_error", "database error %s: %s", state, msg);
}

/* PQexecParams (or PQexec when n is 0: the last result of the statements,
 * or the first error) with a deadline of statement_timeout_s: a database
 * that never answers (its link black-holed, the server stopped) made the
 * calling thread wait forever, an HTTP thread included. NULL with
 * *timed_out set past it. */
static PGresult *exec_deadline(vx_pg *pg, const char *sql, int n, const char *const *vals,
                               int *timed_out)
{
    *timed_out = 0;
    int sent = n ? PQsendQueryParams(pg->conn, sql, n, NULL, vals, NULL, NULL, 0)
                 : PQsendQuery(pg->conn, sql);
    if (!sent) return NULL;
    double deadline = vx_mono() + pg->desc.statement_timeout_s;
    PGresult *keep = NULL;
    for (;;) {
        while (PQisBusy(pg->conn)) {
            double left = deadline - vx_mono();
            struct pollfd p = {.fd = PQsocket(pg->conn), .events = POLLIN};
            int rc = left > 0 ? poll(&p, 1, (int)(left * 1000) + 1) : 0;
            if (rc < 0 && errno == EINTR) continue;
            if (rc == 0) {
                *timed_out = 1;
                PQclear(keep);
                return NULL;
            }
            if (rc < 0 || !PQconsumeInput(pg->conn)) break; /* PQgetResult says why */
        }
        PGresult *r = PQgetResult(pg->conn);
        if (!r) return keep;
        if (keep && PQresultStatus(keep) == PGRES_FATAL_ERROR) {
            PQclear(r); /* the first error stands */
        } else {
            PQclear(keep);
            keep = r;
        }
    }
}

/* A connection whose server has closed it (a restart: its goodbye, then
 * EOF, wait on the socket) is dropped before a statement goes out on it:
 * found only by the statement, a write that is not retried (a cancel, a
 * delete) answered 503 once per connection after every restart. */
static void drop_if_closed(vx_pg *pg)
{
    /* the goodbye (FATAL: terminating connection) is read as data and
     * leaves the connection OK; the EOF after it, read next, does not */
    for (int reads = 0; reads < 2; reads++) {
        struct pollfd p = {.fd = pg->conn ? PQsocket(pg->conn) : -1, .events = POLLIN};
        if (p.fd < 0 || poll(&p, 1, 0) != 1) return;
        if (PQconsumeInput(pg->conn) && PQstatus(pg->conn) != CONNECTION_BAD) continue;
        vx_log(VX_LOG_INFO, "pg.connection_closed", "replica=%s", pg->replica);
        drop_locked(pg);
        return;
    }
}

PGresult *pg_run_locked(vx_pg *pg, int retry, const char *sql, int n, const char *const *vals,
                        vx_err *err)
{
    for (int tries = 0;; tries++) {
        drop_if_closed(pg);
        if (connect_locked(pg, err)) return NULL;
        int timed_out;
        PGresult *r = exec_deadline(pg, sql, n, vals, &timed_out);
        if (timed_out) {
            vx_log(VX_LOG_WARN, "pg.timeout", "replica=%s seconds=%.1f", pg->replica,
                   pg->desc.statement_timeout_s);
            drop_locked(pg);
            /* the next try waits out a backoff: the callers queued behind
             * this one answer 503 at once rather than each wait a connect
             * timeout on a database that does not answer */
            pg->next_try = vx_mono() + pg->backoff;
            unavailable(pg, err, "the database did not answer in time");
            return NULL;
        }
        ExecStatusType st = r ? PQresultStatus(r) : PGRES_FATAL_ERROR;
        if (st == PGRES_COMMAND_OK || st == PGRES_TUPLES_OK) return r;
        int lost = PQstatus(pg->conn) == CONNECTION_BAD;
        map_error(pg, r, lost, err);
        PQclear(r);
        if (lost) {
            vx_log(VX_LOG_WARN, "pg.connection_lost", "replica=%s", pg->replica);
            drop_locked(pg);
        }
        if (!lost || !retry || tries > 0) return NULL;
    }
}

int pg_lock(vx_pg *pg, vx_err *err)
{
    if (!(pg->desc.lock_wait_s > 0)) return pthread_mutex_lock(&pg->lock);
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    double at = (double)t.tv_sec + (double)t.tv_nsec * 1e-9 + pg->desc.lock_wait_s;
    t.tv_sec = (time_t)at;
    t.tv_nsec = (long)((at - (double)t.tv_sec) * 1e9);
    if (pthread_mutex_clocklock(&pg->lock, CLOCK_MONOTONIC, &t) == 0) return 0;
    return vx_err_set(err, VX_EUNAVAIL, "database_unavailable",
                      "the database is not answering (another statement waits on it); try again "
                      "shortly");
}

PGresult *pg_run(vx_pg *pg, int retry, const char *sql, int n, const char *const *vals, vx_err *err)
{
    if (pg_lock(pg, err)) return NULL;
    PGresult *r = pg_run_locked(pg, retry, sql, n, vals, err);
    pthread_mutex_unlock(&pg->lock);
    return r;
}

int pg_exec_locked(vx_pg *pg, int retry, const char *sql, int n, const char *const *vals,
                   vx_err *err)
{
    PGresult *r = pg_run_locked(pg, retry, sql, n, vals, err);
    PQclear(r);
    return r ? 0 : -1;
}

double vx_pg_url_connect_timeout(const char *url)
{
    PQconninfoOption *opts = url ? PQconninfoParse(url, NULL) : NULL;
    double t = 0;
    for (PQconninfoOption *o = opts; o && o->keyword; o++)
        if (!strcmp(o->keyword, "connect_timeout") && o->val && *o->val) {
            t = atof(o->val);
            if (t > 0 && t < 2) t = 2; /* libpq waits 2 s at least */
        }
    PQconninfoFree(opts);
    return t > 0 ? t : 0;
}

vx_pg *vx_pg_open(const vx_pg_desc *desc, vx_err *err)
{
    if (!desc || !desc->url ||
        (strncmp(desc->url, "postgresql://", 13) && strncmp(desc->url, "postgres://", 11))) {
        vx_err_set(err, VX_EINVAL, "invalid_database_url",
                   "the database URL must start with postgresql:// or postgres://");
        return NULL;
    }
    PQconninfoOption *opts = NULL;
    char *perr = NULL;
    opts = PQconninfoParse(desc->url, &perr);
    if (!opts) {
        char line[300];
        first_line(line, sizeof line, perr ? perr : "out of memory");
        PQfreemem(perr);
        vx_err_set(err, VX_EINVAL, "invalid_database_url", "bad database URL: %s", line);
        return NULL;
    }
    PQconninfoFree(opts);
    vx_pg *pg = calloc(1, sizeof *pg);
    if (!pg || !(pg->url = strdup(desc->url))) {
        free(pg);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "out of memory");
        return NULL;
    }
    pg->desc = *desc;
    pg->desc.url = pg->url;
    pg->desc.lease_s = dflt(desc->lease_s, 30);
    pg->desc.max_attempts = desc->max_attempts > 0 ? desc->max_attempts : 3;
    pg->desc.backoff_s = dflt(desc->backoff_s, 1);
    pg->desc.backoff_max_s = dflt(desc->backoff_max_s, 60);
    pg->desc.connect_timeout_s = dflt(desc->connect_timeout_s, 5);
    pg->desc.reconnect_max_s = dflt(desc->reconnect_max_s, 5);
    pg->desc.statement_timeout_s = dflt(desc->statement_timeout_s, 10);
    if (desc->replica && *desc->replica) {
        snprintf(pg->replica, sizeof pg->replica, "%s", desc->replica);
    } else if (gethostname(pg->replica, sizeof pg->replica - 1) != 0) {
        snprintf(pg->replica, sizeof pg->replica, "voxeld");
    }
    pg->desc.replica = pg->replica;
    pg->backoff = 0.1;
    pthread_mutex_init(&pg->lock, NULL);
    if (connect_locked(pg, err)) {
        vx_pg_close(pg);
        return NULL;
    }
    return pg;
}

void vx_pg_close(vx_pg *pg)
{
    if (!pg) return;
    if (pg->conn) PQfinish(pg->conn);
    pthread_mutex_destroy(&pg->lock);
    free(pg->url);
    free(pg);
}

int vx_pg_retry_after(vx_pg *pg)
{
    /* Read without the lock (a waiter may hold it for seconds): a stale
     * value only shifts the hint by one backoff step. */
    double left = pg->next_try - vx_mono();
    return left > 1 ? (int)(left + 0.999) : 1;
}

const char *vx_pg_replica(const vx_pg *pg)
{
    return pg->replica;
}

int vx_pg_migrate(vx_pg *pg, vx_err *err)
{
    pthread_mutex_lock(&pg->lock);
    int version = -1;
    PGresult *r = NULL;
    if (pg_exec_locked(pg, 1, "BEGIN", 0, NULL, err)) goto out;
    /* Replicas starting together migrate one after the other. */
    if (pg_exec_locked(pg, 0,
                       "SELECT pg_advisory_xact_lock(7876198); "
                       "CREATE TABLE IF NOT EXISTS vx_schema (version integer PRIMARY KEY,"
                       " applied timestamptz NOT NULL DEFAULT now())",
                       0, NULL, err))
        goto rollback;
    r = pg_run_locked(pg, 0, "SELECT coalesce(max(version), 0) FROM vx_schema", 0, NULL, err);
    if (!r) goto rollback;
    int have = atoi(PQgetvalue(r, 0, 0));
    PQclear(r);
    if (have > VX_PG_SCHEMA_VERSION) {
        vx_err_set(err, VX_ECONFLICT, "database_schema_newer",
                   "the database has schema version %d; this voxeld knows up to %d: upgrade "
                   "voxeld",
                   have, VX_PG_SCHEMA_VERSION);
        goto rollback;
    }
    for (int v = have + 1; v <= VX_PG_SCHEMA_VERSION; v++) {
        char num[16];
        snprintf(num, sizeof num, "%d", v);
        const char *vals[] = {num};
        if (pg_exec_locked(pg, 0, migrations[v - 1], 0, NULL, err) ||
            pg_exec_locked(pg, 0, "INSERT INTO vx_schema (version) VALUES ($1::integer)", 1, vals,
                           err))
            goto rollback;
        vx_log(VX_LOG_INFO, "pg.migrated", "version=%d", v);
    }
    if (pg_exec_locked(pg, 0, "COMMIT", 0, NULL, err) == 0) version = VX_PG_SCHEMA_VERSION;
    goto out;
rollback:
    if (pg->conn) pg_exec_locked(pg, 0, "ROLLBACK", 0, NULL, NULL);
out:
    pthread_mutex_unlock(&pg->lock);
    return version;
}

void vx_pg_job_clear(vx_pg_job *jb)
{
    if (!jb) return;
    cJSON_Delete(jb->params);
    cJSON_Delete(jb->result);
    cJSON_Delete(jb->errors);
    memset(jb, 0, sizeof *jb);
}

void vx_pg_jobs_free(vx_pg_job *jobs, size_t n)
{
    for (size_t i = 0; jobs && i < n; i++)
        vx_pg_job_clear(&jobs[i]);
    free(jobs);
}

/* Fills *jb from row i of a JOB_COLS result. */
static void read_row(const PGresult *r, int i, vx_pg_job *jb)
{
    memset(jb, 0, sizeof *jb);
    snprintf(jb->id, sizeof jb->id, "%s", PQgetvalue(r, i, 0));
    snprintf(jb->kind, sizeof jb->kind, "%s", PQgetvalue(r, i, 1));
    snprintf(jb->mesh, sizeof jb->mesh, "%s", PQgetvalue(r, i, 2));
    snprintf(jb->parent, sizeof jb->parent, "%s", PQgetvalue(r, i, 3));
    snprintf(jb->state, sizeof jb->state, "%s", PQgetvalue(r, i, 4));
    snprintf(jb->replica, sizeof jb->replica, "%s", PQgetvalue(r, i, 5));
    jb->attempt = atoi(PQgetvalue(r, i, 6));
    jb->max_attempts = atoi(PQgetvalue(r, i, 7));
    jb->cancel_requested = PQgetvalue(r, i, 8)[0] == 't';
    double *t[] = {&jb->created, &jb->started, &jb->finished, &jb->lease_expires, &jb->not_before};
    for (int k = 0; k < 5; k++)
        *t[k] = strtod(PQgetvalue(r, i, 9 + k), NULL);
    jb->params = cJSON_Parse(PQgetvalue(r, i, 14));
    jb->result = PQgetisnull(r, i, 15) ? NULL : cJSON_Parse(PQgetvalue(r, i, 15));
    jb->errors = cJSON_Parse(PQgetvalue(r, i, 16));
    jb->progress = strtod(PQgetvalue(r, i, 17), NULL);
    snprintf(jb->idem, sizeof jb->idem, "%s", PQgetvalue(r, i, 18));
    snprintf(jb->fp, sizeof jb->fp, "%s", PQgetvalue(r, i, 19));
    jb->children = atoi(PQgetvalue(r, i, 20));
}

int vx_pg_submit(vx_pg *pg, const vx_pg_new_job *jobs, size_t n, vx_err *err)
{
    for (size_t i = 0; i < n; i++) {
        if (!vx_jobs_valid_id(jobs[i].id) || !jobs[i].kind || !*jobs[i].kind ||
            (jobs[i].parent && !vx_jobs_valid_id(jobs[i].parent)))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "job %zu: a job needs a valid id and kind (and parent id)", i);
    }
    if (n == 0) return 0;
    if (pg_lock(pg, err)) return -1;
    int rc = -1;
    int tx = n > 1;
    if (tx && pg_exec_locked(pg, 1, "BEGIN", 0, NULL, err)) goto out;
    for (size_t i = 0; i < n; i++) {
        char *params = jobs[i].params ? vx_json_print(jobs[i].params, 0) : NULL;
        char maxa[16];
        snprintf(maxa, sizeof maxa, "%d",
                 jobs[i].max_attempts > 0 ? jobs[i].max_attempts : pg->desc.max_attempts);
        char nch[16];
        snprintf(nch, sizeof nch, "%d", jobs[i].children);
        const char *vals[] = {
            jobs[i].id, jobs[i].kind, jobs[i].mesh, jobs[i].parent, params ? params : "{}",
            maxa,       jobs[i].fp,   nch,          jobs[i].idem};
        int bad = pg_exec_locked(pg, 0,
                                 "INSERT INTO vx_jobs (id, kind, mesh, parent_id, params,"
                                 " max_attempts, fp, children, idem_key) VALUES ($1, $2, $3, $4,"
                                 " $5::json, $6::integer, $7, $8::integer, $9)",
                                 9, vals, err);
        cJSON_free(params);
        if (bad) {
            if (tx && pg->conn) pg_exec_locked(pg, 0, "ROLLBACK", 0, NULL, NULL);
            goto out;
        }
    }
    if (tx && pg_exec_locked(pg, 0, "COMMIT", 0, NULL, err)) goto out;
    rc = 0;
out:
    pthread_mutex_unlock(&pg->lock);
    return rc;
}

int vx_pg_get(vx_pg *pg, const char *id, vx_pg_job *out, vx_err *err)
{
    memset(out, 0, sizeof *out);
    if (!vx_jobs_valid_id(id))
        return vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job %.40s", id ? id : "");
    const char *vals[] = {id};
    PGresult *r = pg_run(pg, 1, "SELECT " JOB_COLS " FROM vx_jobs WHERE id = $1", 1, vals, err);
    if (!r) return -1;
    int rc = 0;
    if (PQntuples(r) == 1)
        read_row(r, 0, out);
    else
        rc = vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job %s", id);
    PQclear(r);
    return rc;
}

int vx_pg_submit_idem(vx_pg *pg, const vx_pg_new_job *job, vx_pg_job *existing, vx_err *err)
{
    memset(existing, 0, sizeof *existing);
    if (!job->idem || !*job->idem) return vx_pg_submit(pg, job, 1, err);
    if (!vx_jobs_valid_id(job->id) || !job->kind || !*job->kind)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "a job needs a valid id and kind");
    char *params = job->params ? vx_json_print(job->params, 0) : NULL;
    char maxa[16];
    snprintf(maxa, sizeof maxa, "%d",
             job->max_attempts > 0 ? job->max_attempts : pg->desc.max_attempts);
    const char *vals[] = {job->id, job->kind, job->mesh, params ? params : "{}",
                          maxa,    job->fp,   job->idem};
    /* Inserted, or the row that holds the key: a key's first job wins (a
     * concurrent insert of the same key waits for it, then does nothing).
     * The winner is read by a statement of its own: the insert's snapshot
     * was taken before the winner committed, so a SELECT in the same
     * statement does not see it (the job was then reported as inserted,
     * 202, and never existed). It can be gone by then (deleted): try again. */
    int rc = -2; /* -2: neither inserted nor the key's row read yet */
    for (int attempt = 0; attempt < 8 && rc == -2; attempt++) {
        PGresult *r =
            pg_run(pg, 0,
                   "INSERT INTO vx_jobs (id, kind, mesh, params, max_attempts, fp, idem_key)"
                   " VALUES ($1, $2, $3, $4::json, $5::integer, $6, $7)"
                   " ON CONFLICT (idem_key) WHERE idem_key IS NOT NULL DO NOTHING RETURNING id",
                   7, vals, err);
        if (!r) {
            rc = -1;
            break;
        }
        int inserted = PQntuples(r) == 1;
        PQclear(r);
        if (inserted) {
            rc = 0;
            break;
        }
        const char *key[] = {job->idem};
        r = pg_run(pg, 1, "SELECT " JOB_COLS " FROM vx_jobs WHERE idem_key = $1", 1, key, err);
        if (!r) {
            rc = -1;
            break;
        }
        if (PQntuples(r) == 1) {
            read_row(r, 0, existing);
            if (strcmp(existing->fp, job->fp ? job->fp : "")) {
                vx_pg_job_clear(existing);
                rc = vx_err_set(err, VX_EUNPROC, "idempotency_key_reused",
                                "the Idempotency-Key was used for another request");
            } else {
                rc = 1;
            }
        }
        PQclear(r);
    }
    if (rc == -2)
        rc = vx_err_set(err, VX_EOVERLOAD, "database_overloaded",
                        "the Idempotency-Key's job kept changing; try again");
    cJSON_free(params);
    return rc;
}

int vx_pg_find_done(vx_pg *pg, const char *fp, vx_pg_job *out, vx_err *err)
{
    memset(out, 0, sizeof *out);
    const char *vals[] = {fp};
    PGresult *r = pg_run(pg, 1,
                         "SELECT " JOB_COLS " FROM vx_jobs WHERE fp = $1 AND state ="
                         " 'succeeded' ORDER BY id DESC LIMIT 1",
                         1, vals, err);
    if (!r) return -1;
    int got = PQntuples(r) == 1;
    if (got) read_row(r, 0, out);
    PQclear(r);
    return got;
}

int vx_pg_delete(vx_pg *pg, const char *id, vx_err *err)
{
    if (!vx_jobs_valid_id(id))
        return vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job %.40s", id ? id : "");
    const char *vals[] = {id};
    PGresult *r = pg_run(pg, 0,
                         "WITH del AS (DELETE FROM vx_jobs WHERE id = $1 AND state IN"
                         " ('succeeded', 'failed', 'canceled') RETURNING id)"
                         " SELECT (SELECT count(*) FROM del),"
                         " (SELECT state FROM vx_jobs WHERE id = $1)",
                         1, vals, err);
    if (!r) return -1;
    int rc = 0;
    if (atoi(PQgetvalue(r, 0, 0)) != 1) {
        if (PQgetisnull(r, 0, 1))
            rc = vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job with id %s", id);
        else
            rc = vx_err_set(err, VX_ECONFLICT, "job_not_finished", "job %s is %s", id,
                            PQgetvalue(r, 0, 1));
    }
    PQclear(r);
    return rc;
}

int vx_pg_store_id(vx_pg *pg,
                   int (*check)(void *ud, const char *have, char out[VX_PG_STORE_ID], vx_err *err),
                   void *ud, vx_err *err)
{
    pthread_mutex_lock(&pg->lock);
    /* Replicas starting together decide one after the other (a session
     * lock: the store is read and written between the statements). */
    if (pg_exec_locked(pg, 1, "SELECT pg_advisory_lock(7876199)", 0, NULL, err)) {
        pthread_mutex_unlock(&pg->lock);
        return -1;
    }
    int rc = -1;
    PGresult *r =
        pg_run_locked(pg, 0, "SELECT value FROM vx_settings WHERE key = 'store_id'", 0, NULL, err);
    if (r) {
        char have[VX_PG_STORE_ID] = "", id[VX_PG_STORE_ID] = "";
        if (PQntuples(r) == 1) snprintf(have, sizeof have, "%s", PQgetvalue(r, 0, 0));
        PQclear(r);
        rc = check(ud, have[0] ? have : NULL, id, err);
        const char *vals[] = {id};
        if (rc > 0)
            rc = 0; /* not decided now */
        else if (rc == 0 && !have[0])
            rc = pg_exec_locked(pg, 0,
                                "INSERT INTO vx_settings (key, value) VALUES ('store_id', $1)"
                                " ON CONFLICT (key) DO NOTHING",
                                1, vals, err);
    }
    vx_err ignored;
    pg_exec_locked(pg, 0, "SELECT pg_advisory_unlock(7876199)", 0, NULL, &ignored);
    pthread_mutex_unlock(&pg->lock);
    return rc;
}

long vx_pg_queued(vx_pg *pg, vx_err *err)
{
    PGresult *r =
        pg_run(pg, 1, "SELECT count(*) FROM vx_jobs WHERE state = 'queued'", 0, NULL, err);
    if (!r) return -1;
    long n = atol(PQgetvalue(r, 0, 0));
    PQclear(r);
    return n;
}

int vx_pg_ping(vx_pg *pg, vx_err *err)
{
    /* a read of the jobs table, not SELECT 1: a lock held on it (which
     * every job request waits on until lock_timeout) is an outage too */
    PGresult *r = pg_run(pg, 1, "SELECT 1 FROM vx_jobs LIMIT 1", 0, NULL, err);
    int rc = r ? 0 : -1;
    PQclear(r);
    return rc;
}

int vx_pg_child_counts(vx_pg *pg, const char *id, int *done, int *total, vx_err *err)
{
    *done = *total = 0;
    const char *vals[] = {id};
    PGresult *r = pg_run(pg, 1,
                         "SELECT count(*) FILTER (WHERE state = 'succeeded'), count(*) FROM"
                         " vx_jobs WHERE parent_id = $1",
                         1, vals, err);
    if (!r) return -1;
    *done = atoi(PQgetvalue(r, 0, 0));
    *total = atoi(PQgetvalue(r, 0, 1));
    PQclear(r);
    return 0;
}

int vx_pg_find_idem(vx_pg *pg, const char *key, vx_pg_job *out, vx_err *err)
{
    memset(out, 0, sizeof *out);
    const char *vals[] = {key};
    PGresult *r =
        pg_run(pg, 1, "SELECT " JOB_COLS " FROM vx_jobs WHERE idem_key = $1", 1, vals, err);
    if (!r) return -1;
    int got = PQntuples(r) == 1;
    if (got) read_row(r, 0, out);
    PQclear(r);
    return got;
}

int vx_pg_list(vx_pg *pg, const vx_pg_filter *f, const char *after, int limit, vx_pg_job **out,
               size_t *n, char next[33], vx_err *err)
{
    char from[33] = ""; /* after may be next */
    if (after) snprintf(from, sizeof from, "%s", after);
    *out = NULL;
    *n = 0;
    next[0] = 0;
    if (limit < 1 || limit > 1000)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "limit must be 1 to 1000");
    vx_pg_filter none = {0};
    if (!f) f = &none;
    char lim[16];
    snprintf(lim, sizeof lim, "%d", limit + 1);
    const char *vals[] = {f->state, f->kind, f->parent, from[0] ? from : NULL, lim, f->mesh};
    const char *asc =
        "SELECT " JOB_COLS " FROM vx_jobs WHERE ($1::text IS NULL OR state = $1)"
        " AND ($2::text IS NULL OR kind = $2) AND ($3::text IS NULL OR parent_id = $3)"
        " AND ($6::text IS NULL OR mesh = $6)"
        " AND ($4::text IS NULL OR id > $4) ORDER BY id LIMIT $5::integer";
    const char *desc =
        "SELECT " JOB_COLS " FROM vx_jobs WHERE ($1::text IS NULL OR state = $1)"
        " AND ($2::text IS NULL OR kind = $2) AND ($3::text IS NULL OR parent_id = $3)"
        " AND ($6::text IS NULL OR mesh = $6)"
        " AND ($4::text IS NULL OR id < $4) ORDER BY id DESC LIMIT $5::integer";
    PGresult *r = pg_run(pg, 1, f->desc ? desc : asc, 6, vals, err);
    if (!r) return -1;
    int rows = PQntuples(r);
    int keep = rows > limit ? limit : rows;
    if (keep > 0) {
        *out = calloc((size_t)keep, sizeof **out);
        if (!*out) {
            PQclear(r);
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "out of memory");
        }
    }
    for (int i = 0; i < keep; i++)
        read_row(r, i, &(*out)[i]);
    *n = (size_t)keep;
    if (rows > limit) snprintf(next, 33, "%s", (*out)[keep - 1].id);
    PQclear(r);
    return 0;
}

int vx_pg_claim(vx_pg *pg, const char *kinds, vx_pg_job *out, vx_err *err)
{
    memset(out, 0, sizeof *out);
    char lease[32];
    snprintf(lease, sizeof lease, "%.3f", pg->desc.lease_s);
    const char *vals[] = {pg->replica, lease, kinds && *kinds ? kinds : NULL};
    PGresult *r = pg_run(
        pg, 0,
        "UPDATE vx_jobs SET state = 'running', replica = $1, attempt = attempt + 1,"
        " lease_expires = now() + make_interval(secs => $2::float8), started = now(),"
        " progress = 0, updated = now()"
        " WHERE id = (SELECT id FROM vx_jobs j WHERE state = 'queued' AND not_before <= now()"
        "  AND ($3::text IS NULL OR kind = ANY (string_to_array($3, ',')))"
        "  AND (children = 0 OR NOT EXISTS (SELECT 1 FROM vx_jobs c WHERE c.parent_id = j.id"
        "   AND c.state <> 'succeeded'))"
        "  ORDER BY id LIMIT 1 FOR UPDATE SKIP LOCKED)"
        " AND state = 'queued' RETURNING " JOB_COLS,
        3, vals, err);
    if (!r) return -1;
    int got = PQntuples(r) == 1;
    if (got) read_row(r, 0, out);
    PQclear(r);
    return got;
}

int vx_pg_renew(vx_pg *pg, const char *id, int attempt, double progress, int *cancel, vx_err *err)
{
    char att[16], lease[32], prog[32];
    snprintf(att, sizeof att, "%d", attempt);
    snprintf(lease, sizeof lease, "%.3f", pg->desc.lease_s);
    snprintf(prog, sizeof prog, "%.6f", progress < 0 ? 0 : progress > 1 ? 1 : progress);
    const char *vals[] = {id, att, pg->replica, lease, prog};
    *cancel = 0;
    pthread_mutex_lock(&pg->lock);
    /* Idempotent: re-run on a new connection after a lost one. */
    PGresult *r = pg_run_locked(pg, 1,
                                "UPDATE vx_jobs SET lease_expires = now() + make_interval(secs =>"
                                " $4::float8), progress = $5::float8 WHERE id = $1 AND attempt ="
                                " $2::integer AND replica = $3 AND state = 'running'"
                                " RETURNING cancel_requested",
                                5, vals, err);
    pthread_mutex_unlock(&pg->lock);
    if (!r) return -1;
    int held = PQntuples(r) == 1;
    if (held) *cancel = PQgetvalue(r, 0, 0)[0] == 't';
    PQclear(r);
    /* Not always a loss: the job may have just been completed by this
     * replica's GL thread. The caller tells them apart (cluster.c: lose). */
    if (!held) VX_DEBUG("pg.lease_not_held", "job=%s attempt=%d", id, attempt);
    return held ? 0 : 1;
}

double vx_pg_renew_interval(const vx_pg *pg)
{
    return pg->desc.lease_s / 3;
}

int vx_pg_complete(vx_pg *pg, const char *id, int attempt, const cJSON *result, vx_err *err)
{
    if (!cJSON_IsObject(result))
        return vx_err_set(err, VX_EINTERNAL, "invalid_result", "a result manifest is an object");
    char *manifest = vx_json_print(result, 0);
    if (!manifest) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "out of memory");
    char att[16];
    snprintf(att, sizeof att, "%d", attempt);
    const char *vals[] = {id, att, pg->replica, manifest};
    pthread_mutex_lock(&pg->lock);
    /* One statement: the fenced update and the results index of its outputs. */
    PGresult *r = pg_run_locked(
        pg, 0,
        "WITH done AS (UPDATE vx_jobs SET state = 'succeeded', result = $4::json,"
        "  finished = now(), lease_expires = NULL, progress = 1, updated = now()"
        "  WHERE id = $1 AND attempt = $2::integer AND replica = $3 AND state = 'running'"
        "  RETURNING id, attempt),"
        " idx AS (INSERT INTO vx_results (job_id, attempt, name, location, bytes, content_type)"
        "  SELECT done.id, done.attempt, o.key, o.value->>'location',"
        "   (o.value->>'bytes')::bigint, o.value->>'content_type'"
        "  FROM done, jsonb_each(CASE WHEN jsonb_typeof($4::jsonb->'outputs') = 'object'"
        "   THEN $4::jsonb->'outputs' ELSE '{}'::jsonb END) o RETURNING 1)"
        " SELECT (SELECT count(*) FROM done), (SELECT count(*) FROM idx)",
        4, vals, err);
    cJSON_free(manifest);
    if (!r) {
        pthread_mutex_unlock(&pg->lock);
        return -1;
    }
    int done = atoi(PQgetvalue(r, 0, 0)) == 1;
    PQclear(r);
    if (!done) {
        /* A try whose answer was lost with the connection may have
         * committed: this very attempt already recorded is no stale one
         * (its results are the job's; removing them lost a success). */
        r = pg_run_locked(pg, 0,
                          "SELECT 1 FROM vx_jobs WHERE id = $1 AND attempt = $2::integer"
                          " AND replica = $3 AND state = 'succeeded'",
                          3, vals, err);
        if (!r) {
            pthread_mutex_unlock(&pg->lock);
            return -1;
        }
        done = PQntuples(r) == 1;
        PQclear(r);
        if (done) vx_log(VX_LOG_INFO, "pg.completion_recorded", "job=%s attempt=%d", id, attempt);
    }
    pthread_mutex_unlock(&pg->lock);
    if (!done) vx_log(VX_LOG_WARN, "pg.stale_completion", "job=%s attempt=%d", id, attempt);
    return done ? 0 : 1;
}

int vx_pg_fail(vx_pg *pg, const char *id, int attempt, const vx_err *why, int retry,
               char state_out[16], vx_err *err)
{
    char att[16], base[32], top[32];
    snprintf(att, sizeof att, "%d", attempt);
    snprintf(base, sizeof base, "%.3f", pg->desc.backoff_s);
    snprintf(top, sizeof top, "%.3f", pg->desc.backoff_max_s);
    int canceled = why && why->kind == VX_ECANCELED && !vx_err_has(why, VX_EF_SHUTDOWN);
    const char *vals[] = {id,
                          att,
                          pg->replica,
                          why ? vx_err_kind_name(why->kind) : "internal",
                          why && why->code[0] ? why->code : "failed",
                          why ? why->message : "",
                          canceled ? "true" : "false",
                          retry ? "true" : "false",
                          base,
                          top};
    pthread_mutex_lock(&pg->lock);
#define RETRY_NOW "(NOT $7::boolean AND $8::boolean AND attempt < max_attempts)"
    PGresult *r = pg_run_locked(
        pg, 0,
        "UPDATE vx_jobs SET errors = errors || jsonb_build_array(jsonb_build_object("
        "  'attempt', attempt, 'replica', replica, 'kind', $4::text, 'code', $5::text,"
        "  'message', $6::text, 'at', now())),"
        " state = CASE WHEN $7::boolean THEN 'canceled' WHEN " RETRY_NOW " THEN 'queued'"
        "  ELSE 'failed' END,"
        " not_before = CASE WHEN " RETRY_NOW " THEN now() + " BACKOFF(
            "$9",
            "$10") " ELSE"
                   "  not_before END,"
                   " finished = CASE WHEN " RETRY_NOW " THEN NULL ELSE now() END,"
                   " progress = CASE WHEN " RETRY_NOW " THEN 0 ELSE progress END,"
                   " lease_expires = NULL, updated = now()"
                   " WHERE id = $1 AND attempt = $2::integer AND replica = $3 AND state = 'running'"
                   " RETURNING state",
        10, vals, err);
#undef RETRY_NOW
    pthread_mutex_unlock(&pg->lock);
    if (!r) return -1;
    int done = PQntuples(r) == 1;
    if (done && state_out) snprintf(state_out, 16, "%s", PQgetvalue(r, 0, 0));
    PQclear(r);
    return done ? 0 : 1;
}

int vx_pg_release(vx_pg *pg, const char *id, int attempt, vx_err *err)
{
    char att[16];
    snprintf(att, sizeof att, "%d", attempt);
    const char *vals[] = {id, att, pg->replica};
    PGresult *r =
        pg_run(pg, 0,
               "UPDATE vx_jobs SET state = CASE WHEN cancel_requested THEN 'canceled' ELSE"
               " 'queued' END, finished = CASE WHEN cancel_requested THEN now() END,"
               " progress = CASE WHEN cancel_requested THEN progress ELSE 0 END,"
               " max_attempts = max_attempts + 1, lease_expires = NULL, not_before = now(),"
               " updated = now()"
               " WHERE id = $1 AND attempt = $2::integer AND replica = $3 AND state = 'running'"
               " RETURNING state",
               3, vals, err);
    if (!r) return -1;
    int done = PQntuples(r) == 1;
    PQclear(r);
    return done ? 0 : 1;
}

int vx_pg_requeue_expired(vx_pg *pg, int max, int *requeued, int *failed, vx_err *err)
{
    if (requeued) *requeued = 0;
    if (failed) *failed = 0;
    char lim[16], base[32], top[32];
    snprintf(lim, sizeof lim, "%d", max > 0 ? max : 100);
    snprintf(base, sizeof base, "%.3f", pg->desc.backoff_s);
    snprintf(top, sizeof top, "%.3f", pg->desc.backoff_max_s);
    const char *vals[] = {lim, base, top, pg->replica};
    pthread_mutex_lock(&pg->lock);
#define AGAIN "(NOT cancel_requested AND attempt < max_attempts)"
    PGresult *r = pg_run_locked(
        pg, 1,
        "UPDATE vx_jobs SET errors = errors || jsonb_build_array(jsonb_build_object("
        "  'attempt', attempt, 'replica', replica, 'kind', 'unavail', 'code', 'lease_expired',"
        "  'message', 'the lease of replica ' || coalesce(replica, '?') || ' expired (noticed by '"
        "  || $4 || ')', 'at', now())),"
        " state = CASE WHEN cancel_requested THEN 'canceled' WHEN " AGAIN " THEN 'queued'"
        "  ELSE 'failed' END,"
        " not_before = CASE WHEN " AGAIN " THEN now() + " BACKOFF(
            "$2", "$3") " ELSE not_before"
                        "  END,"
                        " finished = CASE WHEN " AGAIN " THEN NULL ELSE now() END,"
                        " progress = CASE WHEN " AGAIN " THEN 0 ELSE progress END,"
                        " lease_expires = NULL, updated = now()"
                        " WHERE id IN (SELECT id FROM vx_jobs WHERE state = 'running' AND "
                        "lease_expires < now()"
                        "  ORDER BY lease_expires LIMIT $1::integer FOR UPDATE SKIP LOCKED)"
                        " AND state = 'running' AND lease_expires < now() RETURNING state",
        4, vals, err);
#undef AGAIN
    pthread_mutex_unlock(&pg->lock);
    if (!r) return -1;
    int rows = PQntuples(r);
    for (int i = 0; i < rows; i++) {
        const char *st = PQgetvalue(r, i, 0);
        if (!strcmp(st, "queued") && requeued) (*requeued)++;
        if (!strcmp(st, "failed") && failed) (*failed)++;
    }
    PQclear(r);
    if (rows) vx_log(VX_LOG_INFO, "pg.requeued_expired", "jobs=%d", rows);
    return rows;
}

int vx_pg_cancel(vx_pg *pg, const char *id, int *was_running, vx_err *err)
{
    *was_running = 0;
    if (!vx_jobs_valid_id(id))
        return vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job %.40s", id ? id : "");
    const char *vals[] = {id};
    if (pg_lock(pg, err)) return -1;
    PGresult *r = pg_run_locked(
        pg, 0,
        "WITH kids AS (UPDATE vx_jobs SET cancel_requested = true,"
        "  state = CASE WHEN state = 'queued' THEN 'canceled' ELSE state END,"
        "  finished = CASE WHEN state = 'queued' THEN now() ELSE finished END, updated = now()"
        "  WHERE parent_id = $1 AND state IN ('queued', 'running') AND NOT cancel_requested"
        "  RETURNING 1)"
        " UPDATE vx_jobs SET cancel_requested = true,"
        " state = CASE WHEN state = 'queued' THEN 'canceled' ELSE state END,"
        " finished = CASE WHEN state = 'queued' THEN now() ELSE finished END, updated = now()"
        " WHERE id = $1 AND state IN ('queued', 'running') RETURNING state",
        1, vals, err);
    PGresult *q = NULL;
    if (r && PQntuples(r) == 0)
        q = pg_run_locked(pg, 1, "SELECT state FROM vx_jobs WHERE id = $1", 1, vals, err);
    pthread_mutex_unlock(&pg->lock);
    if (!r) return -1;
    int rc = 0;
    if (PQntuples(r) == 1) {
        *was_running = !strcmp(PQgetvalue(r, 0, 0), "running");
    } else if (!q) {
        rc = -1;
    } else if (PQntuples(q) == 0) {
        rc = vx_err_set(err, VX_ENOTFOUND, "job_not_found", "no job %s", id);
    } else {
        rc = vx_err_set(err, VX_ECONFLICT, "job_finished", "job %s has finished (%s)", id,
                        PQgetvalue(q, 0, 0));
    }
    PQclear(q);
    PQclear(r);
    return rc;
}

int vx_pg_listen(vx_pg *pg, vx_err *err)
{
    pthread_mutex_lock(&pg->lock);
    int rc = pg_exec_locked(pg, 1, "LISTEN " VX_PG_CHANNEL, 0, NULL, err);
    if (rc == 0) pg->listening = 1;
    pthread_mutex_unlock(&pg->lock);
    return rc;
}

static void nap(double s)
{
    if (s <= 0) return;
    struct timespec ts = {(time_t)s, (long)((s - (double)(time_t)s) * 1e9)};
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
    }
}

int vx_pg_wait(vx_pg *pg, double timeout_s, char *payload, size_t payload_n, vx_err *err)
{
    if (payload_n) payload[0] = 0;
    pthread_mutex_lock(&pg->lock);
    if (!pg->listening) {
        pthread_mutex_unlock(&pg->lock);
        return vx_err_set(err, VX_EINTERNAL, "not_listening", "vx_pg_wait before vx_pg_listen");
    }
    double end = vx_mono() + (timeout_s > 0 ? timeout_s : 0);
    int rc = 0;
    for (;;) {
        if (connect_locked(pg, NULL) != 0) {
            /* Down: sleep until the next try or the deadline (the caller polls). */
            double until = pg->next_try < end ? pg->next_try : end;
            nap(until - vx_mono());
            if (vx_mono() >= end) break;
            continue;
        }
        if (pg->missed) {
            /* Reconnected: what was sent meanwhile is lost; "" = re-read. */
            pg->missed = 0;
            rc = 1;
            break;
        }
        if (!PQconsumeInput(pg->conn)) {
            vx_log(VX_LOG_WARN, "pg.connection_lost", "replica=%s listening=1", pg->replica);
            drop_locked(pg);
            continue;
        }
        PGnotify *nf = PQnotifies(pg->conn);
        if (nf) {
            if (payload_n) snprintf(payload, payload_n, "%s", nf->extra);
            PQfreemem(nf);
            rc = 1;
            break;
        }
        double left = end - vx_mono();
        if (left <= 0) break;
        struct pollfd pfd = {.fd = PQsocket(pg->conn), .events = POLLIN};
        int ms = (int)(left * 1000) + 1;
        if (poll(&pfd, 1, ms) < 0 && errno != EINTR) break;
    }
    pthread_mutex_unlock(&pg->lock);
    return rc;
}

int vx_pg_counts(vx_pg *pg, vx_pg_count **out, size_t *n, vx_err *err)
{
    *out = NULL;
    *n = 0;
    PGresult *r = pg_run(pg, 1,
                         "SELECT state, kind, count(*) FROM vx_jobs GROUP BY state, kind"
                         " ORDER BY state, kind",
                         0, NULL, err);
    if (!r) return -1;
    int rows = PQntuples(r);
    if (rows > 0 && !(*out = calloc((size_t)rows, sizeof **out))) {
        PQclear(r);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "out of memory");
    }
    for (int i = 0; i < rows; i++) {
        snprintf((*out)[i].state, sizeof(*out)[i].state, "%s", PQgetvalue(r, i, 0));
        snprintf((*out)[i].kind, sizeof(*out)[i].kind, "%s", PQgetvalue(r, i, 1));
        (*out)[i].n = atol(PQgetvalue(r, i, 2));
    }
    *n = (size_t)rows;
    PQclear(r);
    return 0;
}
