/* libFuzzer target: the .bpt reader on arbitrary bytes (oracle: fuzz_reader.h;
 * a .bpt mesh that comes back also has patches). */
#include "fuzz_reader.h"

static vx_mesh *read_bpt(FILE *f, const vx_mesh_limits *lim, vx_err *err)
{
    vx_mesh *m = vx_bpt_read_file(f, lim, err);
    if (m && !m->npatches) abort();
    return m;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    return fuzz_reader_run(data, size, read_bpt);
}
