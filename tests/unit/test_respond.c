/* The one mapping from error kinds to HTTP answers (daemon/respond.c):
 * every kind has its status, and the statuses that carry a header or
 * replace the code carry them. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <string.h>

#include "http_int.h"

static vx_resp_answer of(vx_err_kind kind, const char *code)
{
    vx_err e;
    vx_err_set(&e, kind, code, "message");
    return vx_resp_answer_of(&e);
}

static void test_statuses(void **state)
{
    (void)state;
    static const struct {
        vx_err_kind kind;
        unsigned status;
    } want[] = {
        {VX_EINVAL, 400},     {VX_EUNPROC, 422}, {VX_ETOOBIG, 413},  {VX_ENOTFOUND, 404},
        {VX_ECONFLICT, 409},  {VX_EMEDIA, 415},  {VX_EBUSY, 429},    {VX_ECANCELED, 409},
        {VX_ETIMEOUT, 504},   {VX_EGPU, 500},    {VX_EIO, 500},      {VX_EINTERNAL, 500},
        {VX_ENOSPC, 507},     {VX_EGONE, 410},   {VX_EUNAVAIL, 503}, {VX_EOVERLOAD, 503},
        {VX_EAUTH, 401},      {VX_EMETHOD, 405}, {VX_ELENGTH, 411},  {VX_EHEADER, 431},
        {VX_ENOTIMPL, 501},   {VX_ERANGE, 416},  {VX_EPRECOND, 412}, {VX_EOK, 500},
        {VX_EFORBIDDEN, 403},
    };
    _Static_assert(sizeof want / sizeof want[0] == VX_EKIND_COUNT, "every kind is listed");
    for (size_t i = 0; i < sizeof want / sizeof want[0]; i++) {
        vx_resp_answer a = of(want[i].kind, "some_code");
        if (a.status != want[i].status)
            fail_msg("kind %s: status %u, want %u", vx_err_kind_name(want[i].kind), a.status,
                     want[i].status);
    }
    /* Out of range: a bug, answered 500. */
    assert_int_equal(of((vx_err_kind)999, "x").status, 500);
}

static void test_the_code_decides_nothing(void **state)
{
    (void)state;
    /* The codes that once picked statuses by string now pick nothing. */
    assert_int_equal(of(VX_ENOTFOUND, "result_evicted").status, 404);
    assert_int_equal(of(VX_EGONE, "result_evicted").status, 410);
    assert_int_equal(of(VX_EBUSY, "not_ready").status, 429);
    assert_int_equal(of(VX_EUNAVAIL, "not_ready").status, 503);
}

static void test_headers_and_codes(void **state)
{
    (void)state;
    vx_resp_answer a = of(VX_EBUSY, "queue_full");
    assert_string_equal(a.header, MHD_HTTP_HEADER_RETRY_AFTER);
    assert_string_equal(a.value, "2");
    a = of(VX_EUNAVAIL, "not_ready");
    assert_string_equal(a.header, MHD_HTTP_HEADER_RETRY_AFTER);
    assert_string_equal(a.value, "5");
    a = of(VX_EOVERLOAD, "busy_parsing");
    assert_string_equal(a.header, MHD_HTTP_HEADER_RETRY_AFTER);
    assert_string_equal(a.value, "2");
    a = of(VX_EAUTH, "unauthorized");
    assert_string_equal(a.header, MHD_HTTP_HEADER_WWW_AUTHENTICATE);
    assert_string_equal(a.value, "Bearer realm=\"voxeld\"");
    a = of(VX_EMETHOD, "method_not_allowed");
    assert_string_equal(a.header, MHD_HTTP_HEADER_ALLOW);
    assert_null(a.value); /* the route's */
    /* Every full-disk error reads the same to clients. */
    a = of(VX_ENOSPC, "journal_failed");
    assert_null(a.header);
    assert_string_equal(a.code, "insufficient_storage");
    for (int k = VX_EOK; k < VX_EKIND_COUNT; k++) {
        a = of((vx_err_kind)k, "x");
        if (k != VX_ENOSPC) assert_null(a.code);
        if (a.status != 429 && a.status != 503 && a.status != 401 && a.status != 405)
            assert_null(a.header);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_statuses),
        cmocka_unit_test(test_the_code_decides_nothing),
        cmocka_unit_test(test_headers_and_codes),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
