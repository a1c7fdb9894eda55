/* libFuzzer target: the Draco reader (header check, then libdraco) on
 * arbitrary bytes, through the C API. Oracle: no crash, no leak, nothing
 * escaping from C++, no allocation beyond what the limits and the input
 * allow (-malloc_limit_mb: libdraco sizes its tables from the declared
 * counts, which vx_draco_check_header bounds), and a mesh that comes back is
 * consistent with the limits and its own indices. */
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
    vx_mesh *m = vx_draco_read_file(f, &lim, &err);
    fclose(f);
    if (m) {
        if (m->ntris > lim.max_triangles || !m->ntris) abort();
        for (size_t t = 0; t < 3 * m->ntris; t++)
            if (m->tri[t] >= m->nverts) abort();
    } else if (err.kind == VX_EOK) {
        abort();
    }
    vx_mesh_free(m);
    return 0;
}
