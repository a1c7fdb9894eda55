/* util: the clock, the parallel-for, the vec3 set, exact JSON numbers and
 * big buffers kept between jobs. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <pthread.h>
#include <stdatomic.h>
#include <string.h>
#include <time.h>

#include "util/bigmem.h"
#include "util/clock.h"
#include "util/err.h"
#include "util/fsutil.h"
#include "util/json.h"
#include "util/par.h"
#include "util/vec3.h"

/* Error messages are UTF-8 whatever they quote (issue #13: a UTF-16 OBJ
 * echoed 0xFE 0xFF into the JSON body). */
static void test_err_utf8(void **state)
{
    (void)state;
    vx_err e;
    vx_err_set(&e, VX_EINVAL, "obj_junk", "line 1: unknown statement '%s'", "\xfe\xff\x00v");
    assert_string_equal(e.message, "line 1: unknown statement '?\?'");
    vx_err_set(&e, VX_EINVAL, "x", "%s", "caf\xc3\xa9 \xe2\x82\xac ok\tx\xc0\xafy\xed\xa0\x80z");
    assert_string_equal(e.message, "caf\xc3\xa9 \xe2\x82\xac ok?x??y???z");
    /* A character cut by the buffer's end is replaced, never half kept. */
    char big[600];
    memset(big, 'a', sizeof big);
    for (size_t i = 500; i + 1 < sizeof big; i += 2)
        big[i] = '\xc3', big[i + 1] = '\xa9';
    big[sizeof big - 1] = 0;
    vx_err_set(&e, VX_EINVAL, "x", "%s", big);
    size_t n = strlen(e.message);
    assert_int_equal(n, sizeof e.message - 1);
    assert_true(e.message[n - 1] == '?' || (unsigned char)e.message[n - 1] == 0xa9);
    for (size_t i = 0; i < n; i++)
        if ((unsigned char)e.message[i] == 0xc3)
            assert_true((unsigned char)e.message[i + 1] == 0xa9);
}

static void test_clock(void **state)
{
    (void)state;
    double m0 = vx_mono(), ms0 = vx_mono_ms(), w = vx_now();
    assert_true(w > 1.6e9); /* after 2020 */
    assert_true(ms0 >= m0 * 1e3 - 1 && ms0 <= m0 * 1e3 + 1000);
    struct timespec ts = {0, 20 * 1000 * 1000};
    nanosleep(&ts, NULL);
    assert_true(vx_mono() - m0 >= 0.019);
    assert_true(vx_mono_ms() - ms0 >= 19);
}

typedef struct par_ud {
    atomic_int seen[1000];
    atomic_int calls;
    pthread_t caller;
    atomic_int caller_wrong; /* t == 0 on another thread, or t != 0 on the caller */
    int stop_at;
} par_ud;

static int count_item(int i, int t, void *arg)
{
    par_ud *u = arg;
    atomic_fetch_add(&u->seen[i], 1);
    atomic_fetch_add(&u->calls, 1);
    if ((t == 0) != (pthread_equal(pthread_self(), u->caller) != 0))
        atomic_fetch_add(&u->caller_wrong, 1);
    if (t < 0 || t >= VX_PAR_MAX) atomic_fetch_add(&u->caller_wrong, 1);
    return u->stop_at >= 0 && i == u->stop_at ? 7 : 0;
}

static void test_par_for(void **state)
{
    (void)state;
    static par_ud u;
    for (int nt = 0; nt <= 20; nt += 5) {
        memset(&u, 0, sizeof u);
        u.caller = pthread_self();
        u.stop_at = -1;
        assert_int_equal(vx_par_for(1000, nt, count_item, &u), 0);
        for (int i = 0; i < 1000; i++)
            assert_int_equal(atomic_load(&u.seen[i]), 1);
        assert_int_equal(atomic_load(&u.caller_wrong), 0);
    }
    /* A nonzero result stops the items not yet started and is returned. */
    memset(&u, 0, sizeof u);
    u.caller = pthread_self();
    u.stop_at = 10;
    assert_int_equal(vx_par_for(1000, 4, count_item, &u), 7);
    assert_int_equal(atomic_load(&u.seen[10]), 1);
    assert_true(atomic_load(&u.calls) < 1000);
    /* No items: fn is never called. */
    memset(&u, 0, sizeof u);
    assert_int_equal(vx_par_for(0, 4, count_item, &u), 0);
    assert_int_equal(atomic_load(&u.calls), 0);
}

static void *count_thread(void *arg)
{
    atomic_fetch_add((atomic_int *)arg, 1);
    return NULL;
}

static void test_par_run(void **state)
{
    (void)state;
    int want[][2] = {{-3, 1}, {0, 1}, {1, 1}, {4, 4}, {16, 16}, {99, VX_PAR_MAX}};
    for (size_t k = 0; k < sizeof want / sizeof *want; k++) {
        atomic_int n;
        atomic_init(&n, 0);
        int ran = vx_par_run(want[k][0], count_thread, &n);
        assert_int_equal(ran, atomic_load(&n)); /* all joined */
        assert_int_equal(ran, want[k][1]);
    }
}

static void test_vec3(void **state)
{
    (void)state;
    double a[3] = {1, 2, 3}, b[3] = {-4, 0.5, 2}, o[3];
    vx_v3_add(a, b, o);
    assert_true(o[0] == -3 && o[1] == 2.5 && o[2] == 5);
    vx_v3_sub(a, b, o);
    assert_true(o[0] == 5 && o[1] == 1.5 && o[2] == 1);
    vx_v3_scale(a, 2, o);
    assert_true(o[0] == 2 && o[1] == 4 && o[2] == 6);
    vx_v3_mid(a, b, o);
    assert_true(o[0] == -1.5 && o[1] == 1.25 && o[2] == 2.5);
    assert_true(vx_v3_dot(a, b) == -4 + 1 + 6);
    vx_v3_cross(a, b, o);
    assert_true(o[0] == 2 * 2 - 3 * 0.5 && o[1] == 3 * -4 - 1 * 2 && o[2] == 1 * 0.5 - 2 * -4);
    assert_true(vx_v3_dot(o, a) == 0 && vx_v3_dot(o, b) == 0);
    double c[3] = {3, 0, 4};
    assert_true(vx_v3_norm(c) == 5);
    assert_int_equal(vx_v3_unit(c), 0);
    assert_true(c[0] == 0.6 && c[1] == 0 && c[2] == 0.8);
    double z[3] = {0, 0, 0};
    assert_int_equal(vx_v3_unit(z), -1);
    assert_true(z[0] == 0 && z[1] == 0 && z[2] == 0);
    /* The output may alias an input. */
    vx_v3_sub(a, a, a);
    assert_true(a[0] == 0 && a[1] == 0 && a[2] == 0);
}

/* Every number printed reads back as the same double (cJSON's own printer
 * gave 0.3 for 0.30000000000000004 and -0.125 for -0.12500000000000003: a
 * grid origin echoed, journaled or compared for reuse was another lattice),
 * in the fewest digits; the tree printed is left as it was. */
static void test_json_exact(void **state)
{
    (void)state;
    const double v[] = {-0.12500000000000003,
                        0.30000000000000004,
                        1.0000000000000002,
                        100.00000000000001,
                        1.0000000000000001e-07,
                        0.1,
                        1.0 / 3,
                        -2.5,
                        1e300,
                        4.9406564584124654e-324,
                        123456.78901234567,
                        42};
    const size_t n = sizeof v / sizeof v[0];
    cJSON *doc = cJSON_CreateObject(), *arr = cJSON_AddArrayToObject(doc, "a");
    for (size_t i = 0; i < n; i++)
        cJSON_AddItemToArray(arr, cJSON_CreateNumber(v[i]));
    cJSON_AddItemToObject(cJSON_AddObjectToObject(doc, "o"), "x", cJSON_CreateNumber(v[0]));
    for (int formatted = 0; formatted <= 1; formatted++) {
        char *text = vx_json_print(doc, formatted);
        assert_non_null(text);
        cJSON *back = cJSON_Parse(text);
        assert_non_null(back);
        const cJSON *b = cJSON_GetObjectItem(back, "a");
        assert_int_equal(cJSON_GetArraySize(b), (int)n);
        for (size_t i = 0; i < n; i++)
            assert_true(cJSON_GetArrayItem(b, (int)i)->valuedouble == v[i]);
        assert_true(cJSON_GetObjectItem(cJSON_GetObjectItem(back, "o"), "x")->valuedouble == v[0]);
        cJSON_Delete(back);
        cJSON_free(text);
    }
    char *text = vx_json_print(arr, 0);
    assert_non_null(strstr(text, "0.1,"));
    assert_non_null(strstr(text, "0.30000000000000004,"));
    assert_non_null(strstr(text, ",42]"));
    cJSON_free(text);
    assert_true(cJSON_IsNumber(cJSON_GetArrayItem(arr, 0))); /* not changed in place */
    cJSON_Delete(doc);
}

static int all_zero(const unsigned char *p, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (p[i]) return 0;
    return 1;
}

/* Freed mappings are kept up to the limit and handed out again zeroed, a
 * long one's head to a buffer 4 MiB or more shorter. */
static void test_bigmem_keep(void **state)
{
    (void)state;
    const size_t MB = 1 << 20;
    size_t m1, m2, m3;
    /* small buffers come from calloc, never kept */
    unsigned char *s = vx_bigmem_alloc(1000, &m1);
    assert_non_null(s);
    assert_int_equal(m1, 0);
    vx_bigmem_free(s, m1);
    vx_bigmem_keep(0);
    unsigned char *a = vx_bigmem_alloc(10 * MB + 1, &m1);
    assert_non_null(a);
    assert_int_equal(m1, 12 * MB); /* whole huge pages */
    memset(a, 0xab, 10 * MB + 1);
    vx_bigmem_free(a, m1);
    assert_int_equal(vx_bigmem_kept(), 0); /* the default keeps nothing */

    vx_bigmem_keep(40 * MB);
    a = vx_bigmem_alloc(10 * MB, &m1);
    memset(a, 0xab, 10 * MB);
    vx_bigmem_free(a, m1);
    assert_int_equal(vx_bigmem_kept(), 10 * MB);
    unsigned char *b = vx_bigmem_alloc(9 * MB, &m2); /* fits: the same, cleared */
    assert_ptr_equal(b, a);
    assert_int_equal(m2, 10 * MB);
    assert_true(all_zero(b, 9 * MB));
    assert_int_equal(vx_bigmem_kept(), 0);
    vx_bigmem_free(b, m2);
    unsigned char *c = vx_bigmem_alloc(4 * MB, &m3); /* 6 MB over: its head, cleared */
    assert_ptr_equal(c, a);
    assert_int_equal(m3, 4 * MB);
    assert_true(all_zero(c, 4 * MB));
    assert_int_equal(vx_bigmem_kept(), 6 * MB);
    memset(c, 0xab, 4 * MB);
    unsigned char *d = vx_bigmem_alloc(30 * MB, &m2); /* bigger than any kept */
    assert_true(all_zero(d, 30 * MB));
    vx_bigmem_free(c, m3); /* joined to its tail again */
    assert_int_equal(vx_bigmem_kept(), 10 * MB);
    c = vx_bigmem_alloc(10 * MB, &m3);
    assert_ptr_equal(c, a);
    assert_int_equal(m3, 10 * MB);
    assert_true(all_zero(c, 10 * MB));
    vx_bigmem_free(c, m3);
    unsigned char *x = vx_bigmem_alloc(8 * MB, &m3); /* 2 MB over the 10: all of it */
    assert_ptr_equal(x, a);
    assert_int_equal(m3, 10 * MB);
    vx_bigmem_free(x, m3);
    vx_bigmem_free(d, m2); /* 40: kept (one piece where the two lie side by side) */
    assert_int_equal(vx_bigmem_kept(), 40 * MB);
    x = vx_bigmem_alloc(12 * MB, &m3); /* a head of the kept */
    assert_int_equal(m3, 12 * MB);
    assert_int_equal(vx_bigmem_kept(), 28 * MB);
    unsigned char *z = vx_bigmem_alloc(30 * MB, &m2); /* more than any kept: mapped */
    vx_bigmem_free(x, m3);
    assert_int_equal(vx_bigmem_kept(), 40 * MB);
    vx_bigmem_free(z, m2); /* 70 > 40: the smallest kept ones leave, z stays */
    assert_int_equal(vx_bigmem_kept(), 30 * MB);
    z = vx_bigmem_alloc(30 * MB, &m2);
    assert_int_equal(m2, 30 * MB);
    assert_int_equal(vx_bigmem_kept(), 0);
    vx_bigmem_free(z, m2);
    size_t m4;
    unsigned char *e = vx_bigmem_alloc(50 * MB, &m4); /* over the limit: unmapped */
    vx_bigmem_free(e, m4);
    assert_int_equal(vx_bigmem_kept(), 30 * MB);
    vx_bigmem_keep(15 * MB); /* lowered: unmapped down to it */
    assert_true(vx_bigmem_kept() <= 15 * MB);
    vx_bigmem_keep(0);
    assert_int_equal(vx_bigmem_kept(), 0);

    /* scratch: kept mappings reused as they were left (not touched again),
     * a fresh one zero as any new mapping; small ones from malloc */
    vx_bigmem_keep(40 * MB);
    unsigned char *f = vx_bigmem_scratch(10 * MB, &m1);
    assert_non_null(f);
    assert_int_equal(m1, 10 * MB);
    assert_true(all_zero(f, 10 * MB));
    memset(f, 0xcd, 10 * MB);
    vx_bigmem_free(f, m1);
    unsigned char *g = vx_bigmem_scratch(8 * MB, &m2);
    assert_ptr_equal(g, f);
    assert_int_equal(g[0], 0xcd);
    assert_int_equal(g[8 * MB - 1], 0xcd);
    vx_bigmem_free(g, m2);
    unsigned char *h = vx_bigmem_alloc(8 * MB, &m2); /* alloc clears it */
    assert_ptr_equal(h, f);
    assert_true(all_zero(h, 8 * MB));
    vx_bigmem_free(h, m2);
    unsigned char *i = vx_bigmem_scratch(1000, &m3);
    assert_non_null(i);
    assert_int_equal(m3, 0);
    vx_bigmem_free(i, m3);
    vx_bigmem_keep(0);

    /* pretouched: mapped and written at once, up to the room kept, then
     * handed out a head at a time and whole again once all come back */
    assert_int_equal(vx_bigmem_pretouch(100 * MB), 0); /* nothing kept: no room */
    vx_bigmem_keep(40 * MB);
    assert_int_equal(vx_bigmem_pretouch(100 * MB), 40 * MB);
    assert_int_equal(vx_bigmem_kept(), 40 * MB);
    assert_int_equal(vx_bigmem_pretouch(100 * MB), 0); /* full */
    unsigned char *p1 = vx_bigmem_alloc(10 * MB, &m1), *p2 = vx_bigmem_alloc(20 * MB, &m2);
    assert_int_equal(m1, 10 * MB);
    assert_int_equal(m2, 20 * MB);
    assert_ptr_equal(p2, p1 + 10 * MB);
    assert_true(all_zero(p1, 10 * MB) && all_zero(p2, 20 * MB));
    assert_int_equal(vx_bigmem_kept(), 10 * MB);
    memset(p2, 1, 20 * MB);
    vx_bigmem_free(p2, m2);
    vx_bigmem_free(p1, m1);
    unsigned char *all = vx_bigmem_alloc(40 * MB, &m3);
    assert_ptr_equal(all, p1);
    assert_int_equal(m3, 40 * MB);
    assert_true(all_zero(all, 40 * MB));
    vx_bigmem_free(all, m3);
    vx_bigmem_keep(0);
    assert_int_equal(vx_bigmem_kept(), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_err_utf8),    cmocka_unit_test(test_clock),
        cmocka_unit_test(test_par_for),     cmocka_unit_test(test_par_run),
        cmocka_unit_test(test_vec3),        cmocka_unit_test(test_json_exact),
        cmocka_unit_test(test_bigmem_keep),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
