/* libFuzzer target: the .bpt reader on arbitrary bytes, from a memory
 * stream (no file size: storage must grow with the data, never with a
 * declared count). Oracle: no crash, no leak, no allocation beyond what the
 * limits and the input allow (-malloc_limit_mb), and a mesh that comes back
 * is consistent: patch and face indices in range, the triangle limit kept. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "mesh/mesh.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    FILE *f = fmemopen((void *)data, size, "rb");
    if (!f) return 0;
    vx_mesh_limits lim = {.max_triangles = 1u << 20};
    vx_err err;
    vx_err_clear(&err);
    vx_mesh *m = vx_bpt_read_file(f, &lim, &err);
    fclose(f);
    if (m) {
        if (m->ntris > lim.max_triangles || !m->npatches) abort();
        for (size_t k = 0; k < 16 * m->npatches; k++)
            if (m->patch_idx[k] >= m->nverts) abort();
        for (size_t t = 0; t < 3 * m->ntris; t++)
            if (m->tri[t] >= m->nverts) abort();
    } else if (err.kind == VX_EOK) {
        abort(); /* a failure must say why */
    }
    vx_mesh_free(m);
    return 0;
}
