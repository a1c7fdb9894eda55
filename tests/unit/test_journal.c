/* Journal: append + replay in order, torn tail ignored, compaction. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "jobs/journal.h"
#include "util/fsutil.h"

typedef struct seen {
    int n;
    int values[64];
} seen;

static void collect(const cJSON *rec, void *ud)
{
    seen *s = ud;
    s->values[s->n++] = (int)cJSON_GetNumberValue(cJSON_GetObjectItem(rec, "v"));
}

static char dir[256];

static int setup(void **state)
{
    snprintf(dir, sizeof dir, "/tmp/vx-journal-XXXXXX");
    return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
    vx_remove_tree(dir);
    return 0;
}

static void append_v(vx_journal *j, int v)
{
    cJSON *r = cJSON_CreateObject();
    cJSON_AddNumberToObject(r, "v", v);
    vx_err err;
    assert_int_equal(vx_journal_append(j, r, &err), 0);
    cJSON_Delete(r);
}

static void test_append_replay(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/a.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    assert_non_null(j);
    for (int i = 0; i < 10; i++) append_v(j, i);
    vx_journal_close(j);
    j = vx_journal_open(path, &err);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), 10);
    for (int i = 0; i < 10; i++) assert_int_equal(s.values[i], i);
    vx_journal_close(j);
}

static void test_torn_tail_and_garbage(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/b.log", dir);
    FILE *f = fopen(path, "w");
    fputs("{\"v\":1}\nnot json\n{\"v\":2}\n{\"v\":3", f); /* crash mid-record */
    fclose(f);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), 2);
    assert_int_equal(s.values[0], 1);
    assert_int_equal(s.values[1], 2);
    vx_journal_close(j);
}

static void test_compact(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/c.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    for (int i = 0; i < 20; i++) append_v(j, i);
    long before = vx_journal_size(j);
    cJSON *recs[2];
    for (int i = 0; i < 2; i++) {
        recs[i] = cJSON_CreateObject();
        cJSON_AddNumberToObject(recs[i], "v", 100 + i);
    }
    assert_int_equal(vx_journal_compact(j, recs, 2, &err), 0);
    assert_true(vx_journal_size(j) < before);
    append_v(j, 7); /* appends go to the new file */
    for (int i = 0; i < 2; i++) cJSON_Delete(recs[i]);
    vx_journal_close(j);
    j = vx_journal_open(path, &err);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), 3);
    assert_int_equal(s.values[0], 100);
    assert_int_equal(s.values[1], 101);
    assert_int_equal(s.values[2], 7);
    vx_journal_close(j);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_append_replay),
        cmocka_unit_test(test_torn_tail_and_garbage),
        cmocka_unit_test(test_compact),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
