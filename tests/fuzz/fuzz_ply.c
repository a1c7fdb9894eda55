/* libFuzzer target: the PLY reader (ASCII, binary little and big endian) on arbitrary bytes: the
 * header-count check (mesh/declared.c), then voxeld's PLY reader, through the C API
 * (oracle: fuzz_reader.h). */
#include "fuzz_reader.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    return fuzz_reader_run_mem(data, size, VX_MESH_PLY);
}
