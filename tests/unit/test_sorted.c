/* The sorted pointer array (util/sorted.h): order, lookups, duplicates,
 * removal and paging, against a plain model. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "util/sorted.h"

typedef struct item {
    char key[16];
} item;

static const char *key_of(const void *p)
{
    return ((const item *)p)->key;
}

static void check_sorted(const vx_sorted *s)
{
    for (size_t i = 1; i < s->n; i++)
        assert_true(strcmp(key_of(s->items[i - 1]), key_of(s->items[i])) < 0);
}

static void test_empty(void **state)
{
    vx_sorted s;
    vx_sorted_init(&s, key_of);
    int found = 1;
    assert_int_equal(vx_sorted_find(&s, "a", &found), 0);
    assert_int_equal(found, 0);
    assert_null(vx_sorted_get(&s, "a"));
    assert_int_equal(vx_sorted_after(&s, NULL), 0);
    assert_int_equal(vx_sorted_after(&s, "x"), 0);
    vx_sorted_free(&s);
    vx_sorted_free(&s); /* twice is fine */
}

static void test_insert_find_remove(void **state)
{
    enum { N = 1000 };
    item *it = calloc(N, sizeof *it);
    assert_non_null(it);
    vx_sorted s;
    vx_sorted_init(&s, key_of);
    /* Inserted out of order (a permutation of 0..N-1), keys of equal width. */
    for (int i = 0; i < N; i++) {
        snprintf(it[i].key, sizeof it[i].key, "k%05d", (i * 389) % N);
        assert_int_equal(vx_sorted_insert(&s, &it[i]), 0);
    }
    assert_int_equal(s.n, N);
    check_sorted(&s);
    /* A duplicate key is refused and changes nothing. */
    item dup = {"k00042"};
    assert_int_equal(vx_sorted_insert(&s, &dup), -1);
    assert_int_equal(s.n, N);
    assert_true(vx_sorted_get(&s, "k00042") != &dup);
    for (int k = 0; k < N; k++) {
        char key[16];
        snprintf(key, sizeof key, "k%05d", k);
        int found = 0;
        size_t at = vx_sorted_find(&s, key, &found);
        assert_int_equal(found, 1);
        assert_int_equal(at, k);
        assert_string_equal(key_of(vx_sorted_get(&s, key)), key);
    }
    /* Insertion points of absent keys. */
    int found = 1;
    assert_int_equal(vx_sorted_find(&s, "a", &found), 0);
    assert_int_equal(found, 0);
    assert_int_equal(vx_sorted_find(&s, "k00010x", &found), 11);
    assert_int_equal(found, 0);
    assert_int_equal(vx_sorted_find(&s, "z", &found), N);
    /* Remove every other one. */
    for (int k = N - 1; k >= 0; k -= 2) {
        char key[16];
        snprintf(key, sizeof key, "k%05d", k);
        size_t at = vx_sorted_find(&s, key, &found);
        assert_int_equal(found, 1);
        item *got = vx_sorted_remove_at(&s, at);
        assert_string_equal(got->key, key);
        assert_null(vx_sorted_get(&s, key));
    }
    assert_int_equal(s.n, N / 2);
    check_sorted(&s);
    vx_sorted_free(&s);
    assert_int_equal(s.n, 0);
    free(it);
}

static void test_paging(void **state)
{
    item it[5] = {{"b"}, {"d"}, {"f"}, {"h"}, {"j"}};
    vx_sorted s;
    vx_sorted_init(&s, key_of);
    for (int i = 4; i >= 0; i--)
        assert_int_equal(vx_sorted_insert(&s, &it[i]), 0);
    assert_int_equal(vx_sorted_after(&s, ""), 0);
    assert_int_equal(vx_sorted_after(&s, "a"), 0);
    assert_int_equal(vx_sorted_after(&s, "b"), 1); /* present: the next one */
    assert_int_equal(vx_sorted_after(&s, "c"), 1); /* absent: the next greater */
    assert_int_equal(vx_sorted_after(&s, "j"), 5);
    assert_int_equal(vx_sorted_after(&s, "z"), 5);
    /* Walking pages of 2 visits each item once, in order. */
    const char *after = NULL;
    char seen[16] = "";
    for (;;) {
        size_t i = vx_sorted_after(&s, after);
        if (i >= s.n) break;
        for (size_t k = i; k < i + 2 && k < s.n; k++) {
            strcat(seen, key_of(s.items[k]));
            after = key_of(s.items[k]);
        }
    }
    assert_string_equal(seen, "bdfhj");
    vx_sorted_free(&s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_empty),
        cmocka_unit_test(test_insert_find_remove),
        cmocka_unit_test(test_paging),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
