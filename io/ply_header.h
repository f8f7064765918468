// The PLY header (Greg Turk, "The PLY Polygon File Format", 1994), parsed once for both PLY readers: the
// ingest reader (io/ply_reader.cpp) and the LOD reader (io/lod_reader.cpp). Each reader then gives the
// properties it knows their roles and checks what it needs of the elements; the error messages of the
// header itself, and of counts the data cannot hold, are the same for both.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "io/mapped_file.h"
#include "io/ply_types.h"

namespace lodstream::io::ply {

enum class Format : uint8_t { ascii, le, be };

// "ply-ascii", "ply-binary-le" or "ply-binary-be".
const char* format_name(Format f);

// What a property means to a reader: set by the reader from the property's name, after the header is parsed.
enum class Role : uint8_t { none, x, y, z, indices, v1, v2, thickness, red, green, blue, alpha, material_index };

struct Property {
  std::string name;
  bool list = false;
  Type count_type = Type::none;  // lists only
  Type type = Type::none;        // scalar type, or the list's item type
  Role role = Role::none;
  uint32_t offset = 0;  // byte offset within a fixed-size binary record
};

struct Element {
  std::string name;
  uint64_t count = 0;
  uint64_t header_line = 0;  // 1-based line of the element line
  std::vector<Property> props;
  bool fixed = true;      // binary records of one size (no list property)
  uint64_t min_size = 0;  // binary: the smallest possible record (every list empty)
};

struct Header {
  Format format = Format::ascii;
  std::vector<Element> elements;
  uint64_t data_start = 0;  // byte offset of the first data byte
  uint64_t lines = 0;       // lines of the header, end_header included
};

// Where "the PLY header has no end_header line" is reported when the file ends inside the header: at its last
// line if that line has no line break (the ingest reader), or at the line after it in any case (the LOD reader).
enum class MissingEndLine : uint8_t { at_unterminated_last, after_last };

// Parses the header in `head`, the first bytes of `file`, into *out. Returns false when the header runs past
// the end of `head` and more of the file exists (`at_eof` false): call again with more. A malformed header
// throws Failure (Status::bad_data) as fail_at_line(file, LINE, ...) does.
bool parse_header(const MappedFile& file, std::string_view head, bool at_eof, Header* out,
                  MissingEndLine missing_end = MissingEndLine::at_unterminated_last);

// A header token or line for an error message: at most 40 bytes, unprintable bytes as '?'.
std::string quoted(std::string_view s);

// The check_counts() error for element `e`: records of at least `per` bytes, after `used` bytes of data.
[[noreturn]] void count_error(const MappedFile& file, const Header& header, const Element& e, uint64_t per,
                              uint64_t used);

// Rejects element counts the data after the header cannot hold, before any data is read or allocated: a
// binary record takes at least min_size bytes; an ascii record of k properties at least 2k (k one-character
// tokens, k-1 separators, a line end that the very last record may lack). `elements` are the header's, in
// file order, as the reader's own element type (derived from Element). Throws as fail_at_line() does.
template <typename E>
void check_counts(const MappedFile& file, const Header& header, const std::vector<E>& elements) {
  const bool binary = header.format != Format::ascii;
  const uint64_t avail = file.size() - header.data_start;
  uint64_t used = 0;
  for (const Element& e : elements) {
    if (e.count == 0) continue;
    const uint64_t per = binary ? e.min_size : 2 * e.props.size();
    const uint64_t room = avail - used + (binary ? 0 : 1);
    if (e.count > room / per) count_error(file, header, e, per, used);
    used += e.count * per;
  }
}

}  // namespace lodstream::io::ply
