#include "core/status.h"
#include "io/reader.h"

namespace lodstream::io {
std::unique_ptr<Reader> make_obj_reader(const MappedFile& file) {
  fail(Status::usage, file.path() + ": obj reader not written yet");
}
}  // namespace lodstream::io
