#include "gl_fixture.h"

#include <stdio.h>
#include <stdlib.h>

vx_gl *vx_test_gl;

int vx_test_gl_setup(void **state)
{
    (void)state;
    vx_err err = {0};
    /* VX_TEST_GL_DEBUG=1: a debug context, its KHR_debug messages in the log */
    vx_gl_desc d = {.debug = getenv("VX_TEST_GL_DEBUG") != NULL};
    vx_test_gl = vx_gl_new(&d, &err);
    if (!vx_test_gl) fprintf(stderr, "vx_gl_new: %s: %s\n", err.code, err.message);
    return vx_test_gl ? 0 : -1;
}

int vx_test_gl_teardown(void **state)
{
    (void)state;
    vx_gl_free(vx_test_gl);
    vx_test_gl = NULL;
    return 0;
}
