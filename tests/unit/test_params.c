/* Typed parameter readers: defaults, types, ranges, integers, unknown keys. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "jobs/kind.h"
#include "kinds.h"

static void test_numbers(void **state)
{
    cJSON *p =
        cJSON_Parse("{\"a\": 2.5, \"s\": \"x\", \"n\": null, \"i\": 7, \"f\": 7.5, \"b\": true}");
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

/* The fuzz_params oracle on one input: parse accepts, the normalised
 * params print, parse back and normalise to the same thing. */
static void oracle(const vx_kind *k, const char *json, const vx_limits *lim)
{
    cJSON *in = cJSON_Parse(json);
    assert_non_null(in);
    vx_err err;
    vx_err_clear(&err);
    cJSON *norm = k->parse(in, lim, &err);
    if (!norm) {
        cJSON_Delete(in);
        return; /* refused at submission: fine */
    }
    char *text = cJSON_PrintUnformatted(norm);
    cJSON *back = cJSON_Parse(text);
    cJSON *again = k->parse(back, lim, &err);
    if (!again)
        fail_msg("%s %s: normalised params %s refused: %s", k->name, json, text, err.message);
    assert_true(cJSON_Compare(norm, again, 1));
    cJSON *n2 = vx_params_normalize(k, in, lim, &err);
    assert_non_null(n2);
    assert_true(cJSON_Compare(norm, n2, 1));
    cJSON_Delete(n2);
    cJSON_Delete(again);
    cJSON_Delete(back);
    free(text);
    cJSON_Delete(norm);
    cJSON_Delete(in);
}

/* Defect 7 of issue #10, found by fuzz_params: render with N above 256 and
 * no R was accepted, with the default R = 8 N over its limit of 2048, and
 * failed when it ran ("params.R must be in [258, 2048], got 2064"). Every
 * even N now normalises to params that read back the same. */
static void test_render_defaults(void **state)
{
    (void)state;
    const vx_kind *k = vx_kind_find("render");
    static const vx_limits none = {0};
    oracle(k, "{\"N\": 258, \"L\": 2}", &none);
    oracle(k, "{\"N\": 300}", &none);
    oracle(k, "{\"N\": 512, \"L\": 1}", &none);
    for (int n = 2; n <= 512; n += 2) {
        char buf[64];
        snprintf(buf, sizeof buf, "{\"N\": %d}", n);
        oracle(k, buf, &none);
        cJSON *in = cJSON_Parse(buf);
        vx_err err;
        cJSON *norm = vx_params_normalize(k, in, &none, &err);
        assert_non_null(norm);
        double R = cJSON_GetNumberValue(cJSON_GetObjectItem(norm, "R"));
        double L = cJSON_GetNumberValue(cJSON_GetObjectItem(norm, "L"));
        assert_true(R >= n && R <= 2048 && (long)R % 2 == 0);
        assert_true(R == (n <= 256 ? 8 * n : 2048));
        assert_true(L >= 1 && L * n <= 1024);
        cJSON_Delete(norm);
        cJSON_Delete(in);
    }
    /* With the daemon's limits N = 300 is too big: a 422 now, naming R. */
    vx_limits lim = {.max_job_memory = 4ull << 30, .max_image_pixels = 8192 * 8192};
    cJSON *in = cJSON_Parse("{\"N\": 300}");
    vx_err err;
    vx_err_clear(&err);
    assert_null(vx_params_normalize(k, in, &lim, &err));
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "invalid_params");
    assert_non_null(strstr(err.message, "params.R"));
    cJSON_Delete(in);
}

/* The seed corpus of fuzz_params (tests/fuzz/corpus/fuzz_params): valid
 * params of every kind, through the oracle. */
static void test_seeds(void **state)
{
    (void)state;
    static const struct {
        const char *kind, *json;
    } seeds[] = {
        {"preview",
         "{\"azimuth\":0,\"elevation\":0,\"fov\":0,\"width\":300,\"height\":200,\"samples\":1}"},
        {"preview", "{\"color\":[1,0.5,0],\"background\":[0,0,0,0],\"ambient\":0.5,\"samples\":2}"},
        {"voxelize",
         "{\"voxel_size\":0.01,\"padding\":2,\"inside\":\"parity\",\"format\":\"raw1\"}"},
        {"voxelize", "{\"grid\":{\"origin\":[0,0,0],\"voxel_size\":0.5,\"dims\":[16,8,4]},"
                     "\"format\":\"binvox\"}"},
        {"voxelize", "{\"resolution\":24,\"supersample\":2,\"samples\":\"faces\",\"threshold\":4,"
                     "\"method\":\"peel\"}"},
        {"render", "{\"N\":16,\"width\":64,\"height\":48,\"camera\":{\"type\":\"orbit\"},"
                   "\"frames\":3,\"bits\":16,\"outputs\":[\"depth\",\"voxels\"]}"},
        {"render", "{\"N\":16,\"lights\":[{\"direction\":[0,0,1],\"color\":[1,0,0]}],"
                   "\"background\":[0,0,1]}"},
        {"render", "{\"N\":8,\"filter\":{\"type\":\"exponential\",\"D0\":2,\"n\":4},\"L\":8,"
                   "\"normals\":\"sobel3d\"}"},
        {"gregory", "{\"max_edge\":0.01,\"weld\":false,\"format\":\"ply\"}"},
        {"gregory", "{\"divisions\":2,\"frames\":[[[0,0,0],[1,1,1]]]}"},
        {"catmull-clark", "{\"levels\":3,\"limit\":true}"},
    };
    vx_limits lim = {
        .max_triangles = 20000000, .max_image_pixels = 8192 * 8192, .max_job_memory = 4ull << 30};
    for (size_t i = 0; i < sizeof seeds / sizeof seeds[0]; i++)
        oracle(vx_kind_find(seeds[i].kind), seeds[i].json, &lim);
    for (size_t i = 0; i < vx_kind_count(); i++)
        oracle(vx_kind_at(i), "{}", &lim);
}

/* A kind whose default is out of its own range (x = 5, x in [0, 4]) and
 * one whose params do not read back the same: vx_params_normalize refuses
 * both with a 422 naming the params. */
static cJSON *bad_default_parse(const cJSON *params, const vx_limits *lim, vx_err *err)
{
    double x;
    if (vx_param_number(params, "x", 5, 0, 4, &x, err)) return NULL;
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "x", x);
    return o;
}

static cJSON *drifting_parse(const cJSON *params, const vx_limits *lim, vx_err *err)
{
    double x;
    if (vx_param_number(params, "x", 1, 0, 1e9, &x, err)) return NULL;
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "x", x + 1);
    return o;
}

static void test_normalize_checks(void **state)
{
    (void)state;
    vx_kind bad = {.name = "bad", .parse = bad_default_parse};
    vx_kind drift = {.name = "drift", .parse = drifting_parse};
    vx_err err;
    vx_err_clear(&err);
    assert_null(vx_params_normalize(&bad, NULL, &(vx_limits){0}, &err));
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "invalid_params");
    assert_non_null(strstr(err.message, "params.x must be in [0, 4], got 5"));
    assert_non_null(strstr(err.message, "defaults"));
    cJSON *in = cJSON_Parse("{\"x\": 3}");
    cJSON *n = vx_params_normalize(&bad, in, &(vx_limits){0}, &err);
    assert_non_null(n); /* given in range: fine */
    cJSON_Delete(n);
    vx_err_clear(&err);
    assert_null(vx_params_normalize(&drift, in, &(vx_limits){0}, &err));
    assert_string_equal(err.code, "invalid_params");
    assert_non_null(strstr(err.message, "read back"));
    cJSON_Delete(in);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_numbers),          cmocka_unit_test(test_only_known),
        cmocka_unit_test(test_mesh_ids),         cmocka_unit_test(test_object),
        cmocka_unit_test(test_kind_table),       cmocka_unit_test(test_preview_params),
        cmocka_unit_test(test_render_defaults),  cmocka_unit_test(test_seeds),
        cmocka_unit_test(test_normalize_checks),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
