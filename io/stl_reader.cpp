// STL, binary and ASCII. Both are triangle soups: parse() emits the three corners of every facet as nine
// doubles and the pipeline welds them by exact position afterwards. Facet normals are ignored.
//
// Binary: an 80-byte header, a uint32 LE facet count and 50-byte records (normal, three corners as
// float32 LE, a 2-byte attribute). open() checks that the count agrees with the file size, so chunks are
// cut by arithmetic at record boundaries and parse() is a straight conversion loop.
//
// ASCII: `solid name` / `facet normal ...` / `outer loop` / `vertex x y z` x3 / `endloop` / `endfacet` /
// `endsolid name`, keywords in any case, several solids per file (one object each, same name -> same
// object). Chunks end right after an `endfacet` line, so every chunk starts between two facets inside a
// solid (or at the start of the file); which solid that is becomes known only in resolve(), which walks
// the chunks in file order. Within a chunk, parse() encodes the object of each facet as 0 = "the solid
// open at the start of the chunk" and k >= 1 = out->object_names[k - 1] (a solid started in the chunk).
#include <bit>
#include <cstring>
#include <string>
#include <string_view>
#include <unordered_map>

#include "core/status.h"
#include "io/reader.h"
#include "io/text.h"

namespace lodstream::io {
namespace {

constexpr uint64_t kHeaderBytes = 84;
constexpr uint64_t kRecordBytes = 50;
// ASCII: bytes mapped past the target to find the next `endfacet` line (tiny in the fuzz build, so that
// small inputs need the window to grow).
#ifdef LODSTREAM_FUZZ_SMALL_WINDOWS
constexpr uint64_t kLookAheadBytes = 16;
constexpr uint64_t kMaxFacetBytes = 256;
#else
constexpr uint64_t kLookAheadBytes = 4096;
// A facet is seven short lines; no `endfacet` this far past the target means the file is not facets,
// and searching on would map (and make resident) the rest of a possibly huge file.
constexpr uint64_t kMaxFacetBytes = uint64_t{1} << 20;
#endif

inline uint32_t load_u32_le(const unsigned char* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  if constexpr (std::endian::native == std::endian::big) v = __builtin_bswap32(v);
  return v;
}

// "header says N triangles (B bytes) but the file has S bytes", or empty when the sizes agree or the
// file is too short to have a binary header.
std::string binary_size_mismatch(const MappedFile& file) {
  if (file.size() < kHeaderBytes) return {};
  const Window w = file.map(80, kHeaderBytes);
  const uint64_t count = load_u32_le(reinterpret_cast<const unsigned char*>(w.data()));
  const uint64_t implied = kHeaderBytes + kRecordBytes * count;
  if (implied == file.size()) return {};
  return "binary STL header says " + std::to_string(count) + " triangles (" + std::to_string(implied) +
         " bytes) but the file has " + std::to_string(file.size()) + " bytes";
}

// ---------------------------------------------------------------------------------------------------
// Binary

class BinaryStlReader final : public Reader {
 public:
  explicit BinaryStlReader(const MappedFile& file) : Reader(file) {}

  std::string format() const override { return "stl-binary"; }
  bool soup() const override { return true; }
  bool single_precision() const override { return true; }

  void open() override {
    if (file_.size() < kHeaderBytes) {
      fail_at_offset(file_, file_.size(),
                     "truncated binary STL: the file has " + std::to_string(file_.size()) +
                         " bytes, less than the 84-byte header (80-byte comment and triangle count)");
    }
    const std::string mismatch = binary_size_mismatch(file_);
    if (!mismatch.empty()) fail_at_offset(file_, 80, mismatch);
    records_ = (file_.size() - kHeaderBytes) / kRecordBytes;
    opened_ = true;
  }

  bool next_chunk(uint64_t target_bytes, Chunk* chunk) override {
    if (!opened_) open();
    if (next_record_ >= records_) return false;
    uint64_t n = target_bytes / kRecordBytes;
    if (n == 0) n = 1;
    n = std::min(n, records_ - next_record_);
    const uint64_t begin = kHeaderBytes + next_record_ * kRecordBytes;
    chunk->bytes = file_.map(begin, begin + n * kRecordBytes);
    chunk->section = 0;
    chunk->first_record = next_record_;
    chunk->record_count = n;
    chunk->first_line = 0;
    next_record_ += n;
    return true;
  }

  void parse(const Chunk& chunk, ParsedChunk* out) const override {
    const uint64_t n = chunk.bytes.size() / kRecordBytes;
    const auto* data = reinterpret_cast<const unsigned char*>(chunk.bytes.data());
    out->positions.resize(n * 9);
    out->triangle_objects.assign(n, 0);
    out->polygons = n;
    double* dst = out->positions.data();
    uint32_t bad = 0;
    for (uint64_t i = 0; i < n; ++i) {
      const unsigned char* rec = data + i * kRecordBytes + 12;
      uint32_t u[9];
      std::memcpy(u, rec, sizeof u);
      for (int k = 0; k < 9; ++k) {
        if constexpr (std::endian::native == std::endian::big) u[k] = __builtin_bswap32(u[k]);
        // Exponent bits all ones: infinity or NaN.
        bad |= static_cast<uint32_t>((u[k] & 0x7f800000u) == 0x7f800000u);
        dst[k] = static_cast<double>(std::bit_cast<float>(u[k]));
      }
      dst += 9;
    }
    if (bad) report_non_finite(chunk, out);
  }

  void resolve(ParsedChunk* chunk) override {
    if (chunk->error.set) fail_at_offset(file_, chunk->error.offset, chunk->error.message);
  }

 private:
  // The slow path, only when the fast loop saw a non-finite value: find the first one.
  void report_non_finite(const Chunk& chunk, ParsedChunk* out) const {
    const uint64_t n = chunk.bytes.size() / kRecordBytes;
    const double* pos = out->positions.data();
    for (uint64_t i = 0; i < n; ++i) {
      for (int corner = 0; corner < 3; ++corner) {
        const double* v = pos + i * 9 + corner * 3;
        if (text::finite3(v)) continue;
        const uint64_t facet = chunk.first_record + i;
        out->error.set = true;
        out->error.offset = chunk.bytes.begin() + i * kRecordBytes;
        out->error.line = 0;
        out->error.message = "non-finite coordinate (" + std::to_string(v[0]) + ", " + std::to_string(v[1]) +
                             ", " + std::to_string(v[2]) + ") in vertex " + std::to_string(corner + 1) +
                             " of facet " + std::to_string(facet) + " (0-based)";
        return;
      }
    }
  }

  uint64_t records_ = 0;
  uint64_t next_record_ = 0;
  bool opened_ = false;
};

// ---------------------------------------------------------------------------------------------------
// ASCII

inline char lower(char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c; }

// Case-insensitive comparison with a lower-case literal.
inline bool keyword_is(std::string_view token, std::string_view lower_literal) {
  if (token.size() != lower_literal.size()) return false;
  for (size_t i = 0; i < token.size(); ++i)
    if (lower(token[i]) != lower_literal[i]) return false;
  return true;
}

inline bool has_binary(const char* p, const char* end) {
  for (; p < end; ++p)
    if (!text::is_text_byte(static_cast<unsigned char>(*p))) return true;
  return false;
}

// A token quoted for a message: at most 40 bytes, control bytes as \xNN.
std::string quote(std::string_view token) {
  static const char* const hex = "0123456789abcdef";
  std::string s = "'";
  const size_t n = std::min<size_t>(token.size(), 40);
  for (size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(token[i]);
    if (c >= 0x20 && c < 0x7f) {
      s += static_cast<char>(c);
    } else {
      s += "\\x";
      s += hex[c >> 4];
      s += hex[c & 15];
    }
  }
  if (token.size() > n) s += "...";
  s += "'";
  return s;
}

// True when the line [b, nl) is `endfacet` with optional blanks around it. `b` is a line start.
bool is_endfacet_line(const char* b, const char* nl) {
  const char* e = nl;
  while (e > b && text::is_blank(e[-1])) --e;
  if (e - b < 8) return false;
  const char* k = e - 8;
  if (!keyword_is(std::string_view(k, 8), "endfacet")) return false;
  while (k > b && text::is_blank(k[-1])) --k;
  return k == b;
}

class AsciiStlReader final : public Reader {
 public:
  explicit AsciiStlReader(const MappedFile& file) : Reader(file) {
    object_names_.clear();  // filled with the solids as they appear
    binary_hint_ = binary_size_mismatch(file);
  }

  std::string format() const override { return "stl-ascii"; }
  bool soup() const override { return true; }
  bool single_precision() const override { return true; }

  // Cuts right after the first `endfacet` line that ends at or past cursor + target_bytes - 1, or at the
  // end of the file: every chunk holds whole facets (at least one, when there is one).
  bool next_chunk(uint64_t target_bytes, Chunk* chunk) override {
    const uint64_t size = file_.size();
    const uint64_t begin = cursor_;
    if (begin >= size) return false;
    if (target_bytes == 0) target_bytes = 1;
    const uint64_t rest = size - begin;
    uint64_t cut = size;
    Window bytes;
    bool mapped = false;
    if (target_bytes < rest) {
      uint64_t scan = begin + target_bytes - 1;  // first byte where the cutting '\n' may be
      uint64_t want = target_bytes + kLookAheadBytes;
      for (;;) {
        const uint64_t end = want < rest ? begin + want : size;
        Window w = file_.map(begin, end);
        const char* d = w.data();
        bool found = false;
        while (scan < end) {
          const void* nl = std::memchr(d + (scan - begin), '\n', static_cast<size_t>(end - scan));
          if (!nl) {
            scan = end;
            break;
          }
          const auto* nlp = static_cast<const char*>(nl);
          const void* prev = memrchr(d, '\n', static_cast<size_t>(nlp - d));
          const char* line_begin = prev ? static_cast<const char*>(prev) + 1 : d;
          scan = begin + static_cast<uint64_t>(nlp - d) + 1;
          if (is_endfacet_line(line_begin, nlp)) {
            found = true;
            break;
          }
        }
        if (found) {
          cut = scan;
          if (cut == end) {
            bytes = std::move(w);
            mapped = true;
          }
          break;
        }
        if (end == size) break;  // no endfacet to the end of the file: take it all
        if (want >= target_bytes + kMaxFacetBytes) {
          // Cut at the window's last line break: parse reports the facet that does not end.
          const void* last = memrchr(d, '\n', static_cast<size_t>(end - begin));
          if (last) {
            cut = begin + static_cast<uint64_t>(static_cast<const char*>(last) - d) + 1;
            break;
          }
        }
        want = want > rest ? rest : want * 2;
      }
    }
    chunk->bytes = mapped ? std::move(bytes) : file_.map(begin, cut);
    chunk->section = 0;
    chunk->first_record = 0;
    chunk->record_count = 0;
    chunk->first_line = 0;
    cursor_ = cut;
    return true;
  }

  void parse(const Chunk& chunk, ParsedChunk* out) const override;

  void resolve(ParsedChunk* chunk) override {
    if (chunk->error.set) fail_at_line(file_, line_base_ + chunk->error.line - 1, chunk->error.message);
    // Local object codes -> global ids: 0 is the solid open at the chunk's start.
    local_to_global_.clear();
    local_to_global_.push_back(current_object_);
    for (const std::string& name : chunk->object_names) {
      auto [it, inserted] = ids_.try_emplace(name, static_cast<uint32_t>(object_names_.size()));
      if (inserted) object_names_.push_back(name);
      local_to_global_.push_back(it->second);
    }
    current_object_ = local_to_global_.back();
    if (object_names_.empty() && !chunk->triangle_objects.empty()) object_names_.emplace_back();  // defensive
    for (uint32_t& o : chunk->triangle_objects) o = local_to_global_[o];
    line_base_ += chunk->newlines;
  }

  void finish(uint64_t) override {
    if (object_names_.empty()) object_names_.emplace_back();
  }

 private:
  enum class State { outside, solid, facet, loop, endloop };

  uint64_t cursor_ = 0;
  uint64_t line_base_ = 1;  // global line number of the next chunk's first line
  uint32_t current_object_ = 0;
  std::unordered_map<std::string, uint32_t> ids_;
  std::vector<uint32_t> local_to_global_;
  std::string binary_hint_;  // set when the file also has a (mismatching) binary STL header
};

void AsciiStlReader::parse(const Chunk& chunk, ParsedChunk* out) const {
  const char* p = chunk.bytes.data();
  const char* const end = p + chunk.bytes.size();
  const uint64_t base = chunk.bytes.begin();
  const bool at_eof = chunk.bytes.end() == file_.size();
  State state = base == 0 ? State::outside : State::solid;
  uint32_t object = 0;  // local object code of the open solid
  double corners[9];
  int vertices = 0;
  uint64_t line = 0;
  uint64_t facet_line = 0, facet_offset = 0;
  const char* line_begin = p;

  auto error = [&](std::string message) {
    out->error.set = true;
    out->error.offset = base + static_cast<uint64_t>(line_begin - chunk.bytes.data());
    out->error.line = line;
    out->error.message = std::move(message);
  };
  auto binary_error = [&]() {
    std::string m = "binary data in an ASCII STL";
    if (!binary_hint_.empty()) m += " (read as binary, its " + binary_hint_ + ")";
    error(std::move(m));
  };
  auto expected = [&]() -> std::string {
    switch (state) {
      case State::outside: return "expected 'solid'";
      case State::solid: return "expected 'facet' or 'endsolid'";
      case State::facet: return "expected 'outer loop'";
      case State::loop: return vertices < 3 ? "expected 'vertex'" : "expected 'endloop'";
      case State::endloop: return "expected 'endfacet'";
    }
    return {};
  };
  // Nothing but blanks may follow a keyword that takes no arguments.
  auto only_blanks = [&](const char* q, const char* le) {
    q = text::skip_blanks(q, le);
    if (q == le) return true;
    if (has_binary(q, le)) {
      binary_error();
    } else {
      const char* t = q;
      error("unexpected " + quote(text::next_token(t, le)) + " at the end of the line");
    }
    return false;
  };

  while (p < end) {
    line_begin = p;
    const char* le = text::line_end(p, end);
    ++line;
    const char* q = p;
    const std::string_view keyword = text::next_token(q, le);
    if (!keyword.empty()) {
      if (keyword_is(keyword, "vertex")) {
        if (state != State::loop) return error("unexpected 'vertex', " + expected());
        if (vertices == 3) return error("facet has more than 3 vertices");
        double* v = corners + vertices * 3;
        for (int k = 0; k < 3; ++k) {
          const char* before = q;
          if (!text::parse_double(q, le, v + k)) {
            if (has_binary(before, le)) return binary_error();
            const char* t = before;
            const std::string_view bad = text::next_token(t, le);
            return error(bad.empty() ? "vertex has " + std::to_string(k) + " coordinates, expected 3"
                                     : "bad vertex coordinate " + quote(bad));
          }
        }
        if (!only_blanks(q, le)) return;
        if (!text::finite3(v)) return error("non-finite vertex coordinate");
        ++vertices;
      } else if (keyword_is(keyword, "facet")) {
        if (state == State::outside) return error("'facet' outside a solid, expected 'solid'");
        if (state != State::solid) return error("unexpected 'facet', " + expected());
        if (has_binary(q, le)) return binary_error();  // the normal itself is ignored
        state = State::facet;
        vertices = 0;
        facet_line = line;
        facet_offset = base + static_cast<uint64_t>(line_begin - chunk.bytes.data());
      } else if (keyword_is(keyword, "outer")) {
        if (state != State::facet) return error("unexpected 'outer', " + expected());
        const char* t = q;
        if (!keyword_is(text::next_token(t, le), "loop")) return error("expected 'outer loop'");
        if (!only_blanks(t, le)) return;
        state = State::loop;
      } else if (keyword_is(keyword, "endloop")) {
        if (state != State::loop) return error("unexpected 'endloop', " + expected());
        if (vertices != 3) return error("facet has " + std::to_string(vertices) + " vertices, expected 3");
        if (!only_blanks(q, le)) return;
        state = State::endloop;
      } else if (keyword_is(keyword, "endfacet")) {
        if (state != State::endloop) return error("unexpected 'endfacet', " + expected());
        if (!only_blanks(q, le)) return;
        out->positions.insert(out->positions.end(), corners, corners + 9);
        out->triangle_objects.push_back(object);
        ++out->polygons;
        state = State::solid;
      } else if (keyword_is(keyword, "solid")) {
        if (state == State::solid) return error("'solid' inside a solid (missing 'endsolid')");
        if (state != State::outside) return error("unexpected 'solid', " + expected());
        const char* b = text::skip_blanks(q, le);
        const char* e = le;
        while (e > b && text::is_blank(e[-1])) --e;
        if (has_binary(b, e)) return binary_error();
        out->object_names.emplace_back(b, static_cast<size_t>(e - b));
        object = static_cast<uint32_t>(out->object_names.size());
        state = State::solid;
      } else if (keyword_is(keyword, "endsolid")) {
        if (state == State::outside) return error("'endsolid' without a matching 'solid'");
        if (state != State::solid) return error("unexpected 'endsolid', " + expected());
        if (has_binary(q, le)) return binary_error();  // the name is not checked against the solid's
        state = State::outside;
      } else {
        if (has_binary(line_begin, le)) return binary_error();
        return error("unexpected " + quote(keyword) + ", " + expected());
      }
    } else if (has_binary(q, le)) {
      return binary_error();
    }
    if (le == end) break;
    ++out->newlines;
    p = le + 1;
  }

  if (state == State::facet || state == State::loop || state == State::endloop) {
    // Chunks end after an `endfacet` line or at the end of the file, so this is a truncated file.
    line = facet_line;
    line_begin = chunk.bytes.data() + (facet_offset - base);
    error(at_eof ? "the file ends inside this facet (no 'endfacet')"
                 : "no 'endfacet' within " + std::to_string(kMaxFacetBytes) + " bytes of this facet");
  }
}

}  // namespace

std::unique_ptr<Reader> make_stl_reader(const MappedFile& file, bool ascii) {
  if (ascii) return std::make_unique<AsciiStlReader>(file);
  return std::make_unique<BinaryStlReader>(file);
}

}  // namespace lodstream::io
