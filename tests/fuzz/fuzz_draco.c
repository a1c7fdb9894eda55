/* libFuzzer target: the Draco reader (header check, then libdraco under its
 * decode-time allocation cap) on arbitrary bytes, through the C API
 * (oracle: fuzz_reader.h; nothing may escape from C++). */
#include "fuzz_reader.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    return fuzz_reader_run(data, size, vx_draco_read_file);
}
