/* Number parsing shared by the text mesh readers (OBJ, .bpt): private to
 * src/mesh. Locale-independent and correctly rounded. */
#ifndef VX_MESH_TEXT_H
#define VX_MESH_TEXT_H

/* Parses one decimal number token at p ([+-] digits [. digits] [e [+-]
 * digits], or inf/infinity/nan, which callers reject). The token must end
 * at whitespace or NUL. Returns the end of the token, or NULL when it is
 * not a number. Any thread. */
char *vx_mesh_parse_double(char *p, double *out);

#endif
