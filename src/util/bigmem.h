/* Big zeroed buffers. Those of 4 MiB and more are mapped with transparent
 * huge pages asked for: a buffer written once, as a grid or an encoder's
 * scratch is, pays a first-touch fault per page, and in 4 KiB pages on a
 * virtual machine that is most of the work (32 MiB took 89 ms here, 2.6 ms
 * in 2 MiB pages). Any thread. */
#ifndef VX_BIGMEM_H
#define VX_BIGMEM_H

#include <stddef.h>

/* bytes of zeroed memory, or NULL; *mapped is what vx_bigmem_free needs
 * back (the length mapped, 0 when it came from calloc). */
void *vx_bigmem_alloc(size_t bytes, size_t *mapped);
/* Frees p (NULL is fine) given the *mapped vx_bigmem_alloc set. */
void vx_bigmem_free(void *p, size_t mapped);

#endif
