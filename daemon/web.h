/* The viewer's files built into the binary (viewer/embed.cmake generates
 * the table from viewer/, api/openapi.yaml and tools/viewer's npm
 * libraries); routes_web.c serves them. */
#ifndef VX_WEB_H
#define VX_WEB_H

#include <stddef.h>

typedef struct vx_web_file {
    const char *name;          /* e.g. "index.html", "three.core.min.js" */
    const unsigned char *data; /* len bytes (NUL after them) */
    size_t len;
    const char *ctype; /* its Content-Type */
    const char *etag;  /* a strong ETag, quotes included */
} vx_web_file;

/* The built-in file called name, or NULL. Static data; any thread. */
const vx_web_file *vx_web_find(const char *name);

#endif
