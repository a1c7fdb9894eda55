/* Typed parameter readers: defaults, types, ranges, integers, unknown keys. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <cmocka.h>

#include "jobs/kind.h"

static void test_numbers(void **state)
{
    cJSON *p = cJSON_Parse("{\"a\": 2.5, \"s\": \"x\", \"n\": null, \"i\": 7, \"f\": 7.5, \"b\": true}");
    vx_err err;
    double d;
    long l;
    int b;
    assert_int_equal(vx_param_number(p, "a", 0, 0, 10, &d, &err), 0);
    assert_true(d == 2.5);
    assert_int_equal(vx_param_number(p, "missing", 3, 0, 10, &d, &err), 0);
    assert_true(d == 3);
    assert_int_equal(vx_param_number(p, "n", 4, 0, 10, &d, &err), 0); /* null = default */
    assert_true(d == 4);
    assert_int_equal(vx_param_number(NULL, "a", 5, 0, 10, &d, &err), 0);
    assert_true(d == 5);
    assert_int_equal(vx_param_number(p, "s", 0, 0, 10, &d, &err), -1);
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "invalid_params");
    assert_non_null(strstr(err.message, "params.s"));
    assert_int_equal(vx_param_number(p, "a", 0, 3, 10, &d, &err), -1);
    assert_non_null(strstr(err.message, "[3, 10]"));
    assert_int_equal(vx_param_int(p, "i", 0, 0, 10, &l, &err), 0);
    assert_int_equal(l, 7);
    assert_int_equal(vx_param_int(p, "f", 0, 0, 10, &l, &err), -1);
    assert_non_null(strstr(err.message, "integer"));
    assert_int_equal(vx_param_bool(p, "b", 0, &b, &err), 0);
    assert_int_equal(b, 1);
    assert_int_equal(vx_param_bool(p, "i", 0, &b, &err), -1);
    cJSON_Delete(p);
}

static void test_only_known(void **state)
{
    cJSON *p = cJSON_Parse("{\"width\": 1, \"zoom\": 2}");
    vx_err err;
    static const char *const known[] = {"width", "height", NULL};
    assert_int_equal(vx_param_only(p, known, &err), -1);
    assert_non_null(strstr(err.message, "zoom"));
    cJSON_DeleteItemFromObject(p, "zoom");
    assert_int_equal(vx_param_only(p, known, &err), 0);
    cJSON_Delete(p);
}

static void test_kind_table(void **state)
{
    assert_non_null(vx_kind_find("preview"));
    assert_null(vx_kind_find("nope"));
    assert_true(vx_kind_count() >= 1);
    for (size_t i = 0; i < vx_kind_count(); i++) {
        const vx_kind *k = vx_kind_at(i);
        assert_non_null(k->parse);
        assert_non_null(k->run_gl);
        assert_ptr_equal(vx_kind_find(k->name), k);
        /* Every kind accepts empty params and fills in its defaults. */
        vx_err err;
        cJSON *norm = k->parse(NULL, &(vx_limits){0}, &err);
        assert_non_null(norm);
        assert_true(cJSON_IsObject(norm));
        cJSON_Delete(norm);
    }
}

static void test_preview_params(void **state)
{
    const vx_kind *k = vx_kind_find("preview");
    vx_err err;
    vx_limits lim = {.max_image_pixels = 100 * 100};
    cJSON *in = cJSON_Parse("{\"width\": 100, \"height\": 100, \"azimuth\": 45}");
    cJSON *norm = k->parse(in, &lim, &err);
    assert_non_null(norm);
    assert_true(cJSON_GetNumberValue(cJSON_GetObjectItem(norm, "azimuth")) == 45);
    assert_true(cJSON_GetNumberValue(cJSON_GetObjectItem(norm, "elevation")) == 20);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(norm, "color")), 3);
    /* parse is idempotent on its own output */
    cJSON *again = k->parse(norm, &lim, &err);
    assert_true(cJSON_Compare(norm, again, 1));
    cJSON_Delete(again);
    cJSON_Delete(norm);
    cJSON_Delete(in);
    static const char *bad[] = {
        "{\"width\": 101, \"height\": 100}", /* over max_image_pixels */
        "{\"width\": 8}",                    /* under 16 */
        "{\"samples\": 3}",
        "{\"elevation\": 90}",
        "{\"color\": [1, 0]}",
        "{\"background\": [1, 0, 0, 2]}",
        "{\"fov\": \"wide\"}",
        "{\"mystery\": 1}",
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        in = cJSON_Parse(bad[i]);
        vx_err_clear(&err);
        assert_null(k->parse(in, &lim, &err));
        assert_int_equal(err.kind, VX_EUNPROC);
        assert_string_equal(err.code, "invalid_params");
        cJSON_Delete(in);
    }
}

static void test_mesh_ids(void **state)
{
    (void)state;
    char id[65];
    memset(id, 'a', 64);
    id[64] = 0;
    char buf[512];
    snprintf(buf, sizeof buf,
             "{\"m\": [\"%s\", \"%s\"], \"bad\": [\"%.63s\"], \"upper\": [\"%.63sA\"],"
             " \"s\": \"%s\", \"num\": [1]}",
             id, id, id, id, id);
    cJSON *p = cJSON_Parse(buf);
    assert_non_null(p);
    vx_err err;
    const cJSON *out;
    assert_int_equal(vx_param_mesh_ids(p, "m", 8, &out, &err), 0);
    assert_int_equal(cJSON_GetArraySize(out), 2);
    assert_int_equal(vx_param_mesh_ids(p, "absent", 8, &out, &err), 0);
    assert_null(out);
    assert_int_equal(vx_param_mesh_ids(p, "m", 1, &out, &err), -1);
    assert_non_null(strstr(err.message, "at most 1"));
    const char *bad[] = {"bad", "upper", "s", "num"};
    for (size_t i = 0; i < 4; i++) {
        assert_int_equal(vx_param_mesh_ids(p, bad[i], 8, &out, &err), -1);
        assert_string_equal(err.code, "invalid_params");
        assert_non_null(strstr(err.message, bad[i]));
    }
    cJSON_Delete(p);
}

static void test_object(void **state)
{
    (void)state;
    static const char *const known[] = {"a", NULL};
    vx_err err;
    const cJSON *p = NULL;
    assert_int_equal(vx_param_object(&p, known, &err), 0);
    assert_null(p);
    cJSON *n = cJSON_CreateNull(), *arr = cJSON_Parse("[1]"), *ok = cJSON_Parse("{\"a\": 1}"),
          *bad = cJSON_Parse("{\"b\": 1}");
    p = n;
    assert_int_equal(vx_param_object(&p, known, &err), 0);
    assert_null(p); /* JSON null is no params */
    p = ok;
    assert_int_equal(vx_param_object(&p, known, &err), 0);
    assert_ptr_equal(p, ok);
    p = arr;
    assert_int_equal(vx_param_object(&p, known, &err), -1);
    assert_non_null(strstr(err.message, "must be an object"));
    p = bad;
    assert_int_equal(vx_param_object(&p, known, &err), -1);
    assert_non_null(strstr(err.message, "params.b"));
    cJSON_Delete(n);
    cJSON_Delete(arr);
    cJSON_Delete(ok);
    cJSON_Delete(bad);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_numbers),
        cmocka_unit_test(test_only_known),
        cmocka_unit_test(test_mesh_ids),
        cmocka_unit_test(test_object),
        cmocka_unit_test(test_kind_table),
        cmocka_unit_test(test_preview_params),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
