/* cmocka group fixture for tests that need the GL context: setup creates
 * it (automatic device choice) into vx_test_gl, teardown destroys it. */
#ifndef VX_GL_FIXTURE_H
#define VX_GL_FIXTURE_H

#include "gl/gl.h"

extern vx_gl *vx_test_gl;
int vx_test_gl_setup(void **state);
int vx_test_gl_teardown(void **state);

#endif
