/* What the text mesh readers (OBJ, .bpt; numbers for OFF and ASCII PLY) share: number parsing
 * (locale-independent and correctly rounded) and line-numbered errors.
 * Private to src/mesh. */
#ifndef VX_MESH_TEXT_H
#define VX_MESH_TEXT_H

#include <stdarg.h>
#include <stddef.h>

#include "util/err.h"

/* Blanks within a line (not the newline). */
static inline int vx_mesh_is_blank(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/* Every error a line causes goes through here, so that each message starts
 * with the line number the client needs to find the problem: sets err to
 * "line N: <fmt, ap>" and logs `event` at debug level. Returns -1. */
int vx_mesh_line_fail(vx_err *err, size_t lineno, const char *event, vx_err_kind kind,
                      const char *code, const char *fmt, va_list ap);

/* Parses one decimal number token at p ([+-] digits [. digits] [e [+-]
 * digits], or inf/infinity/nan, which callers reject). The token must end
 * at whitespace or NUL. Returns the end of the token, or NULL when it is
 * not a number. Any thread. */
char *vx_mesh_parse_double(char *p, double *out);

#endif
