/* libFuzzer target: the OBJ reader on arbitrary bytes (oracle: fuzz_reader.h). */
#include "fuzz_reader.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    return fuzz_reader_run(data, size, vx_obj_read_file);
}
