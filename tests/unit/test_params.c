/* Typed parameter readers: defaults, types, ranges, integers, unknown keys. */
#include <math.h>
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

static void test_kind_table(void **state)
{
    assert_non_null(vx_kind_find("preview"));
    assert_null(vx_kind_find("nope"));
    assert_true(vx_kind_count() >= 1);
    for (size_t i = 0; i < vx_kind_count(); i++) {
        const vx_kind *k = vx_kind_at(i);
        assert_non_null(k->spec);
        assert_non_null(k->run_gl);
        assert_ptr_equal(vx_kind_find(k->name), k);
        /* Every kind accepts empty params and fills in its defaults. */
        vx_err err;
        cJSON *norm = vx_kind_parse(k, NULL, &(vx_limits){0}, &err);
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
    cJSON *norm = vx_kind_parse(k, in, &lim, &err);
    assert_non_null(norm);
    assert_true(cJSON_GetNumberValue(cJSON_GetObjectItem(norm, "azimuth")) == 45);
    assert_true(cJSON_GetNumberValue(cJSON_GetObjectItem(norm, "elevation")) == 20);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(norm, "color")), 3);
    /* parse is idempotent on its own output */
    cJSON *again = vx_kind_parse(k, norm, &lim, &err);
    assert_true(cJSON_Compare(norm, again, 1));
    cJSON_Delete(again);
    /* a field given as null reads as absent (openapi's JobRequest) */
    cJSON *with_null = cJSON_Parse("{\"width\": 100, \"height\": 100, \"azimuth\": 45, "
                                   "\"elevation\": null, \"color\": null}");
    again = vx_kind_parse(k, with_null, &lim, &err);
    assert_non_null(again);
    assert_true(cJSON_Compare(norm, again, 1));
    cJSON_Delete(again);
    cJSON_Delete(with_null);
    /* -0 normalises as 0: the same request for reuse and idempotency */
    cJSON *neg = cJSON_Parse("{\"width\": 100, \"height\": 100, \"azimuth\": -0}"),
          *pos = cJSON_Parse("{\"width\": 100, \"height\": 100, \"azimuth\": 0}");
    cJSON *nn = vx_kind_parse(k, neg, &lim, &err), *np = vx_kind_parse(k, pos, &lim, &err);
    char *tn = cJSON_PrintUnformatted(nn), *tp = cJSON_PrintUnformatted(np);
    assert_string_equal(tn, tp);
    free(tn);
    free(tp);
    cJSON_Delete(nn);
    cJSON_Delete(np);
    cJSON_Delete(neg);
    cJSON_Delete(pos);
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
        assert_null(vx_kind_parse(k, in, &lim, &err));
        assert_int_equal(err.kind, VX_EUNPROC);
        assert_string_equal(err.code, "invalid_params");
        cJSON_Delete(in);
    }
}

/* A range whose low end is open says so: gregory's max_edge is > 0. */
static void test_open_range_message(void **state)
{
    (void)state;
    const vx_kind *k = vx_kind_find("gregory");
    vx_err err;
    cJSON *in = cJSON_Parse("{\"max_edge\": 1.1e300}");
    assert_null(vx_kind_parse(k, in, &(vx_limits){0}, &err));
    assert_non_null(strstr(err.message, "params.max_edge must be in (0, 1e+300], got 1.1e+300"));
    cJSON_Delete(in);
}

/* An array of mesh ids (render's meshes). */
typedef struct t_ids {
    char m[2][VX_MESH_ID_SIZE];
    int n;
} t_ids;

static const vx_pspec t_id_item = {.type = VX_PT_MESH_ID};
static const vx_pspec t_ids_spec[] = {
    {.name = "m",
     .type = VX_PT_ARRAY,
     .off = offsetof(t_ids, m),
     .sub = &t_id_item,
     .item_size = VX_MESH_ID_SIZE,
     .max_items = 2,
     .flags = VX_PF_COUNT,
     .count_off = offsetof(t_ids, n)},
    VX_P_END,
};

static int ids_read(const char *fmt, const char *id, t_ids *out, vx_err *err)
{
    char buf[512];
    snprintf(buf, sizeof buf, fmt, id, id, id);
    cJSON *p = cJSON_Parse(buf);
    assert_non_null(p);
    memset(out, 0, sizeof *out);
    vx_err_clear(err);
    int rc = vx_spec_read(t_ids_spec, p, NULL, out, err);
    cJSON_Delete(p);
    return rc;
}

static void test_mesh_ids(void **state)
{
    (void)state;
    char id[65];
    memset(id, 'a', 64);
    id[64] = 0;
    vx_err err;
    t_ids t;
    assert_int_equal(ids_read("{\"m\": [\"%s\", \"%s\"]}", id, &t, &err), 0);
    assert_int_equal(t.n, 2);
    assert_string_equal(t.m[1], id);
    assert_int_equal(ids_read("{}", id, &t, &err), 0);
    assert_int_equal(t.n, 0);
    assert_int_equal(ids_read("{\"m\": [\"%s\", \"%s\", \"%s\"]}", id, &t, &err), -1);
    assert_string_equal(err.message, "params.m has 3 entries (at most 2)");
    static const char *const bad[] = {"{\"m\": [\"%.63s\"]}", "{\"m\": [\"%.63sA\"]}",
                                      "{\"m\": [1]}"};
    for (size_t i = 0; i < 3; i++) {
        assert_int_equal(ids_read(bad[i], id, &t, &err), -1);
        assert_string_equal(err.code, "invalid_params");
        assert_string_equal(err.message, "params.m[0] is not a mesh id (64 lowercase hex digits)");
    }
    assert_int_equal(ids_read("{\"m\": \"%s\"}", id, &t, &err), -1);
    assert_string_equal(err.message, "params.m must be an array of mesh ids");
}

/* The fuzz_params oracle on one input: parse accepts, the normalised
 * params print, parse back and normalise to the same thing. */
static void oracle(const vx_kind *k, const char *json, const vx_limits *lim)
{
    cJSON *in = cJSON_Parse(json);
    assert_non_null(in);
    vx_err err;
    vx_err_clear(&err);
    cJSON *norm = vx_kind_parse(k, in, lim, &err);
    if (!norm) {
        cJSON_Delete(in);
        return; /* refused at submission: fine */
    }
    char *text = cJSON_PrintUnformatted(norm);
    cJSON *back = cJSON_Parse(text);
    cJSON *again = vx_kind_parse(k, back, lim, &err);
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
        {"voxelize", "{\"inside\":\"winding\",\"supersample\":2,\"samples\":\"faces\"}"},
        {"voxelize", "{\"inside\":null,\"padding\":4}"},
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
typedef struct one_x {
    double x;
} one_x;

static const vx_pspec bad_spec[] = {VX_P_NUM(one_x, x, 5, 0, 4, "default out of range"), VX_P_END};
static const vx_pspec x_spec[] = {VX_P_NUM(one_x, x, 1, 0, 1e9, "x"), VX_P_END};

/* A check that changes a given value: the normalised params drift. */
static int drifting_check(void *params, const vx_limits *lim, vx_err *err)
{
    ((one_x *)params)->x += 1;
    return 0;
}

static void test_normalize_checks(void **state)
{
    (void)state;
    vx_kind bad = {.name = "bad", .spec = bad_spec, .params_size = sizeof(one_x)};
    vx_kind drift = {
        .name = "drift", .spec = x_spec, .params_size = sizeof(one_x), .check = drifting_check};
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

/* The generic reader and writer (spec.h) on a spec of every type. */
typedef struct t_sub {
    double k;
    int mode;
} t_sub;

typedef struct t_item {
    double dir[3];
    long w;
} t_item;

typedef struct t_params {
    long lo, n;
    double x, pos;
    int flag, mode;
    char id[VX_MESH_ID_SIZE];
    double rgb[3];
    t_sub sub;
    t_item items[2];
    int nitems, tags[3];
    long a, b;
    int a_set, b_set, id_set;
} t_params;

static const char *const t_modes[] = {"one", "two", NULL}, *const t_tags[] = {"p", "q", "r", NULL};
static const char *const t_not_b[] = {"b", NULL};
static const double t_grey[3] = {0.5, 0.5, 0.5};
static const vx_pspec t_unit = VX_P_ITEM_NUM(0, 1), t_any = VX_P_ITEM_NUM(-10, 10);
static const vx_pspec t_sub_spec[] = {
    VX_P_NUM(t_sub, k, 2, 0, 4, "k"),
    VX_P_ENUM(t_sub, mode, t_modes, 1, "mode"),
    VX_P_END,
};
static const vx_pspec t_item_spec[] = {
    VX_P_VEC(t_item, dir, 3, NULL, &t_any, "dir", .flags = VX_PF_REQUIRED),
    VX_P_INT(t_item, w, 1, 1, 9, "w"),
    VX_P_END,
};
static const vx_pspec t_item_obj = {.type = VX_PT_OBJECT, .sub = t_item_spec};
static double t_hi(const vx_limits *lim)
{
    return lim && lim->max_triangles ? (double)lim->max_triangles : 100;
}
#define TO(f) offsetof(t_params, f)
static const vx_pspec t_spec[] = {
    VX_P_INT(t_params, lo, 2, 0, 10, "lo"),
    VX_P_INT(t_params, n, 5, 0, 50, "n, at least lo", .lo_field = "lo", .hi_of = t_hi),
    VX_P_NUM(t_params, x, 0.5, -1, 1, "x"),
    VX_P_NUM(t_params, pos, 1, 0, HUGE_VAL, "pos > 0", .flags = VX_PF_GT_LO),
    VX_P_BOOL(t_params, flag, 1, "flag"),
    VX_P_ENUM(t_params, mode, t_modes, 0, "mode"),
    {.name = "id",
     .type = VX_PT_MESH_ID,
     .off = TO(id),
     .flags = VX_PF_NULLABLE,
     .set_off = TO(id_set)},
    VX_P_VEC(t_params, rgb, 3, t_grey, &t_unit, "rgb"),
    {.name = "sub", .type = VX_PT_OBJECT, .off = TO(sub), .sub = t_sub_spec},
    {.name = "items",
     .type = VX_PT_ARRAY,
     .off = TO(items),
     .sub = &t_item_obj,
     .item_size = sizeof(t_item),
     .max_items = 2,
     .flags = VX_PF_COUNT,
     .count_off = TO(nitems)},
    {.name = "tags", .type = VX_PT_ENUM_SET, .off = TO(tags), .names = t_tags},
    VX_P_INT(t_params, a, 0, 0, 9, "a", .flags = VX_PF_NULLABLE, .set_off = TO(a_set),
             .excludes = t_not_b),
    VX_P_INT(t_params, b, 0, 0, 9, "b", .flags = VX_PF_NULLABLE, .set_off = TO(b_set)),
    VX_P_END,
};
#undef TO

/* Reads text; returns 0 and the normalised JSON in *norm, or -1 with err. */
static int t_read(const char *text, const vx_limits *lim, t_params *p, char **norm, vx_err *err)
{
    cJSON *in = text ? cJSON_Parse(text) : NULL;
    assert_true(!text || in);
    memset(p, 0, sizeof *p);
    vx_err_clear(err);
    int rc = vx_spec_read(t_spec, in, lim, p, err);
    cJSON_Delete(in);
    if (rc == 0 && norm) {
        cJSON *o = vx_spec_write(t_spec, p);
        assert_non_null(o);
        *norm = cJSON_PrintUnformatted(o);
        cJSON_Delete(o);
    }
    vx_spec_free(t_spec, p);
    return rc;
}

static void t_fails(const char *text, const char *message)
{
    t_params p;
    vx_err err;
    assert_int_equal(t_read(text, NULL, &p, NULL, &err), -1);
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "invalid_params");
    if (strcmp(err.message, message) != 0) fail_msg("%s: %s, not %s", text, err.message, message);
}

static void test_spec_defaults(void **state)
{
    (void)state;
    t_params p;
    vx_err err;
    char *norm;
    static const char *const none[] = {NULL, "null", "{}"};
    for (int i = 0; i < 3; i++) {
        assert_int_equal(t_read(none[i], NULL, &p, &norm, &err), 0);
        assert_string_equal(norm,
                            "{\"lo\":2,\"n\":5,\"x\":0.5,\"pos\":1,\"flag\":true,\"mode\":"
                            "\"one\",\"id\":null,\"rgb\":[0.5,0.5,0.5],\"sub\":{\"k\":2,"
                            "\"mode\":\"two\"},\"items\":[],\"tags\":[],\"a\":null,\"b\":null}");
        free(norm);
    }
    assert_true(p.lo == 2 && p.n == 5 && p.x == 0.5 && p.flag == 1 && p.mode == 0);
    assert_true(p.rgb[1] == 0.5 && p.sub.k == 2 && p.sub.mode == 1 && p.nitems == 0);
    assert_true(!p.a_set && !p.b_set && !p.id_set);
}

static void test_spec_values(void **state)
{
    (void)state;
    t_params p;
    vx_err err;
    char *norm;
    const char *in =
        "{\"tags\":[\"r\",\"p\"],\"n\":7,\"sub\":{\"mode\":\"one\"},\"flag\":false,"
        "\"id\":\"" /* 64 hex digits */
        "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef\","
        "\"items\":[{\"dir\":[1,2,3]},{\"dir\":[0,0,-1],\"w\":9}],\"a\":3,\"b\":null,\"x\":-1}";
    assert_int_equal(t_read(in, NULL, &p, &norm, &err), 0);
    /* spec order, every field, the tag set in names order */
    assert_string_equal(norm,
                        "{\"lo\":2,\"n\":7,\"x\":-1,\"pos\":1,\"flag\":false,\"mode\":\"one\","
                        "\"id\":\"0123456789abcdef0123456789abcdef0123456789abcdef0123456789a"
                        "bcdef\",\"rgb\":[0.5,0.5,0.5],\"sub\":{\"k\":2,\"mode\":\"one\"},"
                        "\"items\":[{\"dir\":[1,2,3],\"w\":1},{\"dir\":[0,0,-1],\"w\":9}],"
                        "\"tags\":[\"p\",\"r\"],\"a\":3,\"b\":null}");
    assert_true(p.nitems == 2 && p.items[1].w == 9 && p.items[0].dir[2] == 3);
    assert_true(p.tags[0] && !p.tags[1] && p.tags[2] && p.a_set && p.id_set);
    /* the normalised params read back to themselves */
    char *again;
    assert_int_equal(t_read(norm, NULL, &p, &again, &err), 0);
    assert_string_equal(norm, again);
    free(again);
    free(norm);
}

static void test_spec_errors(void **state)
{
    (void)state;
    t_fails("[1]", "params must be an object");
    t_fails("{\"zz\":1}", "unknown parameter params.zz");
    t_fails("{\"sub\":{\"zz\":1}}", "unknown parameter params.sub.zz");
    t_fails("{\"items\":[{\"dir\":[0,0,1],\"zz\":1}]}", "unknown parameter params.items[0].zz");
    t_fails("{\"x\":\"1\"}", "params.x must be a number");
    t_fails("{\"x\":2}", "params.x must be in [-1, 1], got 2");
    /* the value as given, not rounded to 6 digits (it looked in range) */
    t_fails("{\"x\":1.0000001}", "params.x must be in [-1, 1], got 1.0000001");
    t_fails("{\"x\":1e999}", "params.x must be a finite number (it is past the largest double)");
    t_fails("{\"lo\":2.5}", "params.lo must be an integer");
    t_fails("{\"lo\":11}", "params.lo must be in [0, 10], got 11");
    t_fails("{\"pos\":0}", "params.pos must be > 0, got 0");
    t_fails("{\"pos\":-2}", "params.pos must be > 0, got -2"); /* not "in [0, ...]" */
    t_fails("{\"flag\":1}", "params.flag must be true or false");
    t_fails("{\"mode\":\"three\"}", "params.mode must be one of one, two");
    t_fails("{\"id\":\"abc\"}", "params.id is not a mesh id (64 lowercase hex digits)");
    t_fails("{\"rgb\":[1,1]}", "params.rgb must be an array of 3 numbers in [0, 1]");
    t_fails("{\"rgb\":[1,1,2]}", "params.rgb[2] must be a number in [0, 1]");
    t_fails("{\"sub\":3}", "params.sub must be an object");
    t_fails("{\"sub\":{\"k\":5}}", "params.sub.k must be in [0, 4], got 5");
    t_fails("{\"items\":[{},{},{}]}", "params.items must be an array of at most 2 {dir, w}");
    t_fails("{\"items\":[1]}", "params.items[] must be objects");
    t_fails("{\"items\":[{\"w\":2}]}", "params.items[0].dir is required");
    t_fails("{\"items\":[{\"dir\":[0,0,1],\"w\":0}]}",
            "params.items[0].w must be in [1, 9], got 0");
    t_fails("{\"tags\":\"p\"}", "params.tags must be an array of p, q, r");
    t_fails("{\"tags\":[\"s\"]}", "params.tags entries must be p, q or r");
    t_fails("{\"tags\":[\"q\",\"p\",\"q\"]}", "params.tags lists \"q\" twice");
    /* exclusions go before types: on presence alone */
    t_fails("{\"a\":\"x\",\"b\":1}", "params.a and params.b exclude each other");
    /* the minimum of n is lo; its maximum follows the limits */
    t_fails("{\"lo\":8,\"n\":7}", "params.n must be in [8, 100], got 7");
    t_params p;
    vx_err err;
    vx_limits lim = {.max_triangles = 20};
    assert_int_equal(t_read("{\"n\":30}", &lim, &p, NULL, &err), -1);
    assert_string_equal(err.message, "params.n must be in [2, 20], got 30");
    assert_int_equal(t_read("{\"n\":30}", NULL, &p, NULL, &err), 0);
}

static void test_spec_describe(void **state)
{
    (void)state;
    cJSON *d = vx_spec_describe(t_spec);
    assert_non_null(d);
    char *text = cJSON_PrintUnformatted(cJSON_GetObjectItem(d, "n"));
    assert_string_equal(text, "{\"type\":\"integer\",\"doc\":\"n, at least lo\",\"default\":5,"
                              "\"minimum_field\":\"lo\",\"minimum\":0,\"maximum\":50}");
    free(text);
    const cJSON *items = cJSON_GetObjectItem(d, "items");
    assert_string_equal(cJSON_GetStringValue(cJSON_GetObjectItem(items, "type")), "array");
    assert_true(cJSON_GetNumberValue(cJSON_GetObjectItem(items, "maxItems")) == 2);
    const cJSON *dir = cJSON_GetObjectItem(
        cJSON_GetObjectItem(cJSON_GetObjectItem(items, "items"), "properties"), "dir");
    assert_true(cJSON_IsTrue(cJSON_GetObjectItem(dir, "required")));
    assert_non_null(cJSON_GetObjectItem(cJSON_GetObjectItem(d, "a"), "excludes"));
    cJSON_Delete(d);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mesh_ids),         cmocka_unit_test(test_kind_table),
        cmocka_unit_test(test_preview_params),   cmocka_unit_test(test_open_range_message),
        cmocka_unit_test(test_render_defaults),  cmocka_unit_test(test_seeds),
        cmocka_unit_test(test_normalize_checks), cmocka_unit_test(test_spec_defaults),
        cmocka_unit_test(test_spec_values),      cmocka_unit_test(test_spec_errors),
        cmocka_unit_test(test_spec_describe),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
