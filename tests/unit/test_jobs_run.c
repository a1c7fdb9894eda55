/* The job runner with a kind of the test's own (the table comes in
 * vx_jobs_desc.kinds): two outputs declared before either is written keep
 * their own paths (issue #11: vx_run_output reused one buffer); a retry
 * after a context loss (the lose_context hook) starts the stats over; the
 * alive hook is called from the GL thread. Needs a GL context (llvmpipe). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include <sys/stat.h>

#include "jobs/jobs.h"
#include "jobs/jobs_int.h"
#include "jobs/state.h"
#include "store/store.h"

/* The test kind takes no params. */
typedef struct t_params {
    int unused;
} t_params;
static const vx_pspec t_spec[] = {VX_P_END};

static int write_text(const char *path, const char *text, vx_err *err)
{
    FILE *f = fopen(path, "w");
    if (!f) return vx_err_set(err, VX_EIO, "io", "cannot write %s", path);
    fputs(text, f);
    fclose(f);
    return 0;
}

/* Declares both outputs first, then writes each through its own path. */
static int t_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                    vx_err *err)
{
    const char *a = vx_run_output(r, "a", "txt", "text/plain", err);
    const char *b = a ? vx_run_output(r, "b", "txt", "text/plain", err) : NULL;
    if (!b) return -1;
    if (write_text(a, "first", err) || write_text(b, "second", err)) return -1;
    cJSON_AddNumberToObject(vx_run_stats(r), "gl_stat", 1);
    return 0;
}

static const vx_kind k_test = {.name = "two_outputs",
                               .summary = "test",
                               .spec = t_spec,
                               .params_size = sizeof(t_params),
                               .run_gl = t_run_gl};
/* Runs until released or stopped (a cancel). */
static volatile int g_release;
static int w_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                    vx_err *err)
{
    while (!g_release) {
        if (vx_run_progress(r, 0.5, err)) return -1;
        usleep(1000);
    }
    return 0;
}
static const vx_kind k_wait = {.name = "waits",
                               .summary = "test",
                               .spec = t_spec,
                               .params_size = sizeof(t_params),
                               .run_gl = w_run_gl};
static const vx_kind *const rows[] = {&k_test, &k_wait};
static const vx_kinds table = {rows, 2};

static int g_lose, g_alive;
static int lose_context(void *ud)
{
    if (g_lose <= 0) return 0;
    g_lose--;
    return 1;
}
static void alive(void *ud)
{
    __atomic_add_fetch(&g_alive, 1, __ATOMIC_RELAXED);
}

typedef struct fixture {
    char dir[64];
    vx_store *store;
    vx_jobs *jobs;
    char mesh[65];
} fixture;

/* ---- an in-memory job state backend (state.h) ---- */

typedef struct mem_state {
    char *rec[256];
    size_t n;
    int opened, appends, fresh_appends, compacts;
} mem_state;
static mem_state g_mem;
static const vx_jobstate_ops *g_state; /* NULL = the local journal */

static void *mem_open(const char *where, vx_err *err)
{
    g_mem.opened++;
    return &g_mem;
}
static void mem_close(void *st) {}
static long mem_replay(void *st, void (*fn)(const cJSON *rec, void *ud), void *ud, vx_err *err)
{
    mem_state *m = st;
    for (size_t i = 0; i < m->n; i++) {
        cJSON *rec = cJSON_Parse(m->rec[i]);
        fn(rec, ud);
        cJSON_Delete(rec);
    }
    return (long)m->n;
}
static int mem_append(void *st, const cJSON *rec, size_t owed, vx_err *err)
{
    mem_state *m = st;
    if (m->n == 256) return vx_err_set(err, VX_ENOSPC, "insufficient_storage", "full");
    m->rec[m->n++] = cJSON_PrintUnformatted(rec);
    m->appends++;
    m->fresh_appends += owed > 0;
    return 0;
}
static int mem_compact(void *st, cJSON *const *recs, size_t n, vx_err *err)
{
    mem_state *m = st;
    for (size_t i = 0; i < m->n; i++)
        free(m->rec[i]);
    m->n = 0;
    for (size_t i = 0; i < n && i < 256; i++)
        m->rec[m->n++] = cJSON_PrintUnformatted(recs[i]);
    m->compacts++;
    return 0;
}
static long mem_size(void *st)
{
    return -1;
}
static const vx_jobstate_ops mem_ops = {.name = "memory",
                                        .open = mem_open,
                                        .close = mem_close,
                                        .replay = mem_replay,
                                        .append = mem_append,
                                        .compact = mem_compact,
                                        .size = mem_size};

static void open_jobs(fixture *fx)
{
    vx_err err = {0};
    vx_jobs_desc jd = {.store = fx->store,
                       .kinds = &table,
                       .state = g_state,
                       .hooks = {.lose_context = lose_context, .alive = alive}};
    fx->jobs = vx_jobs_open(&jd, &err);
    if (!fx->jobs) fail_msg("vx_jobs_open: %s: %s", err.code, err.message);
    if (vx_jobs_start(fx->jobs, &err)) fail_msg("vx_jobs_start: %s: %s", err.code, err.message);
}

static void open_all(fixture *fx)
{
    vx_err err = {0};
    snprintf(fx->dir, sizeof fx->dir, "/tmp/vx_test_jobs_run.XXXXXX");
    assert_non_null(mkdtemp(fx->dir));
    vx_store_desc sd = {0};
    fx->store = vx_store_open(fx->dir, &sd, &err);
    assert_non_null(fx->store);
    const char *obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    vx_upload *u = vx_upload_begin(fx->store, &err);
    assert_non_null(u);
    assert_int_equal(vx_upload_write(u, obj, strlen(obj), &err), 0);
    assert_int_equal(vx_upload_finish(u, fx->mesh, &err), 0);
    cJSON *meta = cJSON_CreateObject();
    int existed = 0;
    assert_int_equal(vx_store_mesh_commit(fx->store, u, fx->mesh, "obj", meta, &existed, &err), 0);
    cJSON_Delete(meta);
    open_jobs(fx);
}

static void close_all(fixture *fx)
{
    vx_jobs_free(fx->jobs);
    vx_store_close(fx->store);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf %s", fx->dir);
    assert_int_equal(system(cmd), 0);
}

/* Submits a job and waits until it has finished; returns its JSON. */
static cJSON *run(fixture *fx)
{
    vx_err err = {0};
    cJSON *j = vx_jobs_submit(fx->jobs, fx->mesh, "two_outputs", NULL, &err);
    if (!j) fail_msg("submit: %s: %s", err.code, err.message);
    char id[33];
    snprintf(id, sizeof id, "%s", cJSON_GetStringValue(cJSON_GetObjectItem(j, "id")));
    cJSON_Delete(j);
    for (int i = 0; i < 3000; i++) {
        int terminal = 0;
        j = vx_jobs_get(fx->jobs, id, &terminal, &err);
        assert_non_null(j);
        if (terminal) return j;
        cJSON_Delete(j);
        usleep(10000);
    }
    fail_msg("job %s did not finish", id);
    return NULL;
}

static void read_output(fixture *fx, const char *id, const char *name, char *buf, size_t n)
{
    char path[4096], ctype[64], fname[128];
    vx_err err = {0};
    if (vx_jobs_output(fx->jobs, id, name, path, sizeof path, ctype, fname, &err))
        fail_msg("output %s: %s: %s", name, err.code, err.message);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    size_t got = fread(buf, 1, n - 1, f);
    buf[got] = 0;
    fclose(f);
}

static void test_two_paths_valid_together(void **state)
{
    fixture fx;
    open_all(&fx);
    cJSON *j = run(&fx);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(j, "state")), "succeeded");
    const char *id = cJSON_GetStringValue(cJSON_GetObjectItem(j, "id"));
    char a[32], b[32];
    read_output(&fx, id, "a", a, sizeof a);
    read_output(&fx, id, "b", b, sizeof b);
    assert_string_equal(a, "first");
    assert_string_equal(b, "second");
    cJSON_Delete(j);
    assert_true(__atomic_load_n(&g_alive, __ATOMIC_RELAXED) >= 1);
    close_all(&fx);
}

static void test_retry_stats_once(void **state)
{
    fixture fx;
    open_all(&fx);
    g_lose = 1;
    cJSON *j = run(&fx);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(j, "state")), "succeeded");
    const cJSON *st = cJSON_GetObjectItem(j, "stats");
    assert_int_equal(
        (int)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(st, "context_rebuilds")), 1);
    int n = 0;
    const cJSON *it;
    cJSON_ArrayForEach(it, st) n += strcmp(it->string, "gl_stat") == 0;
    assert_int_equal(n, 1);
    cJSON_Delete(j);
    close_all(&fx);
}

/* The job state goes through the backend in the desc: every change is
 * appended there (none to a local journal), stop compacts, and a reopen
 * replays the finished job from it. */
static void test_state_backend(void **state)
{
    fixture fx;
    g_state = &mem_ops;
    open_all(&fx);
    assert_int_equal(g_mem.opened, 1);
    cJSON *j = run(&fx);
    char id[33];
    snprintf(id, sizeof id, "%s", cJSON_GetStringValue(cJSON_GetObjectItem(j, "id")));
    cJSON_Delete(j);
    assert_true(g_mem.appends >= 3);          /* queued, running, succeeded */
    assert_int_equal(g_mem.fresh_appends, 1); /* the queued record only */
    char path[128];
    struct stat sb;
    snprintf(path, sizeof path, "%s/journal.log", fx.dir);
    assert_int_equal(stat(path, &sb), -1);
    vx_jobs_free(fx.jobs);
    assert_true(g_mem.compacts >= 1);
    open_jobs(&fx);
    int terminal = 0;
    vx_err err = {0};
    j = vx_jobs_get(fx.jobs, id, &terminal, &err);
    assert_non_null(j);
    assert_int_equal(terminal, 1);
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(j, "state")), "succeeded");
    cJSON_Delete(j);
    close_all(&fx);
    mem_compact(&g_mem, NULL, 0, &err);
    g_state = NULL;
}

static const char *state_of(fixture *fx, const char *id, const char **code)
{
    static char st[16], cd[64];
    vx_err err = {0};
    int terminal = 0;
    cJSON *j = vx_jobs_get(fx->jobs, id, &terminal, &err);
    if (!j) fail_msg("get %s: %s", id, err.code);
    snprintf(st, sizeof st, "%s", cJSON_GetStringValue(cJSON_GetObjectItem(j, "state")));
    const cJSON *e = cJSON_GetObjectItem(j, "error");
    snprintf(cd, sizeof cd, "%s",
             cJSON_IsObject(e) ? cJSON_GetStringValue(cJSON_GetObjectItem(e, "code")) : "");
    cJSON_Delete(j);
    if (code) *code = cd;
    return st;
}

/* A running job's cancel is journaled before it is acknowledged; at a
 * start, an unfinished job whose cancel was acknowledged is canceled, and
 * one the daemon died during (its journal says running) for the third
 * time fails `interrupted` instead of running again (a job that crashes
 * the daemon would at every start); fewer times, it runs again. */
static void test_restart_ends(void **state)
{
    fixture fx;
    vx_err err = {0};
    g_state = &mem_ops;
    g_release = 0;
    open_all(&fx);
    cJSON *j = vx_jobs_submit(fx.jobs, fx.mesh, "waits", NULL, &err);
    assert_non_null(j);
    char id[33];
    snprintf(id, sizeof id, "%s", cJSON_GetStringValue(cJSON_GetObjectItem(j, "id")));
    cJSON_Delete(j);
    for (int i = 0; i < 3000 && strcmp(state_of(&fx, id, NULL), "running"); i++)
        usleep(1000);
    assert_string_equal(state_of(&fx, id, NULL), "running");
    size_t before = g_mem.n;
    int was_running = 0;
    j = vx_jobs_cancel(fx.jobs, id, &was_running, &err);
    assert_non_null(j);
    cJSON_Delete(j);
    assert_int_equal(was_running, 1);
    int journaled = 0;
    for (size_t i = before; i < g_mem.n; i++)
        journaled |= strstr(g_mem.rec[i], id) &&
                     strstr(g_mem.rec[i], "\"cancel_requested\":true") &&
                     strstr(g_mem.rec[i], "\"running\"");
    assert_true(journaled);
    vx_jobs_free(fx.jobs);

    /* What a daemon killed during three jobs leaves: running snapshots. */
    mem_compact(&g_mem, NULL, 0, &err);
    const char *ids[3] = {"0123456789abcdef0123456789abcde1", "0123456789abcdef0123456789abcde2",
                          "0123456789abcdef0123456789abcde3"};
    const char *extra[3] = {"\"cancel_requested\":true", "\"interruptions\":2",
                            "\"interruptions\":1"};
    for (int i = 0; i < 3; i++) {
        char rec[1024];
        snprintf(rec, sizeof rec,
                 "{\"job\":{\"id\":\"%s\",\"kind\":\"two_outputs\",\"mesh\":\"%s\","
                 "\"state\":\"running\",\"seq\":3,\"attempts\":3,\"params\":{},%s,"
                 "\"created\":\"2026-12-05T00:00:00.000Z\"}}",
                 ids[i], fx.mesh, extra[i]);
        g_mem.rec[g_mem.n++] = strdup(rec);
    }
    open_jobs(&fx);
    const char *code;
    assert_string_equal(state_of(&fx, ids[0], &code), "canceled");
    assert_string_equal(code, "canceled");
    assert_string_equal(state_of(&fx, ids[1], &code), "failed");
    assert_string_equal(code, "interrupted");
    for (int i = 0; i < 3000 && strcmp(state_of(&fx, ids[2], NULL), "succeeded"); i++)
        usleep(1000);
    assert_string_equal(state_of(&fx, ids[2], NULL), "succeeded");
    close_all(&fx);
    mem_compact(&g_mem, NULL, 0, &err);
    g_state = NULL;
}

/* Job ids increase, also many in one millisecond: the API promises that
 * they sort in creation order (a list after the newest id seen missed a
 * job made in the same millisecond with a smaller random part). */
static void test_ids_increase(void **state)
{
    (void)state;
    char prev[33] = "", id[33];
    int same_ms = 0;
    for (int i = 0; i < 100000; i++) {
        jobs_new_id(id);
        assert_true(vx_jobs_valid_id(id));
        if (prev[0]) {
            if (strcmp(prev, id) >= 0) fail_msg("id %d: %s after %s", i, id, prev);
            same_ms += !strncmp(prev, id, 12);
        }
        memcpy(prev, id, sizeof id);
    }
    printf("  %d of 100000 ids in the millisecond of the one before\n", same_ms);
    assert_true(same_ms > 1000); /* what the test is about happened */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ids_increase),     cmocka_unit_test(test_two_paths_valid_together),
        cmocka_unit_test(test_retry_stats_once), cmocka_unit_test(test_state_backend),
        cmocka_unit_test(test_restart_ends),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
