// libFuzzer target for the glTF reader on GLB input (io/gltf_reader.cpp): see fuzz_common.h for what is
// checked, README.md for how to run it. The input is written as a .glb; a file that does not start with
// the magic is refused with its byte offset. Buffers naming external files resolve next to the input
// (normally missing, which must be a located bad_data error, never a crash).
#include "tools/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return lodstream::fuzz::fuzz_one("glb", data, size);
}
