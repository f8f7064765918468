// libFuzzer target for the STL reader: see fuzz_common.h for what is checked, README.md for how to run it.
#include "tools/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return lodstream::fuzz::fuzz_one("stl", data, size);
}
