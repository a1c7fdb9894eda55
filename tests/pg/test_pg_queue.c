/* The PostgreSQL job queue (src/jobs/pg.c) against a real PostgreSQL that
 * tests/support/pg.sh starts (VX_PG_URL, VX_PG_DIR, VX_PG_SH): schema
 * migration, submit/get/list, concurrent claims, lease expiry and fencing,
 * max_attempts, cancel, NOTIFY, counts, a server restart, child jobs and
 * the mesh catalog. */
#include <errno.h>
#include <pthread.h>
#include <signal.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include <libpq-fe.h>

#include "jobs/pg.h"
#include "util/clock.h"

static const char *url(void)
{
    const char *u = getenv("VX_PG_URL");
    if (!u) fail_msg("VX_PG_URL is not set: run through tests/support/pg.sh run");
    return u;
}

/* A raw connection for what the module does not do (tampering, checks). */
static PGresult *sql(const char *q)
{
    PGconn *c = PQconnectdb(url());
    assert_int_equal(PQstatus(c), CONNECTION_OK);
    PGresult *r = PQexec(c, q);
    int st = PQresultStatus(r);
    if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) fail_msg("%s: %s", q, PQerrorMessage(c));
    PQfinish(c);
    return r;
}

static long sql_long(const char *q)
{
    PGresult *r = sql(q);
    long v = atol(PQgetvalue(r, 0, 0));
    PQclear(r);
    return v;
}

static vx_pg *open_as(const char *replica, double lease_s)
{
    vx_pg_desc d = {.url = url(), .replica = replica, .lease_s = lease_s, .backoff_s = 0.2};
    vx_err err = {0};
    vx_pg *pg = vx_pg_open(&d, &err);
    if (!pg) fail_msg("open: %s %s", err.code, err.message);
    return pg;
}

static void make_id(char id[33], unsigned n)
{
    static unsigned salt;
    if (!salt) salt = (unsigned)time(NULL);
    snprintf(id, 33, "%012x%08x%012x", n, salt, n * 2654435761u);
}

static void submit(vx_pg *pg, const char *id, const char *kind, int max_attempts)
{
    cJSON *p = cJSON_Parse("{\"resolution\":64}");
    vx_pg_new_job nj = {.id = id, .kind = kind, .params = p, .max_attempts = max_attempts};
    vx_err err = {0};
    if (vx_pg_submit(pg, &nj, 1, &err)) fail_msg("submit: %s %s", err.code, err.message);
    cJSON_Delete(p);
}

static void nap(double s)
{
    struct timespec ts = {(time_t)s, (long)((s - (double)(time_t)s) * 1e9)};
    nanosleep(&ts, NULL);
}

static int setup(void **state)
{
    vx_pg *pg = open_as("setup", 0);
    vx_err err = {0};
    assert_int_equal(vx_pg_migrate(pg, &err), VX_PG_SCHEMA_VERSION);
    vx_pg_close(pg);
    PQclear(sql("DELETE FROM vx_jobs"));
    return 0;
}

static void test_migrate(void **state)
{
    vx_pg *pg = open_as("m", 0);
    vx_err err = {0};
    /* Twice more: a no-op, one version row. */
    assert_int_equal(vx_pg_migrate(pg, &err), VX_PG_SCHEMA_VERSION);
    assert_int_equal(vx_pg_migrate(pg, &err), VX_PG_SCHEMA_VERSION);
    assert_int_equal(sql_long("SELECT count(*) FROM vx_schema"), VX_PG_SCHEMA_VERSION);
    assert_int_equal(sql_long("SELECT count(*) FROM pg_tables WHERE tablename IN"
                              " ('vx_jobs','vx_results','vx_meshes','vx_schema')"),
                     4);
    /* A newer schema (a later voxeld migrated it) refuses. */
    PQclear(sql("INSERT INTO vx_schema (version) VALUES (99)"));
    assert_int_equal(vx_pg_migrate(pg, &err), -1);
    assert_int_equal(err.kind, VX_ECONFLICT);
    assert_string_equal(err.code, "database_schema_newer");
    assert_non_null(strstr(err.message, "99"));
    PQclear(sql("DELETE FROM vx_schema WHERE version = 99"));
    assert_int_equal(vx_pg_migrate(pg, &err), VX_PG_SCHEMA_VERSION);
    vx_pg_close(pg);
    /* A URL that is not postgresql:// is refused before connecting. */
    vx_pg_desc bad = {.url = "mysql://x"};
    assert_null(vx_pg_open(&bad, &err));
    assert_string_equal(err.code, "invalid_database_url");
}

static void test_submit_get_list(void **state)
{
    vx_pg *pg = open_as("r1", 0);
    vx_err err = {0};
    char ids[5][33];
    for (unsigned i = 0; i < 5; i++) {
        make_id(ids[i], 100 + i);
        submit(pg, ids[i], i % 2 ? "render" : "voxelize", 0);
    }
    /* Acknowledged = committed: another connection sees every row. */
    char qs[160];
    snprintf(qs, sizeof qs, "SELECT count(*) FROM vx_jobs WHERE id IN ('%s','%s')", ids[0], ids[4]);
    assert_int_equal(sql_long(qs), 2);
    vx_pg_job jb;
    assert_int_equal(vx_pg_get(pg, ids[1], &jb, &err), 0);
    assert_string_equal(jb.id, ids[1]);
    assert_string_equal(jb.kind, "render");
    assert_string_equal(jb.state, "queued");
    assert_int_equal(jb.attempt, 0);
    assert_int_equal(jb.max_attempts, 3);
    assert_int_equal(cJSON_GetObjectItem(jb.params, "resolution")->valueint, 64);
    assert_true(jb.created > 1e9);
    assert_int_equal(cJSON_GetArraySize(jb.errors), 0);
    assert_null(jb.result);
    vx_pg_job_clear(&jb);
    char missing[33];
    make_id(missing, 999);
    assert_int_equal(vx_pg_get(pg, missing, &jb, &err), -1);
    assert_string_equal(err.code, "job_not_found");
    /* The same id again. */
    vx_pg_new_job dup = {.id = ids[0], .kind = "voxelize"};
    assert_int_equal(vx_pg_submit(pg, &dup, 1, &err), -1);
    assert_int_equal(err.kind, VX_ECONFLICT);

    /* Pages of 2 of the 3 voxelize jobs, in id order, then newest first. */
    vx_pg_filter f = {.kind = "voxelize"};
    vx_pg_job *page;
    size_t n;
    char next[33];
    assert_int_equal(vx_pg_list(pg, &f, NULL, 2, &page, &n, next, &err), 0);
    assert_int_equal(n, 2);
    assert_string_equal(page[0].id, ids[0]);
    assert_string_equal(page[1].id, ids[2]);
    assert_string_equal(next, ids[2]);
    vx_pg_jobs_free(page, n);
    assert_int_equal(vx_pg_list(pg, &f, next, 2, &page, &n, next, &err), 0);
    assert_int_equal(n, 1);
    assert_string_equal(page[0].id, ids[4]);
    assert_string_equal(next, "");
    vx_pg_jobs_free(page, n);
    f.desc = 1;
    assert_int_equal(vx_pg_list(pg, &f, NULL, 10, &page, &n, next, &err), 0);
    assert_int_equal(n, 3);
    assert_string_equal(page[0].id, ids[4]);
    vx_pg_jobs_free(page, n);
    vx_pg_filter running = {.state = "running"};
    assert_int_equal(vx_pg_list(pg, &running, NULL, 10, &page, &n, next, &err), 0);
    assert_int_equal(n, 0);

    /* A parent and its bricks in one transaction; a brick of a missing
     * parent rolls the whole batch back. */
    char parent[33], b1[33], b2[33], orphan[33];
    make_id(parent, 200);
    make_id(b1, 201);
    make_id(b2, 202);
    make_id(orphan, 203);
    vx_pg_new_job fam[] = {{.id = parent, .kind = "voxelize"},
                           {.id = b1, .kind = "voxelize", .parent = parent},
                           {.id = b2, .kind = "voxelize", .parent = parent}};
    assert_int_equal(vx_pg_submit(pg, fam, 3, &err), 0);
    snprintf(qs, sizeof qs, "SELECT count(*) FROM vx_jobs WHERE id = '%s' OR parent_id = '%s'",
             parent, parent);
    assert_int_equal(sql_long(qs), 3);
    vx_pg_filter kids = {.parent = parent};
    assert_int_equal(vx_pg_list(pg, &kids, NULL, 10, &page, &n, next, &err), 0);
    assert_int_equal(n, 2);
    assert_string_equal(page[0].parent, parent);
    vx_pg_jobs_free(page, n);
    vx_pg_new_job bad[] = {{.id = orphan, .kind = "voxelize"},
                           {.id = b1, .kind = "voxelize", .parent = missing}};
    assert_int_equal(vx_pg_submit(pg, bad, 2, &err), -1);
    assert_int_equal(vx_pg_get(pg, orphan, &jb, &err), -1); /* rolled back */

    /* Counts by state and kind. */
    vx_pg_count *c;
    assert_int_equal(vx_pg_counts(pg, &c, &n, &err), 0);
    long vq = 0, rq = 0;
    for (size_t i = 0; i < n; i++) {
        if (!strcmp(c[i].state, "queued") && !strcmp(c[i].kind, "voxelize")) vq = c[i].n;
        if (!strcmp(c[i].state, "queued") && !strcmp(c[i].kind, "render")) rq = c[i].n;
    }
    free(c);
    assert_int_equal(vq, 6);
    assert_int_equal(rq, 2);
    vx_pg_close(pg);
}

#define RACE_JOBS 120
#define RACERS 4

typedef struct racer {
    char name[16];
    char got[RACE_JOBS][33];
    int n, errors;
} racer;

static void *race(void *ud)
{
    racer *r = ud;
    vx_pg *pg = open_as(r->name, 0);
    for (;;) {
        vx_pg_job jb;
        vx_err err = {0};
        int rc = vx_pg_claim(pg, "race", &jb, &err);
        if (rc == 0) break;
        if (rc < 0) {
            r->errors++;
            break;
        }
        if (r->n < RACE_JOBS) snprintf(r->got[r->n++], 33, "%s", jb.id);
        if (strcmp(jb.replica, r->name) || jb.attempt != 1) r->errors++;
        vx_pg_job_clear(&jb);
    }
    vx_pg_close(pg);
    return NULL;
}

/* The same Idempotency-Key from several replicas at once: one job, which
 * every other submission answers. Before, a loser's statement could not
 * see the winner (committed after its snapshot), reported itself as
 * inserted, and its job id (answered 202) never existed. */
enum { IDEM_RACERS = 3, IDEM_ROUNDS = 40 };
typedef struct idem_racer {
    int n;
    pthread_barrier_t *bar;
    int rc[IDEM_ROUNDS];
    char mine[IDEM_ROUNDS][33], got[IDEM_ROUNDS][33];
} idem_racer;

static void *idem_race(void *arg)
{
    idem_racer *r = arg;
    char name[16];
    snprintf(name, sizeof name, "idem%d", r->n);
    vx_pg *pg = open_as(name, 30);
    for (int k = 0; k < IDEM_ROUNDS; k++) {
        char key[32];
        snprintf(key, sizeof key, "race-%d", k);
        make_id(r->mine[k], (unsigned)(20000 + 100 * k + r->n));
        vx_pg_new_job nj = {.id = r->mine[k],
                            .kind = "idem",
                            .mesh =
                                "aaaa000000000000000000000000000000000000000000000000000000000002",
                            .fp = "00000000000000cc",
                            .idem = key};
        vx_pg_job ex;
        vx_err err = {0};
        pthread_barrier_wait(r->bar);
        r->rc[k] = vx_pg_submit_idem(pg, &nj, &ex, &err);
        snprintf(r->got[k], 33, "%s", r->rc[k] == 1 ? ex.id : r->rc[k] == 0 ? r->mine[k] : "");
        if (r->rc[k] == 1) vx_pg_job_clear(&ex);
    }
    vx_pg_close(pg);
    return NULL;
}

static void test_idem_race(void **state)
{
    (void)state;
    pthread_barrier_t bar;
    pthread_barrier_init(&bar, NULL, IDEM_RACERS);
    static idem_racer rs[IDEM_RACERS];
    pthread_t th[IDEM_RACERS];
    for (int i = 0; i < IDEM_RACERS; i++) {
        memset(&rs[i], 0, sizeof rs[i]);
        rs[i].n = i;
        rs[i].bar = &bar;
        pthread_create(&th[i], NULL, idem_race, &rs[i]);
    }
    for (int i = 0; i < IDEM_RACERS; i++)
        pthread_join(th[i], NULL);
    pthread_barrier_destroy(&bar);
    for (int k = 0; k < IDEM_ROUNDS; k++) {
        int won = 0;
        const char *winner = NULL;
        for (int i = 0; i < IDEM_RACERS; i++) {
            assert_true(rs[i].rc[k] == 0 || rs[i].rc[k] == 1);
            if (rs[i].rc[k] == 0) won++, winner = rs[i].mine[k];
        }
        assert_int_equal(won, 1);
        for (int i = 0; i < IDEM_RACERS; i++)
            assert_string_equal(rs[i].got[k], winner);
        char q[160];
        snprintf(q, sizeof q,
                 "SELECT count(*) FROM vx_jobs WHERE idem_key = 'race-%d' AND id = '%s'", k,
                 winner);
        assert_int_equal(sql_long(q), 1);
    }
    assert_int_equal(sql_long("SELECT count(*) FROM vx_jobs WHERE kind = 'idem'"), IDEM_ROUNDS);
}

static void test_concurrent_claims(void **state)
{
    vx_pg *pg = open_as("feeder", 0);
    for (unsigned i = 0; i < RACE_JOBS; i++) {
        char id[33];
        make_id(id, 1000 + i);
        submit(pg, id, "race", 0);
    }
    char other[33];
    make_id(other, 5000);
    submit(pg, other, "not-race", 0);
    static racer rs[RACERS];
    pthread_t th[RACERS];
    for (int i = 0; i < RACERS; i++) {
        memset(&rs[i], 0, sizeof rs[i]);
        snprintf(rs[i].name, sizeof rs[i].name, "racer%d", i);
        pthread_create(&th[i], NULL, race, &rs[i]);
    }
    int total = 0;
    for (int i = 0; i < RACERS; i++) {
        pthread_join(th[i], NULL);
        assert_int_equal(rs[i].errors, 0);
        total += rs[i].n;
    }
    /* Every job claimed once, none twice, the other kind left alone. */
    assert_int_equal(total, RACE_JOBS);
    for (int a = 0; a < RACERS; a++)
        for (int i = 0; i < rs[a].n; i++)
            for (int b = a; b < RACERS; b++)
                for (int k = (b == a ? i + 1 : 0); k < rs[b].n; k++)
                    assert_string_not_equal(rs[a].got[i], rs[b].got[k]);
    assert_int_equal(sql_long("SELECT count(*) FROM vx_jobs WHERE kind = 'race' AND"
                              " state = 'running' AND attempt = 1"),
                     RACE_JOBS);
    vx_pg_job jb;
    vx_err err = {0};
    assert_int_equal(vx_pg_get(pg, other, &jb, &err), 0);
    assert_string_equal(jb.state, "queued");
    vx_pg_job_clear(&jb);
    vx_pg_close(pg);
}

static void test_lease_expiry_and_fencing(void **state)
{
    vx_pg *a = open_as("replica-a", 1.0), *b = open_as("replica-b", 30);
    vx_err err = {0};
    char id[33];
    make_id(id, 300);
    submit(a, id, "voxelize", 0);
    vx_pg_job ja, jb;
    assert_int_equal(vx_pg_claim(a, NULL, &ja, &err), 1);
    assert_int_equal(ja.attempt, 1);
    assert_string_equal(ja.replica, "replica-a");
    assert_true(ja.lease_expires > ja.started + 0.5 && ja.lease_expires < ja.started + 1.5);
    assert_true(vx_pg_renew_interval(a) > 0.3 && vx_pg_renew_interval(a) < 0.4);
    assert_true(vx_pg_renew_interval(b) == 10);
    int cancel = 1;
    assert_int_equal(vx_pg_renew(a, id, 1, 0.5, &cancel, &err), 0);
    assert_int_equal(cancel, 0);
    /* Nothing has expired yet: nothing moves, b finds no work. */
    assert_int_equal(vx_pg_requeue_expired(b, 0, NULL, NULL, &err), 0);
    assert_int_equal(vx_pg_claim(b, NULL, &jb, &err), 0);
    /* a stalls past its lease; b re-queues and, after the backoff, claims. */
    nap(1.3);
    int rq = 0, fl = 0;
    assert_int_equal(vx_pg_requeue_expired(b, 0, &rq, &fl, &err), 1);
    assert_int_equal(rq, 1);
    assert_int_equal(fl, 0);
    vx_pg_job q;
    assert_int_equal(vx_pg_get(b, id, &q, &err), 0);
    assert_string_equal(q.state, "queued");
    assert_true(q.progress == 0); /* renewed at 0.5: a queued job is at 0 */
    assert_true(q.not_before > ja.started + 1);
    assert_int_equal(cJSON_GetArraySize(q.errors), 1);
    cJSON *e0 = cJSON_GetArrayItem(q.errors, 0);
    assert_string_equal(cJSON_GetObjectItem(e0, "code")->valuestring, "lease_expired");
    assert_int_equal(cJSON_GetObjectItem(e0, "attempt")->valueint, 1);
    assert_string_equal(cJSON_GetObjectItem(e0, "replica")->valuestring, "replica-a");
    vx_pg_job_clear(&q);
    int got = 0;
    for (int i = 0; i < 50 && !got; i++) {
        got = vx_pg_claim(b, NULL, &jb, &err);
        if (!got) nap(0.05);
    }
    assert_int_equal(got, 1);
    assert_int_equal(jb.attempt, 2);
    assert_string_equal(jb.replica, "replica-b");
    /* a comes back: its renewal and completion are fenced off. */
    assert_int_equal(vx_pg_renew(a, id, 1, 0.5, &cancel, &err), 1);
    cJSON *stale = cJSON_Parse("{\"outputs\":{\"grid\":{\"location\":\"results/x/1/grid.vdb\","
                               "\"bytes\":1}},\"by\":\"a\"}");
    assert_int_equal(vx_pg_complete(a, id, 1, stale, &err), 1);
    /* Even with the right attempt number, another replica cannot complete. */
    assert_int_equal(vx_pg_complete(a, id, 2, stale, &err), 1);
    char st[16];
    assert_int_equal(vx_pg_fail(a, id, 1, &err, 1, st, &err), 1);
    cJSON *win = cJSON_Parse("{\"outputs\":{\"grid\":{\"location\":\"results/x/2/grid.vdb\","
                             "\"bytes\":2,\"content_type\":\"application/x-vdb\"}},\"by\":\"b\"}");
    assert_int_equal(vx_pg_complete(b, id, 2, win, &err), 0);
    /* The winner's completion again (a try whose answer was lost with its
     * connection, retried): already recorded, so 0, not stale (a stale
     * answer made the winner remove its own results) and nothing changes;
     * another attempt's stays stale. */
    assert_int_equal(vx_pg_complete(b, id, 2, win, &err), 0);
    assert_int_equal(vx_pg_complete(a, id, 1, stale, &err), 1);
    assert_int_equal(vx_pg_get(a, id, &q, &err), 0);
    assert_string_equal(q.state, "succeeded");
    assert_int_equal(q.attempt, 2);
    assert_string_equal(q.replica, "replica-b");
    assert_string_equal(cJSON_GetObjectItem(q.result, "by")->valuestring, "b");
    assert_true(q.finished >= q.started);
    vx_pg_job_clear(&q);
    /* The results index holds the winner's output only. */
    char qs[200];
    snprintf(qs, sizeof qs,
             "SELECT attempt * 1000 + bytes FROM vx_results WHERE job_id = '%s' AND name = 'grid'",
             id);
    assert_int_equal(sql_long(qs), 2002);
    snprintf(qs, sizeof qs, "SELECT count(*) FROM vx_results WHERE job_id = '%s'", id);
    assert_int_equal(sql_long(qs), 1);
    /* The same replica's own stale attempt is fenced off by its number. */
    char id2[33];
    make_id(id2, 301);
    submit(a, id2, "voxelize", 0);
    vx_pg_job_clear(&ja);
    assert_int_equal(vx_pg_claim(a, NULL, &ja, &err), 1);
    nap(1.3);
    assert_int_equal(vx_pg_requeue_expired(a, 0, NULL, NULL, &err), 1);
    vx_pg_job_clear(&ja);
    for (got = 0; !got;) {
        got = vx_pg_claim(a, NULL, &ja, &err);
        assert_int_not_equal(got, -1);
        if (!got) nap(0.05);
    }
    assert_int_equal(ja.attempt, 2);
    assert_int_equal(vx_pg_renew(a, id2, 1, 0.5, &cancel, &err), 1);
    assert_int_equal(vx_pg_complete(a, id2, 1, stale, &err), 1);
    assert_int_equal(vx_pg_complete(a, id2, 2, win, &err), 0);
    assert_int_equal(vx_pg_get(a, id2, &q, &err), 0);
    assert_string_equal(cJSON_GetObjectItem(q.result, "by")->valuestring, "b");
    vx_pg_job_clear(&q);
    cJSON_Delete(stale);
    cJSON_Delete(win);
    vx_pg_job_clear(&ja);
    vx_pg_job_clear(&jb);
    vx_pg_close(a);
    vx_pg_close(b);
}

/* A database that holds a statement (a lock here; a black-holed link or a
 * stopped server alike) answers 503 database_unavailable within the
 * statement timeout, not never; the next statement reconnects. */
static void test_statement_timeout(void **state)
{
    (void)state;
    vx_pg_desc d = {.url = url(), .replica = "timeout", .statement_timeout_s = 1};
    vx_err err = {0};
    vx_pg *pg = vx_pg_open(&d, &err);
    assert_non_null(pg);
    char id[33];
    make_id(id, 900);
    submit(pg, id, "voxelize", 0);
    PGconn *locker = PQconnectdb(url());
    assert_int_equal(PQstatus(locker), CONNECTION_OK);
    PGresult *r = PQexec(locker, "BEGIN; LOCK TABLE vx_jobs IN ACCESS EXCLUSIVE MODE");
    assert_int_equal(PQresultStatus(r), PGRES_COMMAND_OK);
    PQclear(r);
    vx_pg_job jb;
    double t0 = vx_mono();
    assert_int_equal(vx_pg_get(pg, id, &jb, &err), -1);
    double dt = vx_mono() - t0;
    assert_int_equal(err.kind, VX_EUNAVAIL);
    assert_string_equal(err.code, "database_unavailable");
    if (dt > 3) fail_msg("the locked read took %.1f s", dt);
    PQclear(PQexec(locker, "ROLLBACK"));
    PQfinish(locker);
    /* the lock gone, the module works again (after its reconnect backoff) */
    int rc = -1, i;
    for (i = 0; i < 50 && rc; i++) {
        rc = vx_pg_get(pg, id, &jb, &err);
        if (rc) nap(0.1);
    }
    assert_int_equal(rc, 0);
    assert_string_equal(jb.state, "queued");
    vx_pg_job_clear(&jb);
    /* A server that answers nothing at all (its backend stopped, as a
     * black-holed link or a frozen host): the server's own timeouts cannot
     * fire, the module's deadline does. Needs the right to signal it. */
    r = sql("SELECT pid FROM pg_stat_activity WHERE application_name = 'voxeld'");
    assert_int_equal(PQntuples(r), 1);
    pid_t backend = (pid_t)atol(PQgetvalue(r, 0, 0));
    PQclear(r);
    if (kill(backend, SIGSTOP) == 0) {
        t0 = vx_mono();
        rc = vx_pg_get(pg, id, &jb, &err);
        dt = vx_mono() - t0;
        kill(backend, SIGCONT);
        assert_int_equal(rc, -1);
        assert_string_equal(err.code, "database_unavailable");
        if (dt < 0.9 || dt > 3) fail_msg("the stopped server's read took %.1f s", dt);
        for (rc = -1, i = 0; i < 50 && rc; i++) {
            rc = vx_pg_get(pg, id, &jb, &err);
            if (rc) nap(0.1);
        }
        assert_int_equal(rc, 0);
        vx_pg_job_clear(&jb);
    } else {
        printf("note: cannot stop the server's backend (%s): its deadline not checked\n",
               strerror(errno));
    }
    vx_pg_close(pg);
}

static void claim_soon(vx_pg *pg, vx_pg_job *jb)
{
    vx_err err = {0};
    for (int i = 0; i < 100; i++) {
        int rc = vx_pg_claim(pg, "flaky", jb, &err);
        assert_int_not_equal(rc, -1);
        if (rc == 1) return;
        nap(0.05);
    }
    fail_msg("no job to claim");
}

static void test_max_attempts(void **state)
{
    vx_pg *a = open_as("ra", 0.5), *b = open_as("rb", 30);
    vx_err err = {0}, why = {0};
    char id[33], st[16];
    make_id(id, 400);
    submit(a, id, "flaky", 0); /* the default: 3 attempts */
    vx_pg_job jb;
    /* 1: fails with an error that may be retried. */
    claim_soon(a, &jb);
    assert_int_equal(jb.attempt, 1);
    int cancel = 0;
    assert_int_equal(vx_pg_renew(a, id, 1, 0.5, &cancel, &err), 0);
    vx_err_set(&why, VX_EGPU, "gl_context_lost", "context lost in attempt 1");
    assert_int_equal(vx_pg_fail(a, id, 1, &why, 1, st, &err), 0);
    assert_string_equal(st, "queued");
    vx_pg_job_clear(&jb);
    assert_int_equal(vx_pg_get(b, id, &jb, &err), 0);
    assert_true(jb.progress == 0); /* queued again: back to 0 */
    vx_pg_job_clear(&jb);
    /* 2: the lease runs out. */
    claim_soon(a, &jb);
    assert_int_equal(jb.attempt, 2);
    vx_pg_job_clear(&jb);
    nap(0.7);
    assert_int_equal(vx_pg_requeue_expired(b, 0, NULL, NULL, &err), 1);
    /* 3: fails again; no attempt left. */
    claim_soon(b, &jb);
    assert_int_equal(jb.attempt, 3);
    vx_pg_job_clear(&jb);
    vx_err_set(&why, VX_EGPU, "out_of_gpu_memory", "attempt 3 ran out of GPU memory");
    assert_int_equal(vx_pg_fail(b, id, 3, &why, 1, st, &err), 0);
    assert_string_equal(st, "failed");
    assert_int_equal(vx_pg_claim(b, "flaky", &jb, &err), 0);
    assert_int_equal(vx_pg_get(b, id, &jb, &err), 0);
    assert_string_equal(jb.state, "failed");
    assert_true(jb.finished > 0);
    assert_int_equal(cJSON_GetArraySize(jb.errors), 3);
    const char *codes[] = {"gl_context_lost", "lease_expired", "out_of_gpu_memory"};
    const char *reps[] = {"ra", "ra", "rb"};
    for (int i = 0; i < 3; i++) {
        cJSON *e = cJSON_GetArrayItem(jb.errors, i);
        assert_int_equal(cJSON_GetObjectItem(e, "attempt")->valueint, i + 1);
        assert_string_equal(cJSON_GetObjectItem(e, "code")->valuestring, codes[i]);
        assert_string_equal(cJSON_GetObjectItem(e, "replica")->valuestring, reps[i]);
    }
    assert_string_equal(cJSON_GetObjectItem(cJSON_GetArrayItem(jb.errors, 0), "kind")->valuestring,
                        vx_err_kind_name(VX_EGPU));
    vx_pg_job_clear(&jb);

    /* A job whose error is final fails at once; a released one keeps its tries. */
    char id2[33];
    make_id(id2, 401);
    submit(a, id2, "flaky", 2);
    claim_soon(a, &jb);
    vx_pg_job_clear(&jb);
    assert_int_equal(vx_pg_renew(a, id2, 1, 0.5, &cancel, &err), 0);
    assert_int_equal(vx_pg_release(a, id2, 1, &err), 0);
    assert_int_equal(vx_pg_get(b, id2, &jb, &err), 0);
    assert_true(jb.progress == 0);
    vx_pg_job_clear(&jb);
    claim_soon(a, &jb);
    assert_int_equal(jb.attempt, 2);
    assert_int_equal(jb.max_attempts, 3);
    vx_pg_job_clear(&jb);
    vx_err_set(&why, VX_EUNPROC, "mesh_has_no_faces", "no faces");
    assert_int_equal(vx_pg_fail(a, id2, 2, &why, 0, st, &err), 0);
    assert_string_equal(st, "failed");
    vx_pg_close(a);
    vx_pg_close(b);
}

static void test_cancel(void **state)
{
    vx_pg *pg = open_as("rc", 30), *lis = open_as("rcl", 0);
    vx_err err = {0};
    char q[33], r[33], missing[33];
    make_id(q, 500);
    make_id(r, 501);
    make_id(missing, 502);
    submit(pg, q, "c1", 0);
    submit(pg, r, "c2", 0);
    int was = 1;
    assert_int_equal(vx_pg_cancel(pg, q, &was, &err), 0);
    assert_int_equal(was, 0);
    vx_pg_job jb;
    assert_int_equal(vx_pg_get(pg, q, &jb, &err), 0);
    assert_string_equal(jb.state, "canceled");
    vx_pg_job_clear(&jb);
    assert_int_equal(vx_pg_claim(pg, "c1", &jb, &err), 0);
    /* Running: renew reports the request; the run then fails as canceled. */
    assert_int_equal(vx_pg_claim(pg, "c2", &jb, &err), 1);
    vx_pg_job_clear(&jb);
    assert_int_equal(vx_pg_listen(lis, &err), 0);
    int cancel = 1;
    assert_int_equal(vx_pg_renew(pg, r, 1, 0.5, &cancel, &err), 0);
    assert_int_equal(cancel, 0);
    assert_int_equal(vx_pg_cancel(pg, r, &was, &err), 0);
    assert_int_equal(was, 1);
    char note[128], want[100];
    assert_int_equal(vx_pg_wait(lis, 5, note, sizeof note, &err), 1);
    snprintf(want, sizeof want, "cancel %s c2", r);
    assert_string_equal(note, want);
    assert_int_equal(vx_pg_renew(pg, r, 1, 0.5, &cancel, &err), 0);
    assert_int_equal(cancel, 1);
    vx_err why = {0};
    char st[16];
    vx_err_set(&why, VX_ECANCELED, "canceled", "canceled by a client");
    assert_int_equal(vx_pg_fail(pg, r, 1, &why, 1, st, &err), 0);
    assert_string_equal(st, "canceled");
    assert_int_equal(vx_pg_cancel(pg, r, &was, &err), -1);
    assert_string_equal(err.code, "job_finished");
    assert_int_equal(vx_pg_cancel(pg, missing, &was, &err), -1);
    assert_string_equal(err.code, "job_not_found");
    vx_pg_close(lis);
    vx_pg_close(pg);
}

typedef struct waiter {
    vx_pg *pg;
    char payload[128];
    int rc;
    double waited;
} waiter;

static void *wait_main(void *ud)
{
    waiter *w = ud;
    vx_err err = {0};
    double t0 = vx_mono();
    w->rc = vx_pg_wait(w->pg, 10, w->payload, sizeof w->payload, &err);
    w->waited = vx_mono() - t0;
    return NULL;
}

static void test_notify(void **state)
{
    vx_pg *pg = open_as("rn", 0), *lis = open_as("listener", 0);
    vx_err err = {0};
    char buf[128];
    assert_int_equal(vx_pg_wait(lis, 0.1, buf, sizeof buf, &err), -1); /* not listening */
    assert_int_equal(vx_pg_listen(lis, &err), 0);
    /* No activity: a timeout. */
    double t0 = vx_mono();
    assert_int_equal(vx_pg_wait(lis, 0.3, buf, sizeof buf, &err), 0);
    assert_true(vx_mono() - t0 >= 0.29);
    /* A submission on another connection wakes a waiting thread at once. */
    waiter w = {.pg = lis};
    pthread_t th;
    pthread_create(&th, NULL, wait_main, &w);
    nap(0.3);
    char id[33], want[100];
    make_id(id, 600);
    submit(pg, id, "voxelize", 0);
    pthread_join(th, NULL);
    assert_int_equal(w.rc, 1);
    snprintf(want, sizeof want, "queued %s voxelize", id);
    assert_string_equal(w.payload, want);
    assert_true(w.waited < 5);
    /* A claim sends nothing (the hot path); the completion wakes waiters. */
    vx_pg_job jb;
    assert_int_equal(vx_pg_claim(pg, "voxelize", &jb, &err), 1);
    assert_int_equal(vx_pg_wait(lis, 0.3, buf, sizeof buf, &err), 0);
    cJSON *res = cJSON_CreateObject();
    assert_int_equal(vx_pg_complete(pg, id, jb.attempt, res, &err), 0);
    cJSON_Delete(res);
    vx_pg_job_clear(&jb);
    assert_int_equal(vx_pg_wait(lis, 5, buf, sizeof buf, &err), 1);
    snprintf(want, sizeof want, "succeeded %s voxelize", id);
    assert_string_equal(buf, want);
    vx_pg_close(lis);
    vx_pg_close(pg);
}

static void pg_sh(const char *what)
{
    char cmd[600];
    snprintf(cmd, sizeof cmd, "bash '%s' %s '%s'", getenv("VX_PG_SH"), what, getenv("VX_PG_DIR"));
    assert_int_equal(system(cmd), 0);
}

static void test_restart(void **state)
{
    vx_pg *pg = open_as("rr", 30), *lis = open_as("rl", 0);
    vx_err err = {0};
    assert_int_equal(vx_pg_listen(lis, &err), 0);
    char id[33], id2[33];
    make_id(id, 700);
    make_id(id2, 701);
    submit(pg, id, "voxelize", 0);
    char buf[128];
    while (vx_pg_wait(lis, 0.2, buf, sizeof buf, &err) == 1) {
    }
    /* A restart: the next read reconnects and re-runs by itself. */
    pg_sh("restart");
    vx_pg_job jb;
    assert_int_equal(vx_pg_get(pg, id, &jb, &err), 0);
    assert_string_equal(jb.state, "queued");
    vx_pg_job_clear(&jb);
    /* Down: writes answer VX_EUNAVAIL (503 + Retry-After) without blocking. */
    pg_sh("stop");
    vx_pg_new_job nj = {.id = id2, .kind = "voxelize"};
    double t0 = vx_mono();
    assert_int_equal(vx_pg_submit(pg, &nj, 1, &err), -1);
    assert_int_equal(err.kind, VX_EUNAVAIL);
    assert_string_equal(err.code, "database_unavailable");
    assert_int_equal(vx_pg_get(pg, id, &jb, &err), -1);
    assert_int_equal(err.kind, VX_EUNAVAIL);
    assert_true(vx_pg_retry_after(pg) >= 1);
    assert_true(vx_mono() - t0 < 3);
    /* The waiter times out meanwhile (the polling fallback). */
    assert_int_equal(vx_pg_wait(lis, 0.5, buf, sizeof buf, &err), 0);
    /* Back: calls succeed again within the backoff. */
    pg_sh("start");
    int ok = 0;
    for (int i = 0; i < 100 && !ok; i++) {
        ok = vx_pg_submit(pg, &nj, 1, &err) == 0;
        if (!ok) {
            assert_int_equal(err.kind, VX_EUNAVAIL);
            nap(0.1);
        }
    }
    assert_true(ok);
    assert_int_equal(vx_pg_get(pg, id2, &jb, &err), 0);
    vx_pg_job_clear(&jb);
    /* The listener reconnected and listens again: first "" (re-read what
     * you wait for), then the next notification. */
    int got = 0;
    for (int i = 0; i < 10 && !got; i++)
        got = vx_pg_wait(lis, 1, buf, sizeof buf, &err);
    assert_int_equal(got, 1);
    assert_string_equal(buf, "");
    int was;
    assert_int_equal(vx_pg_cancel(pg, id2, &was, &err), 0);
    assert_int_equal(vx_pg_wait(lis, 5, buf, sizeof buf, &err), 1);
    char want[100];
    snprintf(want, sizeof want, "canceled %s voxelize", id2);
    assert_string_equal(buf, want);
    vx_pg_close(lis);
    vx_pg_close(pg);
}

/* Schema 2: params keep their key order (json), an Idempotency-Key answers
 * its first job (and refuses another request), a succeeded job is found by
 * its fingerprint, progress is written by renewals, lists filter by mesh,
 * delete takes finished jobs only, queued counts, ping. */
static void test_v2(void **state)
{
    (void)state;
    vx_pg *pg = open_as("v2", 30);
    vx_err err = {0};
    char a[33], b[33], c[33];
    make_id(a, 9001);
    make_id(b, 9002);
    make_id(c, 9003);
    cJSON *p = cJSON_Parse("{\"zeta\":1,\"alpha\":2,\"mid\":{\"y\":1,\"x\":2}}");
    const char *mesh = "aaaa000000000000000000000000000000000000000000000000000000000001";
    vx_pg_new_job nj = {.id = a,
                        .kind = "voxelize",
                        .mesh = mesh,
                        .params = p,
                        .fp = "00000000000000aa",
                        .idem = "key-1"};
    vx_pg_job ex;
    assert_int_equal(vx_pg_submit_idem(pg, &nj, &ex, &err), 0);
    /* The same key and request: the first job, not a new one. */
    nj.id = b;
    assert_int_equal(vx_pg_submit_idem(pg, &nj, &ex, &err), 1);
    assert_string_equal(ex.id, a);
    assert_string_equal(ex.idem, "key-1");
    vx_pg_job_clear(&ex);
    /* The same key, another request. */
    nj.fp = "00000000000000bb";
    assert_int_equal(vx_pg_submit_idem(pg, &nj, &ex, &err), -1);
    assert_string_equal(err.code, "idempotency_key_reused");
    assert_int_equal(sql_long("SELECT count(*) FROM vx_jobs WHERE idem_key = 'key-1'"), 1);
    /* Key order as sent. */
    vx_pg_job got;
    assert_int_equal(vx_pg_get(pg, a, &got, &err), 0);
    char *text = cJSON_PrintUnformatted(got.params);
    assert_string_equal(text, "{\"zeta\":1,\"alpha\":2,\"mid\":{\"y\":1,\"x\":2}}");
    cJSON_free(text);
    assert_string_equal(got.fp, "00000000000000aa");
    vx_pg_job_clear(&got);
    assert_int_equal(vx_pg_queued(pg, &err), 1);
    assert_int_equal(vx_pg_ping(pg, &err), 0);
    /* Not finished: no delete, not found by fingerprint. */
    assert_int_equal(vx_pg_delete(pg, a, &err), -1);
    assert_string_equal(err.code, "job_not_finished");
    assert_int_equal(vx_pg_find_done(pg, "00000000000000aa", &got, &err), 0);
    /* Claimed, renewed with progress, completed with ordered outputs. */
    vx_pg_job cl;
    assert_int_equal(vx_pg_claim(pg, "voxelize", &cl, &err), 1);
    assert_string_equal(cl.id, a);
    assert_true(cl.progress == 0);
    int cancel = 0;
    assert_int_equal(vx_pg_renew(pg, a, cl.attempt, 0.25, &cancel, &err), 0);
    assert_int_equal(vx_pg_get(pg, a, &got, &err), 0);
    assert_true(got.progress == 0.25);
    vx_pg_job_clear(&got);
    cJSON *res = cJSON_Parse("{\"outputs\":{\"voxels\":{\"location\":\"results/x/1/voxels.raw\","
                             "\"bytes\":8},\"a_second\":{\"location\":\"y\",\"bytes\":1}}}");
    assert_int_equal(vx_pg_complete(pg, a, cl.attempt, res, &err), 0);
    cJSON_Delete(res);
    char q0[160];
    snprintf(q0, sizeof q0, "SELECT count(*) FROM vx_results WHERE job_id = '%s'", a);
    assert_int_equal(sql_long(q0), 2); /* the results index of both outputs */
    vx_pg_job_clear(&cl);
    assert_int_equal(vx_pg_get(pg, a, &got, &err), 0);
    assert_true(got.progress == 1);
    const cJSON *outs = cJSON_GetObjectItemCaseSensitive(got.result, "outputs");
    assert_string_equal(outs->child->string, "voxels"); /* the primary one stays first */
    vx_pg_job_clear(&got);
    assert_int_equal(vx_pg_find_done(pg, "00000000000000aa", &got, &err), 1);
    assert_string_equal(got.id, a);
    vx_pg_job_clear(&got);
    /* Lists by mesh. */
    nj = (vx_pg_new_job){.id = c, .kind = "preview", .mesh = "bbbb", .params = p};
    assert_int_equal(vx_pg_submit(pg, &nj, 1, &err), 0);
    vx_pg_filter f = {.mesh = mesh};
    vx_pg_job *rows = NULL;
    size_t n = 0;
    char next[33];
    assert_int_equal(vx_pg_list(pg, &f, NULL, 10, &rows, &n, next, &err), 0);
    assert_int_equal(n, 1);
    assert_string_equal(rows[0].id, a);
    vx_pg_jobs_free(rows, n);
    /* Finished: deleted, with its results index. */
    assert_int_equal(vx_pg_delete(pg, a, &err), 0);
    assert_int_equal(vx_pg_get(pg, a, &got, &err), -1);
    assert_string_equal(err.code, "job_not_found");
    assert_int_equal(vx_pg_delete(pg, a, &err), -1);
    assert_string_equal(err.code, "job_not_found");
    char q[160];
    snprintf(q, sizeof q, "SELECT count(*) FROM vx_results WHERE job_id = '%s'", a);
    assert_int_equal(sql_long(q), 0);
    cJSON_Delete(p);
    vx_pg_close(pg);
}

/* Schema 3: a job split into child jobs is claimable only once they all
 * succeeded; a child that fails fails its parent and cancels its waiting
 * siblings; canceling the parent cancels its children. */
static void test_children(void **state)
{
    (void)state;
    vx_pg *pg = open_as("kids", 30);
    vx_err err = {0};
    char par[33], k1[33], k2[33];
    make_id(par, 9101);
    make_id(k1, 9102);
    make_id(k2, 9103);
    vx_pg_new_job jobs[3] = {{.id = par, .kind = "voxelize", .children = 2},
                             {.id = k1, .kind = "voxelize", .parent = par},
                             {.id = k2, .kind = "voxelize", .parent = par}};
    assert_int_equal(vx_pg_submit(pg, jobs, 3, &err), 0);
    vx_pg_job a, b, c;
    /* The parent is oldest, but the children come first. */
    assert_int_equal(vx_pg_claim(pg, "voxelize", &a, &err), 1);
    assert_string_equal(a.parent, par);
    assert_int_equal(vx_pg_claim(pg, "voxelize", &b, &err), 1);
    assert_string_equal(b.parent, par);
    assert_int_equal(vx_pg_claim(pg, "voxelize", &c, &err), 0);
    cJSON *res = cJSON_Parse("{\"outputs\":{}}");
    assert_int_equal(vx_pg_complete(pg, a.id, a.attempt, res, &err), 0);
    assert_int_equal(vx_pg_claim(pg, "voxelize", &c, &err), 0); /* one child still runs */
    int done = 0, total = 0;
    assert_int_equal(vx_pg_child_counts(pg, par, &done, &total, &err), 0);
    assert_int_equal(done, 1);
    assert_int_equal(total, 2);
    assert_int_equal(vx_pg_complete(pg, b.id, b.attempt, res, &err), 0);
    assert_int_equal(vx_pg_claim(pg, "voxelize", &c, &err), 1);
    assert_string_equal(c.id, par);
    assert_int_equal(c.children, 2);
    vx_pg_job_clear(&a);
    vx_pg_job_clear(&b);
    vx_pg_job_clear(&c);

    /* A child that fails for good fails its parent, cancels its sibling. */
    make_id(par, 9111);
    make_id(k1, 9112);
    make_id(k2, 9113);
    assert_int_equal(vx_pg_submit(pg, jobs, 3, &err), 0);
    assert_int_equal(vx_pg_claim(pg, "voxelize", &a, &err), 1);
    vx_err why;
    vx_err_set(&why, VX_EUNPROC, "invalid_params", "no such brick");
    char st[16];
    assert_int_equal(vx_pg_fail(pg, a.id, a.attempt, &why, 0, st, &err), 0);
    assert_string_equal(st, "failed");
    assert_int_equal(vx_pg_get(pg, par, &c, &err), 0);
    assert_string_equal(c.state, "failed");
    const cJSON *last = cJSON_GetArrayItem(c.errors, cJSON_GetArraySize(c.errors) - 1);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(last, "code")), "child_failed");
    assert_non_null(
        strstr(cJSON_GetStringValue(cJSON_GetObjectItem(last, "message")), "no such brick"));
    vx_pg_job_clear(&c);
    const char *sib = strcmp(a.id, k1) ? k1 : k2;
    assert_int_equal(vx_pg_get(pg, sib, &c, &err), 0);
    assert_string_equal(c.state, "canceled");
    vx_pg_job_clear(&c);
    vx_pg_job_clear(&a);

    /* Canceling the parent cancels its children. */
    make_id(par, 9121);
    make_id(k1, 9122);
    make_id(k2, 9123);
    assert_int_equal(vx_pg_submit(pg, jobs, 3, &err), 0);
    int was_running = 1;
    assert_int_equal(vx_pg_cancel(pg, par, &was_running, &err), 0);
    assert_int_equal(was_running, 0);
    for (int i = 0; i < 2; i++) {
        assert_int_equal(vx_pg_get(pg, i ? k2 : k1, &c, &err), 0);
        assert_string_equal(c.state, "canceled");
        vx_pg_job_clear(&c);
    }
    cJSON_Delete(res);
    vx_pg_close(pg);
}

/* The mesh catalog (pg_mesh.c). */
static char purged[4][65];
static int npurged, purge_fails;

static int on_purge(void *ud, const char *id, const char *format)
{
    (void)ud;
    assert_string_equal(format, "obj");
    if (purge_fails) return -1;
    if (npurged < 4) snprintf(purged[npurged++], 65, "%s", id);
    return 0;
}

typedef struct purge_run {
    vx_pg *pg;
    int n;
} purge_run;

static void *purge_thread(void *arg)
{
    purge_run *pr = arg;
    vx_err err = {0};
    pr->n = vx_pg_mesh_purge(pr->pg, 0, on_purge, NULL, &err);
    return NULL;
}

static void mesh_id(char id[65], int n)
{
    snprintf(id, 65, "%064x", n);
}

static cJSON *mesh_meta(const char *id, const char *name)
{
    cJSON *m = cJSON_CreateObject();
    cJSON_AddStringToObject(m, "id", id);
    cJSON_AddStringToObject(m, "format", "obj");
    cJSON_AddStringToObject(m, "name", name);
    cJSON_AddNumberToObject(m, "bytes", 123);
    cJSON_AddNumberToObject(m, "triangles", 4);
    return m;
}

static void test_meshes(void **state)
{
    (void)state;
    PQclear(sql("DELETE FROM vx_meshes"));
    vx_pg *pg = open_as("meshes", 30), *other = open_as("meshes2", 30);
    vx_err err = {0};
    char ids[5][65];
    int existed = -1;
    for (int i = 0; i < 5; i++) {
        mesh_id(ids[i], 0x5a0 + i);
        cJSON *m = mesh_meta(ids[i], "first");
        assert_int_equal(vx_pg_mesh_put(pg, ids[i], m, &existed, NULL, &err), 0);
        assert_int_equal(existed, 0);
        cJSON_Delete(m);
    }
    /* Again, another name: it existed, and the first upload's row stays. */
    cJSON *m = mesh_meta(ids[0], "second"), *got = NULL, *stored = NULL;
    assert_int_equal(vx_pg_mesh_put(other, ids[0], m, &existed, &stored, &err), 0);
    assert_int_equal(existed, 1);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(stored, "name")), "first");
    cJSON_Delete(stored);
    cJSON_Delete(m);
    assert_int_equal(vx_pg_mesh_get(other, ids[0], &got, &err), 1);
    /* the metadata keeps its key order (json, not jsonb) */
    assert_string_equal(got->child->string, "id");
    cJSON_Delete(got);
    assert_int_equal(vx_pg_mesh_count(pg, &err), 5);
    /* Pages of 2: 2, 2, 1, in id order. */
    char next[65] = "", after[65] = "";
    int pages = 0, seen = 0;
    do {
        cJSON *page = vx_pg_mesh_list(other, after[0] ? after : NULL, 2, next, &err);
        assert_non_null(page);
        const cJSON *it;
        cJSON_ArrayForEach(it, page)
        {
            assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(it, "id")), ids[seen]);
            seen++;
        }
        cJSON_Delete(page);
        snprintf(after, sizeof after, "%s", next);
        pages++;
    } while (after[0]);
    assert_int_equal(pages, 3);
    assert_int_equal(seen, 5);

    /* Deleted: gone for get, list and count at once; a second delete is 404. */
    assert_int_equal(vx_pg_mesh_delete(pg, ids[1], &err), 0);
    assert_int_equal(vx_pg_mesh_get(other, ids[1], &got, &err), 0);
    assert_int_equal(vx_pg_mesh_count(other, &err), 4);
    assert_int_equal(vx_pg_mesh_delete(other, ids[1], &err), -1);
    assert_string_equal(err.code, "mesh_not_found");
    /* A queued job names ids[2] (its mesh) and a running one ids[3] (in
     * its params): deleted, their bytes wait for the jobs. */
    assert_int_equal(vx_pg_mesh_delete(pg, ids[2], &err), 0);
    assert_int_equal(vx_pg_mesh_delete(pg, ids[3], &err), 0);
    char j1[33], j2[33];
    make_id(j1, 9201);
    make_id(j2, 9202);
    char params[200];
    snprintf(params, sizeof params, "{\"meshes\":[{\"mesh\":\"%s\"}]}", ids[3]);
    cJSON *pj = cJSON_Parse(params);
    vx_pg_new_job jobs[2] = {{.id = j1, .kind = "render", .mesh = ids[2]},
                             {.id = j2, .kind = "render", .mesh = ids[4], .params = pj}};
    assert_int_equal(vx_pg_submit(pg, jobs, 2, &err), 0);
    vx_pg_job run;
    assert_int_equal(vx_pg_claim(pg, "render", &run, &err), 1);
    assert_string_equal(run.id, j1);
    vx_pg_job_clear(&run);
    assert_int_equal(vx_pg_claim(pg, "render", &run, &err), 1);
    npurged = 0;
    assert_int_equal(vx_pg_mesh_purge(other, 0, on_purge, NULL, &err), 1);
    assert_string_equal(purged[0], ids[1]);
    assert_int_equal(sql_long("SELECT count(*) FROM vx_meshes"), 4);
    /* A failing byte removal keeps the row for the next purge. */
    cJSON *res = cJSON_Parse("{\"outputs\":{}}");
    assert_int_equal(vx_pg_complete(pg, j1, 1, res, &err), 0);
    purge_fails = 1;
    assert_int_equal(vx_pg_mesh_purge(other, 0, on_purge, NULL, &err), -1);
    purge_fails = 0;
    assert_int_equal(sql_long("SELECT count(*) FROM vx_meshes"), 4);
    npurged = 0;
    assert_int_equal(vx_pg_mesh_purge(other, 0, on_purge, NULL, &err), 1);
    assert_string_equal(purged[0], ids[2]);
    /* An upload in progress (its lock held) holds the purge back until it
     * is done; a re-upload brings a deleted mesh back. */
    assert_int_equal(vx_pg_complete(pg, j2, run.attempt, res, &err), 0);
    vx_pg_job_clear(&run);
    assert_int_equal(vx_pg_mesh_lock(pg, ids[3], &err), 0);
    purge_run pr = {other, -2};
    pthread_t t;
    npurged = 0;
    assert_int_equal(pthread_create(&t, NULL, purge_thread, &pr), 0);
    nap(0.5);
    assert_int_equal(npurged, 0); /* waiting for the upload */
    m = mesh_meta(ids[3], "again");
    assert_int_equal(vx_pg_mesh_put(pg, ids[3], m, &existed, NULL, &err), 0);
    assert_int_equal(existed, 0);
    vx_pg_mesh_unlock(pg, ids[3]);
    pthread_join(t, NULL);
    assert_int_equal(pr.n, 0); /* it came back: not purged */
    assert_int_equal(npurged, 0);
    assert_int_equal(vx_pg_mesh_get(other, ids[3], &got, &err), 1);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(got, "name")), "again");
    cJSON_Delete(got);
    cJSON_Delete(m);
    /* What a store held before the catalog: added, but neither a live nor
     * a deleted row changes. */
    assert_int_equal(vx_pg_mesh_delete(pg, ids[4], &err), 0);
    cJSON *arr = cJSON_CreateArray();
    char fresh[65];
    mesh_id(fresh, 0x5b0);
    cJSON_AddItemToArray(arr, mesh_meta(fresh, "old"));
    cJSON_AddItemToArray(arr, mesh_meta(ids[0], "old"));
    cJSON_AddItemToArray(arr, mesh_meta(ids[4], "old"));
    cJSON_AddItemToArray(arr, mesh_meta("not-an-id", "old"));
    assert_int_equal(vx_pg_mesh_add_missing(pg, arr, &err), 1);
    cJSON_Delete(arr);
    assert_int_equal(vx_pg_mesh_get(pg, fresh, &got, &err), 1);
    cJSON_Delete(got);
    assert_int_equal(vx_pg_mesh_get(pg, ids[4], &got, &err), 0);
    assert_int_equal(vx_pg_mesh_get(pg, ids[0], &got, &err), 1);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(got, "name")), "first");
    cJSON_Delete(got);
    cJSON_Delete(pj);
    cJSON_Delete(res);
    vx_pg_close(pg);
    vx_pg_close(other);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_migrate, setup),
        cmocka_unit_test_setup(test_submit_get_list, setup),
        cmocka_unit_test_setup(test_concurrent_claims, setup),
        cmocka_unit_test_setup(test_lease_expiry_and_fencing, setup),
        cmocka_unit_test_setup(test_max_attempts, setup),
        cmocka_unit_test_setup(test_cancel, setup),
        cmocka_unit_test_setup(test_notify, setup),
        cmocka_unit_test_setup(test_restart, setup),
        cmocka_unit_test_setup(test_v2, setup),
        cmocka_unit_test_setup(test_idem_race, setup),
        cmocka_unit_test_setup(test_children, setup),
        cmocka_unit_test_setup(test_meshes, setup),
        cmocka_unit_test_setup(test_statement_timeout, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
