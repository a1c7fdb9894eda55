/* Bounded queue: order, capacity, force, remove, timeouts, close. */
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "jobs/queue.h"
#include "util/clock.h"
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

static void *consumer(void *arg)
{
    struct timespec ts = {0, 50 * 1000 * 1000};
    nanosleep(&ts, NULL);
    vx_queue_pop(arg, 0);
    return NULL;
}

/* wait_below: at once when below, a timeout when not, woken by a pop or a
 * close. */
static void test_wait_below(void **state)
{
    vx_queue *q = vx_queue_new(0);
    int a = 1, b = 2;
    assert_int_equal(vx_queue_wait_below(q, 1, 0), 0);
    vx_queue_push(q, &a, 0);
    vx_queue_push(q, &b, 0);
    assert_int_equal(vx_queue_wait_below(q, 3, 0), 0);
    assert_int_equal(vx_queue_wait_below(q, 2, 0), -1);
    double t0 = vx_mono();
    assert_int_equal(vx_queue_wait_below(q, 2, 0.1), -1);
    assert_true(vx_mono() - t0 >= 0.09);
    pthread_t t;
    pthread_create(&t, NULL, consumer, q);
    assert_int_equal(vx_queue_wait_below(q, 2, -1), 0); /* the pop wakes it */
    assert_int_equal(vx_queue_depth(q), 1);
    pthread_join(t, NULL);
    vx_queue_close(q);
    assert_int_equal(vx_queue_wait_below(q, 1, -1), 0); /* closed: does not block */
    vx_queue_free(q);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fifo_and_capacity), cmocka_unit_test(test_grow_and_remove),
        cmocka_unit_test(test_timeout),           cmocka_unit_test(test_blocking_pop_and_close),
        cmocka_unit_test(test_wait_below),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
