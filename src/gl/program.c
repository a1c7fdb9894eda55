/* Programs built from the embedded shaders (gl.h), cached per context.
 *
 * The cache is a plain array: an engine uses a handful of programs, and a
 * linear scan of a few names costs nothing next to a draw call. */
#include "gl/internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"

static const char *stage_name(GLenum type)
{
    switch (type) {
    case GL_VERTEX_SHADER:
        return "vertex";
    case GL_FRAGMENT_SHADER:
        return "fragment";
    case GL_COMPUTE_SHADER:
        return "compute";
    default:
        return "other";
    }
}

/* Reads an info log into a malloc'd string (never NULL unless out of memory). */
static char *info_log(GLuint obj, int is_program)
{
    GLint n = 0;
    if (is_program)
        glGetProgramiv(obj, GL_INFO_LOG_LENGTH, &n);
    else
        glGetShaderiv(obj, GL_INFO_LOG_LENGTH, &n);
    if (n < 1) n = 1;
    char *s = calloc((size_t)n + 1, 1);
    if (!s) return NULL;
    if (is_program)
        glGetProgramInfoLog(obj, n, NULL, s);
    else
        glGetShaderInfoLog(obj, n, NULL, s);
    /* Drivers end logs with newlines; the error message is one line. */
    size_t len = strlen(s);
    while (len && (s[len - 1] == '\n' || s[len - 1] == ' '))
        s[--len] = 0;
    return s;
}

static int build_fail(vx_err *err, const char *label, const char *what, const char *log)
{
    char q[1500];
    VX_ERROR("gl.shader_build", "program=%s stage=%s log=%s", label, what,
             vx_log_quote(q, sizeof q, log ? log : ""));
    return vx_err_set(err, VX_EGPU, "shader_build", "shader %s: %s failed: %s", label, what,
                      log && log[0] ? log : "(no log)");
}

static GLuint compile(const char *label, GLenum type, const char *src, vx_err *err)
{
    GLuint sh = glCreateShader(type);
    if (!sh) {
        build_fail(err, label, stage_name(type), "glCreateShader returned 0");
        return 0;
    }
    /* The sources carry their own "#version 450 core": nothing is prepended,
     * so line numbers in the log match the .glsl file. */
    glShaderSource(sh, 1, &src, NULL);
    glCompileShader(sh);
    GLint ok = 0;
    glGetShaderiv(sh, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char *log = info_log(sh, 0);
        char what[48];
        snprintf(what, sizeof what, "%s compile", stage_name(type));
        build_fail(err, label, what, log);
        free(log);
        glDeleteShader(sh);
        return 0;
    }
    return sh;
}

GLuint vx_gl_program_from_source(const char *label, const char *vs, const char *fs, const char *cs,
                                 vx_err *err)
{
    GLuint sh[2] = {0, 0};
    int nsh = 0;
    if (cs) {
        if (!(sh[nsh++] = compile(label, GL_COMPUTE_SHADER, cs, err))) return 0;
    } else {
        if (!vs || !fs) {
            vx_err_set(err, VX_EINTERNAL, "shader_build", "shader %s: need vs+fs or cs", label);
            return 0;
        }
        if (!(sh[nsh++] = compile(label, GL_VERTEX_SHADER, vs, err))) return 0;
        if (!(sh[nsh++] = compile(label, GL_FRAGMENT_SHADER, fs, err))) {
            glDeleteShader(sh[0]);
            return 0;
        }
    }
    GLuint prog = glCreateProgram();
    for (int i = 0; i < nsh; i++)
        glAttachShader(prog, sh[i]);
    glLinkProgram(prog);
    /* Shaders are not needed once linked; detaching lets the driver free them. */
    for (int i = 0; i < nsh; i++) {
        glDetachShader(prog, sh[i]);
        glDeleteShader(sh[i]);
    }
    GLint ok = 0;
    glGetProgramiv(prog, GL_LINK_STATUS, &ok);
    if (!ok) {
        char *log = info_log(prog, 1);
        build_fail(err, label, "link", log);
        free(log);
        glDeleteProgram(prog);
        return 0;
    }
    return prog;
}

/* The embedded source `name` with each line `#include "other"` replaced by
 * the embedded source `other` (one level; the included text has no
 * #version) and a #line that puts the log's line numbers back on the
 * including file's. malloc'd; NULL when a name is unknown (copied into
 * missing) or out of memory (missing empty). */
static char *expand(const char *name, char missing[64])
{
    const char *src = vx_shader_source(name);
    snprintf(missing, 64, "%s", name);
    if (!src) return NULL;
    missing[0] = 0;
    size_t cap = strlen(src) + 1, len = 0;
    char *out = malloc(cap);
    if (!out) return NULL;
    int line = 1;
    for (const char *p = src; *p;) {
        const char *eol = strchr(p, '\n');
        size_t n = eol ? (size_t)(eol - p) + 1 : strlen(p);
        char inc[64];
        const char *add = p;
        size_t addn = n;
        char tail[32] = "";
        if (sscanf(p, "#include \"%63[^\"]\"", inc) == 1) {
            if (!(add = vx_shader_source(inc))) {
                snprintf(missing, 64, "%s", inc);
                free(out);
                return NULL;
            }
            addn = strlen(add);
            snprintf(tail, sizeof tail, "\n#line %d\n", line + 1);
        }
        size_t need = len + addn + strlen(tail) + 1;
        if (need > cap) {
            while (cap < need)
                cap *= 2;
            char *q = realloc(out, cap);
            if (!q) {
                free(out);
                return NULL;
            }
            out = q;
        }
        memcpy(out + len, add, addn);
        len += addn;
        memcpy(out + len, tail, strlen(tail));
        len += strlen(tail);
        p += n;
        line++;
    }
    out[len] = 0;
    return out;
}

static GLuint cached(vx_gl *gl, const char *a, const char *b, vx_err *err)
{
    size_t *n, *cap;
    vx_gl_prog_entry **slots = vx_gl_prog_slots(gl, &n, &cap);
    for (size_t i = 0; i < *n; i++) {
        vx_gl_prog_entry *e = &(*slots)[i];
        if (strcmp(e->a, a) == 0 && ((!b && !e->b) || (b && e->b && strcmp(e->b, b) == 0)))
            return e->prog;
    }

    char missing[64];
    char *sa = expand(a, missing), *sb = NULL;
    if (sa && b) sb = expand(b, missing);
    if (!sa || (b && !sb)) {
        free(sa);
        if (!missing[0]) {
            vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for shader %s", a);
            return 0;
        }
        VX_ERROR("gl.shader_missing", "shader=%s", missing);
        vx_err_set(err, VX_EGPU, "shader_missing", "no embedded shader named %s (shaders/%s.glsl)",
                   missing, missing);
        return 0;
    }
    char label[160];
    if (b)
        snprintf(label, sizeof label, "%s+%s", a, b);
    else
        snprintf(label, sizeof label, "%s", a);
    GLuint prog = b ? vx_gl_program_from_source(label, sa, sb, NULL, err)
                    : vx_gl_program_from_source(label, NULL, NULL, sa, err);
    free(sa);
    free(sb);
    if (!prog) return 0;

    if (*n == *cap) {
        size_t nc = *cap ? 2 * *cap : 8;
        vx_gl_prog_entry *p = realloc(*slots, nc * sizeof *p);
        if (!p) goto oom;
        *slots = p;
        *cap = nc;
    }
    vx_gl_prog_entry *e = &(*slots)[*n];
    e->a = strdup(a);
    e->b = b ? strdup(b) : NULL;
    if (!e->a || (b && !e->b)) {
        free(e->a);
        free(e->b);
        goto oom;
    }
    e->prog = prog;
    (*n)++;
    return prog;
oom:
    glDeleteProgram(prog);
    vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the program cache");
    return 0;
}

GLuint vx_gl_program(vx_gl *gl, const char *vs, const char *fs, vx_err *err)
{
    if (!vs || !fs) {
        vx_err_set(err, VX_EINTERNAL, "shader_missing", "vx_gl_program needs two shader names");
        return 0;
    }
    return cached(gl, vs, fs, err);
}

GLuint vx_gl_compute_program(vx_gl *gl, const char *cs, vx_err *err)
{
    if (!cs) {
        vx_err_set(err, VX_EINTERNAL, "shader_missing", "vx_gl_compute_program needs a name");
        return 0;
    }
    return cached(gl, cs, NULL, err);
}

void vx_gl_programs_clear(vx_gl *gl)
{
    size_t *n, *cap;
    vx_gl_prog_entry **slots = vx_gl_prog_slots(gl, &n, &cap);
    for (size_t i = 0; i < *n; i++) {
        glDeleteProgram((*slots)[i].prog);
        free((*slots)[i].a);
        free((*slots)[i].b);
    }
    *n = 0;
}

GLuint vx_gl_position_vao(GLuint vbo, GLuint ibo)
{
    GLuint vao = 0;
    glCreateVertexArrays(1, &vao);
    glVertexArrayVertexBuffer(vao, 0, vbo, 0, 3 * sizeof(float));
    glVertexArrayAttribFormat(vao, 0, 3, GL_FLOAT, GL_FALSE, 0);
    glVertexArrayAttribBinding(vao, 0, 0);
    glEnableVertexArrayAttrib(vao, 0);
    if (ibo) glVertexArrayElementBuffer(vao, ibo);
    return vao;
}
