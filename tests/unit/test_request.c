/* daemon/request.c: routes, strict query parameters (issue #10: repeated,
 * empty and hex values), plain-decimal numbers, transfer codings and the
 * UTF-8 / \u0000 checks of JSON bodies. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <string.h>

#include "request.h"

#define JID "0123456789abcdef0123456789abcdef"

static vx_route route(const char *p, vx_req_target *t)
{
    return vx_req_route(p, strlen(p), t);
}

static void test_routes(void **state)
{
    vx_req_target t;
    assert_int_equal(route("/livez", &t), VX_R_LIVEZ);
    assert_int_equal(route("/livez/", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/v1/meshes/abc", &t), VX_R_MESH);
    assert_string_equal(t.id, "abc");
    assert_int_equal(route("/v1/meshes/", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/v1/meshes/a/b", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/v1/jobs/" JID "/result/image", &t), VX_R_RESULT_NAME);
    assert_string_equal(t.id, JID);
    assert_string_equal(t.name, "image");
    assert_int_equal(route("/v1/jobs/" JID "/result", &t), VX_R_RESULT);
    assert_int_equal(route("/v1/jobs/" JID "/result/", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/v1/jobs//result", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/v1/jobs/" JID "/events", &t), VX_R_EVENTS);
    assert_string_equal(t.id, JID);
    assert_int_equal(route("/v1/jobs/" JID "/events/", &t), VX_R_UNKNOWN);
    assert_true(vx_req_method_allowed(VX_R_EVENTS, "HEAD"));
    assert_false(vx_req_method_allowed(VX_R_EVENTS, "POST"));
    assert_int_equal(vx_req_route("/livez\0x", 8, &t), VX_R_UNKNOWN);
    assert_true(vx_req_method_allowed(VX_R_MESH, "DELETE"));
    assert_false(vx_req_method_allowed(VX_R_MESH, "POST"));
    assert_false(vx_req_method_allowed(VX_R_MESH, "ELE"));
    assert_false(vx_req_method_allowed(VX_R_MESH, ""));
    assert_string_equal(vx_req_route_name(VX_R_JOB), "/v1/jobs/{id}");
}

/* The viewer's routes (routes_web.c): exact pages, one-segment files. */
static void test_web_routes(void **state)
{
    vx_req_target t;
    assert_int_equal(route("/", &t), VX_R_WEB_INDEX);
    assert_int_equal(route("", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/docs", &t), VX_R_WEB_DOCS);
    assert_int_equal(route("/docs/", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/openapi.yaml", &t), VX_R_WEB_SPEC);
    assert_int_equal(route("/ui/app.js", &t), VX_R_WEB_ASSET);
    assert_string_equal(t.name, "app.js");
    assert_int_equal(route("/ui/", &t), VX_R_UNKNOWN);
    assert_int_equal(route("/ui/a/b.js", &t), VX_R_UNKNOWN);
    assert_string_equal(t.name, "");
    assert_true(vx_req_method_allowed(VX_R_WEB_ASSET, "HEAD"));
    assert_false(vx_req_method_allowed(VX_R_WEB_INDEX, "POST"));
    assert_string_equal(vx_req_route_name(VX_R_WEB_ASSET), "/ui/{name}");
}

/* Adds "k=v" pairs (v NULL: no '='); returns the first failure's index or -1. */
static int add_all(vx_req_query *q, vx_route rt, const char *m, const char *const *kv, size_t n,
                   char *msg)
{
    vx_req_query_init(q);
    for (size_t i = 0; i < n; i += 2)
        if (vx_req_query_add(q, rt, m, kv[i], strlen(kv[i]), kv[i + 1],
                             kv[i + 1] ? strlen(kv[i + 1]) : 0, msg, 160))
            return (int)i / 2;
    return -1;
}

static void test_query(void **state)
{
    vx_req_query q;
    char msg[160];
    const char *ok[] = {"limit",  "5",      "after", JID,      "state",
                        "failed", "colour", NULL,    "colour", "x"};
    assert_int_equal(add_all(&q, VX_R_JOBS, "GET", ok, 10, msg), -1);
    assert_int_equal(q.limit, 5);
    assert_string_equal(q.after, JID);
    assert_string_equal(q.state, "failed");
    char back[200];
    assert_true(vx_req_query_format(&q, back, sizeof back) > 0);
    assert_string_equal(back, "limit=5&after=" JID "&state=failed");

    const char *twice[] = {"limit", "5", "limit", "abc"};
    assert_int_equal(add_all(&q, VX_R_MESHES, "GET", twice, 4, msg), 1);
    assert_non_null(strstr(msg, "limit"));
    const char *same[] = {"limit", "5", "limit", "5"};
    assert_int_equal(add_all(&q, VX_R_MESHES, "GET", same, 4, msg), 1);
    const char *bare[] = {"limit", NULL};
    assert_int_equal(add_all(&q, VX_R_MESHES, "GET", bare, 2, msg), 0);
    const char *empty[] = {"wait", ""};
    assert_int_equal(add_all(&q, VX_R_JOB, "GET", empty, 2, msg), 0);
    const char *hex[] = {"wait", "0x10"};
    assert_int_equal(add_all(&q, VX_R_JOB, "GET", hex, 2, msg), 0);
    assert_int_equal(add_all(&q, VX_R_JOBS, "POST", hex, 2, msg), 0);
    /* wait is not declared on GET /v1/jobs: ignored */
    assert_int_equal(add_all(&q, VX_R_JOBS, "GET", hex, 2, msg), -1);
    /* progress: a fraction 0..1 on GET /v1/jobs/{id}, written back exactly */
    const char *prog[] = {"wait", "5", "progress", "0.25"};
    assert_int_equal(add_all(&q, VX_R_JOB, "GET", prog, 4, msg), -1);
    assert_int_equal(q.progress_ppm, 250000);
    assert_true(vx_req_query_format(&q, back, sizeof back) > 0);
    assert_string_equal(back, "wait=5.000000&progress=0.250000");
    const char *one[] = {"progress", "1"};
    assert_int_equal(add_all(&q, VX_R_JOB, "GET", one, 2, msg), -1);
    assert_int_equal(q.progress_ppm, 1000000);
    const char *over[] = {"progress", "1.000001"};
    assert_int_equal(add_all(&q, VX_R_JOB, "GET", over, 2, msg), 0);
    assert_non_null(strstr(msg, "progress"));
    const char *neg[] = {"progress", "-0.5"};
    assert_int_equal(add_all(&q, VX_R_JOB, "GET", neg, 2, msg), 0);
    /* not declared on the list: ignored */
    assert_int_equal(add_all(&q, VX_R_JOBS, "GET", over, 2, msg), -1);
    const char *mesh_after[] = {"after", JID};
    assert_int_equal(add_all(&q, VX_R_MESHES, "GET", mesh_after, 2, msg), 0);
    vx_req_query_init(&q);
    assert_int_equal(
        vx_req_query_add(&q, VX_R_MESHES, "GET", "limit", 5, "5\0", 2, msg, sizeof msg), -1);
}

static void test_numbers(void **state)
{
    int l;
    uint64_t us;
    assert_int_equal(vx_req_parse_limit("1000", 4, &l), 0);
    assert_int_equal(l, 1000);
    assert_int_equal(vx_req_parse_limit("1001", 4, &l), -1);
    assert_int_equal(vx_req_parse_limit("0", 1, &l), -1);
    assert_int_equal(vx_req_parse_limit("+5", 2, &l), -1);
    assert_int_equal(vx_req_parse_limit(" 5", 2, &l), -1);
    assert_int_equal(vx_req_parse_seconds("2", 1, &us), 0);
    assert_int_equal(us, 2000000);
    assert_int_equal(vx_req_parse_seconds("0.5", 3, &us), 0);
    assert_int_equal(us, 500000);
    assert_int_equal(vx_req_parse_seconds("1.00000099", 10, &us), 0);
    assert_int_equal(us, 1000000);
    assert_int_equal(vx_req_parse_seconds("99999999999999999999999", 23, &us), 0);
    assert_true(us == VX_REQ_WAIT_MAX_US);
    const char *bad[] = {"0x10", "1e1", ".5", "5.", "-1", "+1", "1 ", "inf", "nan", "1.2.3", ""};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
        assert_int_equal(vx_req_parse_seconds(bad[i], strlen(bad[i]), &us), -1);
    uint64_t n;
    assert_int_equal(vx_req_parse_length("1000", &n), 0);
    assert_int_equal(n, 1000);
    assert_int_equal(vx_req_parse_length("-1", &n), -1);
    assert_int_equal(vx_req_parse_length("1 ", &n), -1);
    assert_int_equal(vx_req_parse_length("99999999999999999999", &n), -1);
    assert_int_equal(vx_req_transfer_encoding(NULL), 0);
    assert_int_equal(vx_req_transfer_encoding("Chunked"), 1);
    assert_int_equal(vx_req_transfer_encoding("gzip"), -1);
    assert_int_equal(vx_req_transfer_encoding("gzip, chunked"), -1);
}

static void test_utf8(void **state)
{
    assert_true(vx_req_utf8_valid("h\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80", 12));
    assert_false(vx_req_utf8_valid("\xff", 1));
    assert_false(vx_req_utf8_valid("\xc0\xaf", 2));         /* overlong '/' */
    assert_false(vx_req_utf8_valid("\xed\xa0\x80", 3));     /* a surrogate */
    assert_false(vx_req_utf8_valid("\xf4\x90\x80\x80", 4)); /* above U+10FFFF */
    assert_false(vx_req_utf8_valid("\xe2\x82", 2));         /* cut short */
    char out[16];
    assert_string_equal(vx_req_utf8_sanitize("a\xff"
                                             "b\xc3\xa9\n",
                                             out, sizeof out),
                        "a?b\xc3\xa9?");
    assert_string_equal(vx_req_utf8_sanitize("\xe2\x82\xac\xe2\x82\xac", out, 5), "\xe2\x82\xac");
    char msg[128];
    const char *nul = "{\"kind\":\"preview\\u0000junk\"}";
    assert_int_equal(vx_req_json_text_ok(nul, strlen(nul), msg, sizeof msg), -1);
    const char *text = "{\"kind\":\"preview\\\\u0000junk\"}";
    assert_int_equal(vx_req_json_text_ok(text, strlen(text), msg, sizeof msg), 0);
    assert_int_equal(vx_req_json_text_ok("{\"k\":\"\xff\"}", 8, msg, sizeof msg), -1);
    assert_int_equal(vx_req_json_text_ok("{}\0", 3, msg, sizeof msg), -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_routes), cmocka_unit_test(test_web_routes),
        cmocka_unit_test(test_query),  cmocka_unit_test(test_numbers),
        cmocka_unit_test(test_utf8),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
