#include "core/status.h"
#include "io/reader.h"

namespace lodstream::io {
std::unique_ptr<Reader> make_stl_reader(const MappedFile& file, bool ascii) {
  fail(Status::usage, file.path() + ": stl reader not written yet");
}
}  // namespace lodstream::io
