/* util: the clock, the parallel-for and the vec3 set. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <pthread.h>
#include <stdatomic.h>
#include <string.h>
#include <time.h>

#include "util/clock.h"
#include "util/fsutil.h"
#include "util/par.h"
#include "util/vec3.h"

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

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_clock),
        cmocka_unit_test(test_par_for),
        cmocka_unit_test(test_par_run),
        cmocka_unit_test(test_vec3),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
