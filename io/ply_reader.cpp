#include "core/status.h"
#include "io/reader.h"

namespace lodstream::io {
std::unique_ptr<Reader> make_ply_reader(const MappedFile& file) {
  fail(Status::usage, file.path() + ": ply reader not written yet");
}
}  // namespace lodstream::io
