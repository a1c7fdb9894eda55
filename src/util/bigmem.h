/* Big zeroed buffers. Those of 4 MiB and more are mapped with transparent
 * huge pages asked for: a buffer written once, as a grid or an encoder's
 * scratch is, pays a first-touch fault per page, and in 4 KiB pages on a
 * virtual machine that is most of the work (32 MiB took 89 ms here, 2.6 ms
 * in 2 MiB pages).
 *
 * Freed mappings can be kept for the next buffer (vx_bigmem_keep): a
 * virtual machine that hands freed memory back to its host (free page
 * reporting) faults every fresh page in again through the host, 1-3 ms a
 * 2 MiB page here, where clearing a kept one takes 0.2 ms. Any thread. */
#ifndef VX_BIGMEM_H
#define VX_BIGMEM_H

#include <stddef.h>

/* bytes of zeroed memory, or NULL; *mapped is what vx_bigmem_free needs
 * back (the length mapped, 0 when it came from calloc). */
void *vx_bigmem_alloc(size_t bytes, size_t *mapped);
/* As vx_bigmem_alloc, but the contents are undefined (a kept mapping is
 * handed out as it was left, not cleared): for scratch that is written
 * before it is read, reserved at the most it may take and touched as used
 * (clearing all of a kept one would touch all of it). */
void *vx_bigmem_scratch(size_t bytes, size_t *mapped);
/* Frees p (NULL is fine) given the *mapped vx_bigmem_alloc set: kept
 * mapped while the kept ones stay within vx_bigmem_keep's bytes, joined to
 * a kept piece beside it. A kept mapping serves any buffer it holds, a
 * long one its head only. */
void vx_bigmem_free(void *p, size_t mapped);
/* Keeps up to bytes of freed mappings (0, the default: none), unmapping
 * what is over it now. */
void vx_bigmem_keep(size_t bytes);
/* Bytes of freed mappings kept now. */
size_t vx_bigmem_kept(void);
/* Maps up to bytes (whole 2 MiB pages, within what vx_bigmem_keep leaves
 * room for), touches every page on all CPUs and keeps it, so that the
 * first buffers do not pay their first-touch faults either; the bytes
 * kept. */
size_t vx_bigmem_pretouch(size_t bytes);

#endif
