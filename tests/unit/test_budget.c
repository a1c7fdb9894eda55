/* util/budget: reservations against a shared limit, from several threads. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <pthread.h>

#include "util/budget.h"

static void test_reserve(void **state)
{
    (void)state;
    vx_budget b = VX_BUDGET_INIT;
    assert_int_equal(vx_budget_reserve(&b, 60, 100), VX_BUDGET_OK);
    assert_int_equal(vx_budget_reserve(&b, 50, 100), VX_BUDGET_BUSY);
    assert_int_equal(vx_budget_used(&b), 60);
    assert_int_equal(vx_budget_reserve(&b, 40, 100), VX_BUDGET_OK);
    assert_int_equal(vx_budget_reserve(&b, 101, 100), VX_BUDGET_TOO_BIG);
    vx_budget_release(&b, 60);
    assert_int_equal(vx_budget_reserve(&b, 50, 100), VX_BUDGET_OK);
    vx_budget_release(&b, 50);
    vx_budget_release(&b, 40);
    assert_int_equal(vx_budget_used(&b), 0);
    /* 0 = no limit */
    assert_int_equal(vx_budget_reserve(&b, UINT64_MAX / 2, 0), VX_BUDGET_OK);
    vx_budget_release(&b, UINT64_MAX / 2);
    assert_int_equal(vx_budget_used(&b), 0);
}

static vx_budget shared = VX_BUDGET_INIT;
static int overflow;

static void *worker(void *arg)
{
    (void)arg;
    for (int i = 0; i < 20000; i++) {
        if (vx_budget_reserve(&shared, 30, 100) != VX_BUDGET_OK) continue;
        if (vx_budget_used(&shared) > 100) overflow = 1;
        vx_budget_release(&shared, 30);
    }
    return NULL;
}

static void test_threads(void **state)
{
    (void)state;
    pthread_t t[4];
    for (int i = 0; i < 4; i++)
        assert_int_equal(pthread_create(&t[i], NULL, worker, NULL), 0);
    for (int i = 0; i < 4; i++)
        pthread_join(t[i], NULL);
    assert_false(overflow);
    assert_int_equal(vx_budget_used(&shared), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_reserve),
        cmocka_unit_test(test_threads),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
