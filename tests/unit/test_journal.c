/* Journal: append + replay in order, torn tail cut, torn writes cut back,
 * CRC framing, salvage of glued records, compaction. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
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
    const cJSON *v = cJSON_GetObjectItem(rec, "v");
    s->values[s->n++] = cJSON_IsNumber(v) ? v->valueint : -1;
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
    assert_int_equal(vx_journal_append(j, r, 0, &err), 0);
    cJSON_Delete(r);
}

static void test_append_replay(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/a.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    assert_non_null(j);
    for (int i = 0; i < 10; i++)
        append_v(j, i);
    vx_journal_close(j);
    j = vx_journal_open(path, &err);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), 10);
    for (int i = 0; i < 10; i++)
        assert_int_equal(s.values[i], i);
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
    for (int i = 0; i < 20; i++)
        append_v(j, i);
    long before = vx_journal_size(j);
    cJSON *recs[2];
    for (int i = 0; i < 2; i++) {
        recs[i] = cJSON_CreateObject();
        cJSON_AddNumberToObject(recs[i], "v", 100 + i);
    }
    assert_int_equal(vx_journal_compact(j, recs, 2, &err), 0);
    assert_true(vx_journal_size(j) < before);
    append_v(j, 7); /* appends go to the new file */
    for (int i = 0; i < 2; i++)
        cJSON_Delete(recs[i]);
    vx_journal_close(j);
    j = vx_journal_open(path, &err);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), 3);
    assert_int_equal(s.values[0], 100);
    assert_int_equal(s.values[1], 101);
    assert_int_equal(s.values[2], 7);
    vx_journal_close(j);
}

/* Replays the journal at path afresh: n records, with these values of v. */
static void expect_replay(const char *path, int n, ...)
{
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    assert_non_null(j);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), n);
    va_list ap;
    va_start(ap, n);
    for (int i = 0; i < n; i++)
        assert_int_equal(s.values[i], va_arg(ap, int));
    va_end(ap);
    vx_journal_close(j);
}

static long file_size(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 ? (long)st.st_size : -1;
}

static void append_raw(const char *path, const char *text)
{
    FILE *f = fopen(path, "a");
    fputs(text, f);
    fclose(f);
}

/* A crash in the middle of a write leaves a torn last line: replay cuts it
 * off, so the next record starts on a line of its own. */
static void test_torn_tail_is_cut(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/d.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    append_v(j, 1);
    append_v(j, 2);
    vx_journal_close(j);
    long good = file_size(path);
    append_raw(path, "#0badf00d {\"v\":");
    j = vx_journal_open(path, &err);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), 2);
    assert_int_equal(file_size(path), good);
    append_v(j, 3);
    vx_journal_close(j);
    expect_replay(path, 3, 1, 2, 3);
}

/* Whether a file named path.damaged-* exists (and its size into *n). */
static int damaged_copy(const char *path, long *n)
{
    char pat[400];
    snprintf(pat, sizeof pat, "%s.damaged-", path);
    const char *slash = strrchr(pat, '/');
    DIR *d = opendir(dir);
    struct dirent *e;
    int found = 0;
    while (d && (e = readdir(d)))
        if (!strncmp(e->d_name, slash + 1, strlen(slash + 1))) {
            char full[700];
            snprintf(full, sizeof full, "%s/%s", dir, e->d_name);
            *n = file_size(full);
            found = 1;
        }
    if (d) closedir(d);
    return found;
}

/* Damage to acknowledged records (a record whose CRC fails, a tail of
 * zeros where records were) is not a torn write: the good records are
 * replayed and the journal as found is kept beside it (path.damaged-T)
 * before the cut; a torn write alone keeps no copy. */
static void test_damage_kept(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/damage.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    append_v(j, 1);
    append_v(j, 2);
    vx_journal_close(j);
    long n = 0;
    assert_false(damaged_copy(path, &n));
    append_raw(path, "#0badf00d {\"v\":3}\n");
    FILE *f = fopen(path, "a");
    for (int i = 0; i < 300; i++)
        fputc(0, f);
    fclose(f);
    long whole = file_size(path);
    j = vx_journal_open(path, &err);
    seen s = {0};
    assert_int_equal(vx_journal_replay(j, collect, &s, &err), 2);
    vx_journal_close(j);
    assert_true(damaged_copy(path, &n));
    assert_int_equal(n, whole);
}

/* A write that fails part-way (here the file-size limit, as ENOSPC would)
 * leaves nothing behind: the record acknowledged after it survives. */
static void test_failed_write_is_cut_back(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/e.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    append_v(j, 1);
    long good = file_size(path);
    struct rlimit old, lim;
    getrlimit(RLIMIT_FSIZE, &old);
    signal(SIGXFSZ, SIG_IGN);
    lim = old;
    lim.rlim_cur = (rlim_t)good + 8; /* room for 8 bytes of the next line */
    assert_int_equal(setrlimit(RLIMIT_FSIZE, &lim), 0);
    cJSON *r = cJSON_CreateObject();
    cJSON_AddNumberToObject(r, "v", 2);
    cJSON_AddStringToObject(r, "pad", "a record longer than the eight bytes that fit");
    assert_int_equal(vx_journal_append(j, r, 0, &err), -1);
    cJSON_Delete(r);
    assert_int_equal(setrlimit(RLIMIT_FSIZE, &old), 0);
    assert_int_equal(file_size(path), good);
    append_v(j, 3); /* acknowledged after the failure */
    vx_journal_close(j);
    expect_replay(path, 2, 1, 3);
}

/* Rewrites the file at path with one byte changed: the one at offset off
 * from the first occurrence of needle. */
static void set_byte(const char *path, const char *needle, size_t off, char c)
{
    vx_err err;
    char *text = vx_read_file(path, 1 << 20, NULL, &err);
    assert_non_null(text);
    char *at = strstr(text, needle);
    assert_non_null(at);
    at[off] = c;
    FILE *f = fopen(path, "w");
    fputs(text, f);
    fclose(f);
    free(text);
}

/* A record whose bytes changed fails its CRC and is skipped; its
 * neighbours are read. */
static void test_crc_mismatch_skipped(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/f.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    for (int i = 1; i <= 3; i++)
        append_v(j, i);
    vx_journal_close(j);
    set_byte(path, "\"v\":2}", 4, '5'); /* still valid JSON, wrong CRC */
    expect_replay(path, 2, 1, 3);
}

/* The same for job records, which the unframed salvage looks for: a
 * framed job record whose CRC fails is not read as an unframed one (a
 * resolution 64 flipped to 94 on disk used to run as 94). */
static void test_crc_mismatch_job_skipped(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/h.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    for (int i = 1; i <= 3; i++) {
        cJSON *r = cJSON_Parse("{\"job\":{\"id\":\"x\",\"params\":{\"resolution\":64}}}");
        cJSON_AddNumberToObject(r, "v", i);
        assert_int_equal(vx_journal_append(j, r, 0, &err), 0);
        cJSON_Delete(r);
    }
    vx_journal_close(j);
    /* the second line's 64 becomes 94: still valid JSON, wrong CRC */
    set_byte(path, "\"resolution\":64}},\"v\":2}", 13, '9');
    expect_replay(path, 2, 1, 3);
}

/* Journals written before failed writes were cut back can hold a fragment
 * with a good record glued on: replay salvages the record, framed or not. */
static void test_glued_record_salvaged(void **state)
{
    char path[300];
    snprintf(path, sizeof path, "%s/g.log", dir);
    vx_err err;
    vx_journal *j = vx_journal_open(path, &err);
    append_v(j, 1);
    vx_journal_close(j);
    append_raw(path, "#1234abcd {\"v\":9,\"pad\":\"tor");
    j = vx_journal_open(path, &err);
    /* no replay: the fragment stays, the next append is glued onto it */
    append_v(j, 2);
    vx_journal_close(j);
    append_raw(path, "{\"job\":{\"i\":\"tor{\"job\":{\"id\":\"x\"}}\n");
    expect_replay(path, 3, 1, 2, -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_append_replay),
        cmocka_unit_test(test_torn_tail_and_garbage),
        cmocka_unit_test(test_compact),
        cmocka_unit_test(test_torn_tail_is_cut),
        cmocka_unit_test(test_damage_kept),
        cmocka_unit_test(test_failed_write_is_cut_back),
        cmocka_unit_test(test_crc_mismatch_skipped),
        cmocka_unit_test(test_crc_mismatch_job_skipped),
        cmocka_unit_test(test_glued_record_salvaged),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
