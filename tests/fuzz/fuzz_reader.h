/* The body the mesh-reader fuzz targets share: run a reader on the input
 * from a memory stream (no file size: storage must grow with the data,
 * never with a declared count). Oracle: no crash, no leak, no allocation
 * beyond what the limits and the input allow (libFuzzer's -malloc_limit_mb),
 * a failure that says why, and a mesh that comes back is consistent: the
 * triangle limit kept, at least one triangle, every triangle and patch
 * index in range. */
#ifndef VX_FUZZ_READER_H
#define VX_FUZZ_READER_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "mesh/mesh.h"

typedef vx_mesh *(*fuzz_reader_fn)(FILE *f, const vx_mesh_limits *lim, vx_err *err);

/* The oracle on what a reader gave back under lim; frees m. */
static inline void fuzz_reader_check(vx_mesh *m, const vx_mesh_limits *lim, const vx_err *err)
{
    if (m) {
        if (m->ntris > lim->max_triangles || !m->ntris) abort();
        for (size_t t = 0; t < 3 * m->ntris; t++)
            if (m->tri[t] >= m->nverts) abort();
        for (size_t k = 0; k < 16 * m->npatches; k++)
            if (m->patch_idx[k] >= m->nverts) abort();
    } else if (err->kind == VX_EOK) {
        abort();
    }
    vx_mesh_free(m);
}

/* A format of mesh/import.cc (STL, PLY, glTF, glb, OFF) read from memory, as the
 * daemon does after reading the whole upload. */
static inline int fuzz_reader_run_mem(const uint8_t *data, size_t size, vx_mesh_format fmt)
{
    vx_mesh_limits lim = {.max_triangles = 1u << 20};
    vx_err err;
    vx_err_clear(&err);
    fuzz_reader_check(vx_import_read_mem(data, size, fmt, &lim, &err), &lim, &err);
    return 0;
}

static inline int fuzz_reader_run(const uint8_t *data, size_t size, fuzz_reader_fn read)
{
    FILE *f = fmemopen((void *)data, size, "rb");
    if (!f) return 0;
    vx_mesh_limits lim = {.max_triangles = 1u << 20};
    vx_err err;
    vx_err_clear(&err);
    vx_mesh *m = read(f, &lim, &err);
    fclose(f);
    if (m) {
        if (m->ntris > lim.max_triangles || !m->ntris) abort();
        for (size_t t = 0; t < 3 * m->ntris; t++)
            if (m->tri[t] >= m->nverts) abort();
        for (size_t k = 0; k < 16 * m->npatches; k++)
            if (m->patch_idx[k] >= m->nverts) abort();
    } else if (err.kind == VX_EOK) {
        abort();
    }
    vx_mesh_free(m);
    return 0;
}

#endif
