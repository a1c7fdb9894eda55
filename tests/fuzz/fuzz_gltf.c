/* libFuzzer target: the glTF 2.0 reader on arbitrary bytes, as glb when
 * they start with the glb magic and as glTF JSON otherwise: the JSON and
 * count checks (mesh/declared.c), then tinygltf under its allocation cap
 * and the scene walk (mesh/import.cc),
 * through the C API (oracle: fuzz_reader.h). */
#include <string.h>

#include "fuzz_reader.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    int glb = size >= 4 && !memcmp(data, "glTF", 4);
    return fuzz_reader_run_mem(data, size, glb ? VX_MESH_GLB : VX_MESH_GLTF);
}
