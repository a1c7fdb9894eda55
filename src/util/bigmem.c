/* Big zeroed buffers (bigmem.h). */
#include "util/bigmem.h"

#include <stdlib.h>
#include <sys/mman.h>

#define BIGMEM_MAP_MIN ((size_t)4 << 20)

void *vx_bigmem_alloc(size_t bytes, size_t *mapped)
{
    *mapped = 0;
    if (bytes < BIGMEM_MAP_MIN) return calloc(bytes ? bytes : 1, 1);
    void *p = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) return NULL;
#ifdef MADV_HUGEPAGE
    madvise(p, bytes, MADV_HUGEPAGE); /* a hint: without THP, small pages */
#endif
    *mapped = bytes;
    return p;
}

void vx_bigmem_free(void *p, size_t mapped)
{
    if (mapped)
        munmap(p, mapped);
    else
        free(p);
}
