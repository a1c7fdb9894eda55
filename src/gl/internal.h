/* Internals of the GL module shared by egl.c and program.c (and by tests
 * that need to build programs from strings). Not part of the gl.h contract. */
#ifndef VX_GL_INTERNAL_H
#define VX_GL_INTERNAL_H

#include "gl/gl.h"

/* One cached program: vertex+fragment (b != NULL) or compute (b == NULL). */
typedef struct vx_gl_prog_entry {
    char *a, *b;
    GLuint prog;
} vx_gl_prog_entry;

/* Deletes every cached program (the context must be current) and empties
 * the cache. egl.c calls it before destroying a context. */
void vx_gl_programs_clear(vx_gl *gl);

/* Cache storage lives in vx_gl (egl.c); program.c reaches it through these. */
vx_gl_prog_entry **vx_gl_prog_slots(vx_gl *gl, size_t **n, size_t **cap);

/* Compiles and links a program from source strings, uncached: a vertex +
 * fragment pair (cs NULL) or a compute shader (vs, fs NULL). `label` names
 * it in errors. Returns a program the caller owns (glDeleteProgram), or 0
 * with VX_EGPU "shader_build" carrying the GLSL info log. GL thread. */
GLuint vx_gl_program_from_source(const char *label, const char *vs, const char *fs, const char *cs,
                                 vx_err *err);

/* The EGL device index a desc asks for exactly, or -1 for the automatic
 * order (a zero-initialised desc). */
int vx_gl_desc_device(const vx_gl_desc *desc);

#endif
