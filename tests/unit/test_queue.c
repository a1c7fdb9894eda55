/* Bounded queue: order, capacity, force, remove, timeouts, close. */
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "jobs/queue.h"
#include "util/fsutil.h"

static void test_fifo_and_capacity(void **state)
{
    vx_queue *q = vx_queue_new(3);
    int a = 1, b = 2, c = 3, d = 4;
    assert_int_equal(vx_queue_push(q, &a, 0), 0);
    assert_int_equal(vx_queue_push(q, &b, 0), 0);
    assert_int_equal(vx_queue_push(q, &c, 0), 0);
    assert_int_equal(vx_queue_push(q, &d, 0), -1); /* full */
    assert_int_equal(vx_queue_depth(q), 3);
    assert_int_equal(vx_queue_push(q, &d, 1), 0); /* replayed jobs may exceed it */
    assert_ptr_equal(vx_queue_pop(q, 0), &a);
    assert_ptr_equal(vx_queue_pop(q, 0), &b);
    assert_ptr_equal(vx_queue_pop(q, 0), &c);
    assert_ptr_equal(vx_queue_pop(q, 0), &d);
    assert_null(vx_queue_pop(q, 0));
    vx_queue_free(q);
}

static void test_grow_and_remove(void **state)
{
    vx_queue *q = vx_queue_new(0);
    int v[100];
    for (int i = 0; i < 100; i++)
        assert_int_equal(vx_queue_push(q, &v[i], 0), 0);
    assert_int_equal(vx_queue_remove(q, &v[50]), 1);
    assert_int_equal(vx_queue_remove(q, &v[50]), 0);
    for (int i = 0; i < 100; i++) {
        if (i == 50) continue;
        assert_ptr_equal(vx_queue_pop(q, 0), &v[i]);
    }
    assert_int_equal(vx_queue_depth(q), 0);
    vx_queue_free(q);
}

static void test_timeout(void **state)
{
    vx_queue *q = vx_queue_new(1);
    double t = vx_mono();
    assert_null(vx_queue_pop(q, 0.2));
    double dt = vx_mono() - t;
    assert_true(dt >= 0.19 && dt < 2.0);
    vx_queue_free(q);
}

static void *producer(void *arg)
{
    static int item = 7;
    struct timespec ts = {0, 50 * 1000 * 1000};
    nanosleep(&ts, NULL);
    vx_queue_push(arg, &item, 0);
    return NULL;
}

static void test_blocking_pop_and_close(void **state)
{
    vx_queue *q = vx_queue_new(1);
    pthread_t t;
    pthread_create(&t, NULL, producer, q);
    int *got = vx_queue_pop(q, -1);
    assert_non_null(got);
    assert_int_equal(*got, 7);
    pthread_join(t, NULL);
    vx_queue_close(q);
    assert_null(vx_queue_pop(q, -1)); /* closed and empty: does not block */
    int x;
    assert_int_equal(vx_queue_push(q, &x, 1), -1);
    vx_queue_free(q);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fifo_and_capacity),
        cmocka_unit_test(test_grow_and_remove),
        cmocka_unit_test(test_timeout),
        cmocka_unit_test(test_blocking_pop_and_close),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
