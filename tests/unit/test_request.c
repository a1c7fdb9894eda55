/* daemon/request.c: routes, strict query parameters (issue #10: repeated,
 * empty and hex values), plain-decimal numbers, transfer codings and the
 * UTF-8 / \u0000 checks of JSON bodies. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <string.h>

#include <cJSON.h>

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
    assert_string_equal(vx_req_route_allow(VX_R_MESH), "GET, HEAD, DELETE, OPTIONS");
    assert_true(vx_req_method_known("PATCH"));
    assert_true(vx_req_method_known("TRACE"));
    assert_false(vx_req_method_known("PROPFIND"));
    assert_false(vx_req_method_known("get"));
    assert_false(vx_req_method_known(""));
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
    /* libmicrohttpd keeps trailing white space and then reads no chunks */
    assert_int_equal(vx_req_transfer_encoding("chunked "), -1);
    assert_int_equal(vx_req_transfer_encoding("chunked\t"), -1);
    /* an empty value is malformed (400), not a coding not implemented (501) */
    assert_int_equal(vx_req_transfer_encoding(""), -2);
    assert_int_equal(vx_req_transfer_encoding(" \t"), -2);
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

    /* strict parsing: what cJSON alone would take and RFC 8259 does not */
    static const char *const good[] = {
        "{\"a\":[0,-0,1.5,-2e3,1E+2,0.25e-1,10],\"b\":{\"a\":1}}\n",
        " {\"s\":\"tab\\t \\\"q\\\" 1.\"} ",
        "[{\"a\":1},{\"a\":2}]",
        "-0.0",
        "true",
    };
    static const char *const bad[] = {
        "{\"a\":1} x",         "{}{}",
        "{\"a\":016}",         "{\"a\":00}",
        "{\"a\":8.}",          "{\"a\":.5}",
        "{\"a\":+1}",          "{\"a\":1e}",
        "{\"a\":-}",           "{\"a\":1.e3}",
        "{\"a\":\"x\ty\"}",    "{\"a\":\"x\ny\"}",
        "{\"a\":1,\"a\":2}",   "{\"p\":{\"r\":8,\"q\":1,\"r\":16}}",
        "[{\"k\":1,\"k\":1}]", "{\"a\":-Infinity}",
    };
    for (size_t i = 0; i < sizeof good / sizeof *good; i++) {
        cJSON *d = vx_req_json_parse(good[i], strlen(good[i]), msg, sizeof msg);
        if (!d) fail_msg("refused %s: %s", good[i], msg);
        cJSON_Delete(d);
    }
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        msg[0] = 0;
        cJSON *d = vx_req_json_parse(bad[i], strlen(bad[i]), msg, sizeof msg);
        if (d) fail_msg("took %s", bad[i]);
        assert_true(msg[0] != 0);
    }
    cJSON *d = vx_req_json_parse("{\"r\":1,\"r\":2}", 13, msg, sizeof msg);
    assert_null(d);
    assert_string_equal(msg, "an object has the key \"r\" twice");
}

#define MID "4f3c4172a4fe308cebc840da665171f534849b1fca101eaf635d68fb453393db"

/* GET /v1/jobs: order, kind and mesh (issue #13), strict like the rest. */
static void test_job_filters(void **state)
{
    (void)state;
    vx_req_query q;
    char msg[160], back[300];
    const char *ok[] = {"order", "desc", "kind", "catmull-clark", "mesh", MID};
    assert_int_equal(add_all(&q, VX_R_JOBS, "GET", ok, 6, msg), -1);
    assert_true(q.desc);
    assert_string_equal(q.kind, "catmull-clark");
    assert_string_equal(q.mesh, MID);
    assert_true(vx_req_query_format(&q, back, sizeof back) > 0);
    assert_string_equal(back, "order=desc&kind=catmull-clark&mesh=" MID);
    const char *asc[] = {"order", "asc"};
    assert_int_equal(add_all(&q, VX_R_JOBS, "GET", asc, 2, msg), -1);
    assert_false(q.desc);
    const char *bad[][2] = {{"order", "newest"}, {"kind", "Preview"}, {"kind", "a b"},
                            {"mesh", "abc"},     {"mesh", JID},       {"order", ""}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
        assert_int_equal(add_all(&q, VX_R_JOBS, "GET", bad[i], 2, msg), 0);
    /* Only GET /v1/jobs declares them. */
    const char *elsewhere[] = {"order", "newest"};
    assert_int_equal(add_all(&q, VX_R_MESHES, "GET", elsewhere, 2, msg), -1);
}

static void test_negotiation(void **state)
{
    (void)state;
    assert_int_equal(vx_req_accept_coding(NULL), VX_CODING_IDENTITY);
    assert_int_equal(vx_req_accept_coding("gzip, deflate, br"), VX_CODING_GZIP);
    assert_int_equal(vx_req_accept_coding("zstd"), VX_CODING_ZSTD);
    assert_int_equal(vx_req_accept_coding("gzip, zstd"), VX_CODING_ZSTD); /* a tie: zstd */
    assert_int_equal(vx_req_accept_coding("gzip;q=0.9, zstd;q=0.5"), VX_CODING_GZIP);
    /* a qvalue has at most three decimals: a fourth makes the element void */
    assert_int_equal(vx_req_accept_coding("gzip;q=0.001"), VX_CODING_GZIP);
    assert_int_equal(vx_req_accept_coding("gzip;q=0.0001"), VX_CODING_IDENTITY);
    assert_int_equal(vx_req_accept_coding("zstd;q=0, gzip"), VX_CODING_GZIP);
    assert_int_equal(vx_req_accept_coding("ZSTD ; Q=1"), VX_CODING_ZSTD); /* case-insensitive */
    assert_int_equal(vx_req_accept_coding("*"), VX_CODING_ZSTD);
    assert_int_equal(vx_req_accept_coding("*;q=0"), VX_CODING_IDENTITY);
    assert_int_equal(vx_req_accept_coding("*;q=0.1, zstd;q=0"), VX_CODING_GZIP);
    assert_int_equal(vx_req_accept_coding("identity"), VX_CODING_IDENTITY);
    assert_int_equal(vx_req_accept_coding("x-gzip"), VX_CODING_GZIP);
    assert_int_equal(vx_req_accept_coding("zstd;q=2"), VX_CODING_IDENTITY); /* malformed q */
    /* identity preferred by q over every coding offered: sent as it is */
    assert_int_equal(vx_req_accept_coding("identity, gzip;q=0.1"), VX_CODING_IDENTITY);
    assert_int_equal(vx_req_accept_coding("gzip;q=0.5, identity;q=1"), VX_CODING_IDENTITY);
    assert_int_equal(vx_req_accept_coding("*;q=0.5, identity;q=0.8"), VX_CODING_IDENTITY);
    assert_int_equal(vx_req_accept_coding("identity;q=0.5, zstd"), VX_CODING_ZSTD);
    assert_int_equal(vx_req_accept_coding("identity;q=0.5, gzip;q=0.5"),
                     VX_CODING_GZIP); /* a tie */
    assert_int_equal(vx_req_accept_coding("identity;q=0, gzip;q=0.2"), VX_CODING_GZIP);

    uint64_t a, b;
    assert_int_equal(vx_req_range("bytes=0-99", 1000, &a, &b), 1);
    assert_true(a == 0 && b == 99);
    assert_int_equal(vx_req_range("bytes=900-", 1000, &a, &b), 1);
    assert_true(a == 900 && b == 999);
    assert_int_equal(vx_req_range("bytes=990-5000", 1000, &a, &b), 1);
    assert_true(a == 990 && b == 999);
    assert_int_equal(vx_req_range("bytes=-10", 1000, &a, &b), 1);
    assert_true(a == 990 && b == 999);
    assert_int_equal(vx_req_range("bytes=-5000", 1000, &a, &b), 1);
    assert_true(a == 0 && b == 999);
    assert_int_equal(vx_req_range("bytes=1000-", 1000, &a, &b), -1);
    assert_int_equal(vx_req_range("bytes=-0", 1000, &a, &b), -1);
    assert_int_equal(vx_req_range("bytes=0-", 0, &a, &b), -1);
    assert_int_equal(vx_req_range(NULL, 1000, &a, &b), 0);
    assert_int_equal(vx_req_range("items=0-1", 1000, &a, &b), 0);
    assert_int_equal(vx_req_range("bytes=5-1", 1000, &a, &b), 0);
    assert_int_equal(vx_req_range("bytes=0-1,5-9", 1000, &a, &b), 0);
    assert_int_equal(vx_req_range("bytes=x-", 1000, &a, &b), 0);
    /* digits past uint64: past any end (416), or up to the end */
    assert_int_equal(vx_req_range("bytes=99999999999999999999-", 1000, &a, &b), -1);
    assert_int_equal(vx_req_range("bytes=18446744073709551615-", 1000, &a, &b), -1);
    assert_int_equal(vx_req_range("bytes=10-99999999999999999999999", 1000, &a, &b), 1);
    assert_true(a == 10 && b == 999);
    assert_int_equal(vx_req_range("bytes=-99999999999999999999", 1000, &a, &b), 1);
    assert_true(a == 0 && b == 999);
    /* empty list elements are ignored (RFC 9110 5.6.1.2); leading zeros
     * are digits */
    assert_int_equal(vx_req_range("bytes=0-9,", 1000, &a, &b), 1);
    assert_true(a == 0 && b == 9);
    assert_int_equal(vx_req_range("bytes=, ,-10 ,", 1000, &a, &b), 1);
    assert_true(a == 990 && b == 999);
    assert_int_equal(vx_req_range("bytes=,", 1000, &a, &b), 0);
    assert_int_equal(vx_req_range("bytes=0-1, ,5-9", 1000, &a, &b), 0);
    assert_int_equal(vx_req_range("bytes=00000000000000000000000000005-0009", 1000, &a, &b), 1);
    assert_true(a == 5 && b == 9);
    assert_int_equal(vx_req_range("bytes=0000000000000000000000001000-", 1000, &a, &b), -1);
    assert_int_equal(vx_req_range("bytes=0 -9", 1000, &a, &b), 0);

    assert_true(vx_req_etag_match("\"a\", \"b\"", "\"b\"", 1, 1));
    assert_false(vx_req_etag_match("\"ab\"", "\"a\"", 1, 1));
    assert_true(vx_req_etag_match("W/\"a\"", "\"a\"", 1, 1));
    assert_false(vx_req_etag_match("W/\"a\"", "\"a\"", 0, 0)); /* If-Range: strong only */
    assert_true(vx_req_etag_match("*", "\"a\"", 1, 1));
    assert_false(vx_req_etag_match("*", "\"a\"", 0, 0));
    assert_false(vx_req_etag_match("Tue, 01 Dec 2026 10:00:00 GMT", "\"a\"", 0, 0));
    assert_false(vx_req_etag_match(NULL, "\"a\"", 1, 1));

    assert_true(vx_req_id_ok("abc-123_x.y:z"));
    assert_false(vx_req_id_ok(""));
    assert_false(vx_req_id_ok("a b"));
    assert_false(vx_req_id_ok("a\nb"));
    char long_id[80];
    memset(long_id, 'a', sizeof long_id - 1);
    long_id[sizeof long_id - 1] = 0;
    assert_false(vx_req_id_ok(long_id));
}

static int name_of(const char *cd, char *out)
{
    return vx_req_disposition_name(cd, out, VX_NAME_MAX + 1);
}

/* Mesh names: what may be one, and where a Content-Disposition has it. */
static void test_names(void **state)
{
    (void)state;
    static const char *good[] = {"box.stl",
                                 "Cube \xc3\xa9t\xc3\xa9.off",
                                 "...",
                                 ".hidden",
                                 "a..b",
                                 "\xe2\x80\x90"
                                 "dash"}; /* U+2010 is a visible hyphen */
    for (size_t i = 0; i < sizeof good / sizeof *good; i++)
        assert_true(vx_name_ok(good[i], strlen(good[i])));
    static const char *bad[] = {
        ".",
        "..",
        "a/b",
        "a\\b",
        "a\"b",
        "tab\there",
        "del\x7f",
        "c1\xc2\x85",              /* U+0085 NEL */
        "evil\xe2\x80\xaegpj.exe", /* U+202E right-to-left override */
        "iso\xe2\x81\xa6x",        /* U+2066 left-to-right isolate */
        "zw\xe2\x80\x8b",          /* U+200B zero width space */
        "\xef\xbb\xbf"
        "bom",         /* U+FEFF */
        "alm\xd8\x9c", /* U+061C Arabic letter mark */
        "bad\xff",     /* not UTF-8 */
        "",
    };
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++)
        assert_false(vx_name_ok(bad[i], strlen(bad[i])));

    char out[VX_NAME_MAX + 1];
    assert_int_equal(name_of("attachment; filename=\"C:\\\\m\\\\box.stl\"", out), 1);
    assert_string_equal(out, "box.stl");
    assert_int_equal(name_of("attachment; filename=plain.obj; size=3", out), 1);
    assert_string_equal(out, "plain.obj");
    assert_int_equal(name_of("filename=first.obj", out), 1);
    assert_string_equal(out, "first.obj");
    /* filename* is preferred, UTF-8 or ISO-8859-1, percent-decoded */
    assert_int_equal(
        name_of("attachment; filename=\"fallback.stl\"; filename*=UTF-8''%C3%A9t%C3%A9.stl", out),
        1);
    assert_string_equal(out, "\xc3\xa9t\xc3\xa9.stl");
    assert_int_equal(name_of("attachment; FILENAME*=utf-8'en'only%20star.obj", out), 1);
    assert_string_equal(out, "only star.obj");
    assert_int_equal(name_of("attachment; filename*=iso-8859-1''caf%E9.ply", out), 1);
    assert_string_equal(out, "caf\xc3\xa9.ply");
    /* an ext-value that cannot be read falls back to filename=, else is bad */
    assert_int_equal(name_of("attachment; filename*=Shift_JIS''x.obj; filename=y.obj", out), 1);
    assert_string_equal(out, "y.obj");
    assert_int_equal(name_of("attachment; filename*=UTF-8''a%00b.obj", out), -1);
    assert_int_equal(name_of("attachment; filename*=UTF-8''a%zzb.obj", out), -1);
    assert_int_equal(name_of("attachment; filename*=UTF-8''%E2%80%AEgpj.exe", out), -1);
    assert_int_equal(name_of("attachment; filename*=UTF-8''..%2F..%2Fetc%2Fpasswd", out), 1);
    assert_string_equal(out, "passwd");
    assert_int_equal(name_of("attachment; filename=\"..\"", out), -1);
    assert_int_equal(name_of("attachment; filename=\"a/..\"", out), -1);
    /* a parameter inside a quoted string is not a parameter */
    assert_int_equal(name_of("attachment; filename=\"a; filename*=UTF-8''b.obj\"", out), 1);
    assert_string_equal(out, "a; filename*=UTF-8''b.obj");
    assert_int_equal(name_of("attachment; xfilename=z.obj", out), 0);
    assert_int_equal(name_of("attachment", out), 0);
    assert_int_equal(name_of(NULL, out), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_routes),      cmocka_unit_test(test_web_routes),
        cmocka_unit_test(test_query),       cmocka_unit_test(test_numbers),
        cmocka_unit_test(test_utf8),        cmocka_unit_test(test_job_filters),
        cmocka_unit_test(test_negotiation), cmocka_unit_test(test_names),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
