/* Bearer-token checks of daemon/auth.c. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include "auth.h"

static void test_bearer(void **state)
{
    (void)state;
    vx_auth a;
    vx_auth_init(&a, "s3cret");
    assert_true(a.on);
    assert_true(vx_auth_ok(&a, "Bearer s3cret"));
    assert_true(vx_auth_ok(&a, "bearer s3cret"));
    assert_true(vx_auth_ok(&a, "BEARER    s3cret"));
    assert_false(vx_auth_ok(&a, NULL));
    assert_false(vx_auth_ok(&a, ""));
    assert_false(vx_auth_ok(&a, "s3cret"));
    assert_false(vx_auth_ok(&a, "Basic s3cret"));
    assert_false(vx_auth_ok(&a, "Bearer s3cre"));
    /* the header value's trailing blanks are not part of it (RFC 9110 5.5) */
    assert_true(vx_auth_ok(&a, "Bearer s3cret "));
    assert_true(vx_auth_ok(&a, "Bearer s3cret\t "));
    assert_false(vx_auth_ok(&a, "Bearer s3cret x"));
    assert_false(vx_auth_ok(&a, "Bearer   "));
    assert_false(vx_auth_ok(&a, "Bearer S3CRET"));
    assert_false(vx_auth_ok(&a, "Bearer"));
}

static void test_no_token(void **state)
{
    (void)state;
    vx_auth a;
    vx_auth_init(&a, "");
    assert_false(a.on);
    vx_auth_init(&a, NULL);
    assert_false(a.on);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bearer),
        cmocka_unit_test(test_no_token),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
