// PLY reader: ascii, binary_little_endian and binary_big_endian, any elements in any order.
//
// open() parses the header (io/ply_header.h) into element layouts and rejects counts the file cannot hold.
// next_chunk() cuts whole records of one element at a time: by arithmetic for fixed-size binary records, by
// walking the list counts for variable-size binary records, and by lines for ascii. parse() turns vertex records
// into positions (and, with red, green, blue [alpha] properties, colours: integer values clamped to 0..255,
// float values as 0..1 scaled by 255 and rounded; no alpha is 255; vertex records of variable size, which
// hold a list, give no colour and ingest makes them white), face records into triangles and segments by io::add_face (PLY indices are absolute, so they are
// final after parse), edge records into lines, and only counts the records of any other element.
//
// Truncation and broken list counts are never thrown by next_chunk(): it hands parse() a chunk that claims
// one record more than the bytes hold, so the error is raised by resolve() in file order, after any earlier
// error, whatever the chunk size.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <unordered_map>
#include <type_traits>
#include <vector>

#include "core/status.h"
#include "io/ply_header.h"
#include "io/ply_types.h"
#include "io/reader.h"
#include "io/text.h"

namespace lodstream::io {
namespace {

// The splitter reads ahead through a window of about 8 chunks, kMinScanBytes to kMaxScanBytes; the header
// is read through a window that doubles from kHeaderBytes. The fuzz build (tools/fuzz) makes them tiny so
// that its small inputs cross window boundaries.
#ifdef LODSTREAM_FUZZ_SMALL_WINDOWS
constexpr uint64_t kMinScanBytes = 16, kMaxScanBytes = 64ull << 20, kHeaderBytes = 32;
#else
constexpr uint64_t kMinScanBytes = 4096, kMaxScanBytes = 64ull << 20, kHeaderBytes = 64 * 1024;
#endif

// ---------------------------------------------------------------------------------------------- types

using namespace ply;  // Type, type_size, ... (io/ply_types.h); Property, Role, quoted, ... (io/ply_header.h)


// ------------------------------------------------------------------------------------------- layout

enum class Kind : uint8_t { vertex, face, edge, other };

// A header element (name, count, properties with their roles and offsets, min_size) and how it is read.
struct Element : ply::Element {
  Kind kind = Kind::other;
  uint64_t record_size = 0;  // binary, fixed only
  int px = -1, py = -1, pz = -1, pv1 = -1, pv2 = -1;
  int pc[4] = {-1, -1, -1, -1};  // red, green, blue, alpha of a vertex or a face
  // Fast paths: vertex with x, y, z all float (1) or all double (2) in fixed records; face whose only
  // property is `list (u)char (u)int` (1 = int items, 2 = uint items).
  uint8_t fast_vertex = 0;
  uint8_t fast_face = 0;
};

bool has_binary_bytes(const char* p, const char* end) {
  for (; p < end; ++p)
    if (!text::is_text_byte(static_cast<unsigned char>(*p))) return true;
  return false;
}

std::string record_text(uint64_t k, const Element& e) {
  return "record " + std::to_string(k) + " of " + std::to_string(e.count) + " of element '" + e.name + "'";
}

void set_error(ParsedChunk* out, uint64_t offset, uint64_t line, std::string message) {
  if (out->error.set) return;
  out->error.set = true;
  out->error.offset = offset;
  out->error.line = line;
  out->error.message = std::move(message);
}

std::string not_finite_message(const double* v) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "vertex coordinate is not finite (%g, %g, %g)", v[0], v[1], v[2]);
  return buf;
}

std::string index_message(int64_t index, uint64_t vertex_count) {
  return "vertex index " + std::to_string(index) + " out of range: the file has " + std::to_string(vertex_count) +
         (vertex_count == 1 ? " vertex" : " vertices");
}

std::string small_face_message(uint64_t n) {
  return "face with " + std::to_string(n) + (n == 1 ? " vertex" : " vertices") + " (a face needs at least 2)";
}

enum class Rec : uint8_t { ok, truncated, negative_count };

// Face colours become materials; a file with more distinct ones is refused rather than written as that
// many primitives per level.
constexpr size_t kMaxFaceColors = 65536;

// A colour component from a property value: integers clamped to 0..255, floats 0..1 scaled and rounded.
uint8_t color_byte(double v, Type t) {
  if (t == Type::f32 || t == Type::f64) v *= 255;
  if (!(v > 0)) return 0;
  return v >= 255 ? 255 : static_cast<uint8_t>(std::lround(v));
}

// Walks one binary record at p (never past end), extracting what the element's roles ask for when
// Extract. On negative_count, p is left just past the offending count.
template <bool Swap, bool Extract>
inline Rec read_binary_record(const char*& p, const char* end, const Element& e, double* xyz, int64_t* v12,
                              std::vector<int64_t>* idx, uint8_t* rgba = nullptr) {
  for (const Property& pr : e.props) {
    if (pr.list) {
      const unsigned cs = type_size(pr.count_type);
      if (static_cast<size_t>(end - p) < cs) return Rec::truncated;
      const int64_t n = load_int<Swap>(p, pr.count_type);
      p += cs;
      if (n < 0) return Rec::negative_count;
      const unsigned is = type_size(pr.type);
      if (static_cast<uint64_t>(end - p) / is < static_cast<uint64_t>(n)) return Rec::truncated;
      if constexpr (Extract) {
        if (pr.role == Role::indices) {
          idx->clear();
          for (int64_t i = 0; i < n; ++i) idx->push_back(load_int<Swap>(p + i * is, pr.type));
        }
      }
      p += static_cast<uint64_t>(n) * is;
    } else {
      const unsigned s = type_size(pr.type);
      if (static_cast<size_t>(end - p) < s) return Rec::truncated;
      if constexpr (Extract) {
        switch (pr.role) {
          case Role::x: xyz[0] = load_double<Swap>(p, pr.type); break;
          case Role::y: xyz[1] = load_double<Swap>(p, pr.type); break;
          case Role::z: xyz[2] = load_double<Swap>(p, pr.type); break;
          case Role::v1: v12[0] = load_int<Swap>(p, pr.type); break;
          case Role::v2: v12[1] = load_int<Swap>(p, pr.type); break;
          case Role::red: case Role::green: case Role::blue: case Role::alpha:
            if (rgba) rgba[static_cast<int>(pr.role) - static_cast<int>(Role::red)] = color_byte(load_double<Swap>(p, pr.type), pr.type);
            break;
          default: break;
        }
      }
      p += s;
    }
  }
  return Rec::ok;
}

// Reads one ascii value of type t at p (within a line ending at e). Integers must be integers in range;
// float values are rounded to float as the file declares them.
enum class Val : uint8_t { ok, missing, bad, range };

inline Val ascii_value(const char*& p, const char* e, Type t, double* d, int64_t* i) {
  p = text::skip_blanks(p, e);
  if (p == e) return Val::missing;
  if (is_integer(t)) {
    int64_t v = 0;
    const char* q = p;
    if (!text::parse_int64(q, e, &v)) return Val::bad;
    if (q < e && !text::is_blank(*q)) return Val::bad;
    if (v < type_min(t) || v > type_max(t)) return Val::range;
    p = q;
    *i = v;
    *d = static_cast<double>(v);
    return Val::ok;
  }
  double v = 0;
  const char* q = p;
  if (!text::parse_double(q, e, &v)) return Val::bad;
  if (t == Type::f32) v = static_cast<double>(static_cast<float>(v));
  p = q;
  *d = v;
  *i = 0;
  return Val::ok;
}

class PlyReader final : public Reader {
 public:
  explicit PlyReader(const MappedFile& file) : Reader(file) { peek_format(); }

  std::string format() const override { return format_name(fmt_); }

  void open() override;
  bool single_precision() const override { return single_; }
  bool has_colors() const override { return colors_; }
  bool next_chunk(uint64_t target_bytes, Chunk* chunk) override;
  void parse(const Chunk& chunk, ParsedChunk* out) const override;
  void resolve(ParsedChunk* chunk) override;
  void finish(uint64_t vertex_records) override;

 private:
  using Fmt = ply::Format;

  void peek_format();
  void finalize_header(ply::Header&& header);
  [[noreturn]] void header_error(uint64_t line, const std::string& message) const {
    fail_at_line(file_, line, message);
  }

  // Splitting.
  const char* scan(uint64_t offset, uint64_t min_bytes);
  void cut_fixed(const Element& e, uint64_t target, Chunk* chunk);
  template <bool Swap>
  void cut_variable(const Element& e, uint64_t target, Chunk* chunk);
  void cut_ascii(const Element& e, uint64_t target, Chunk* chunk);
  // Ends a cut: [begin, end) holds `records` whole records, or, when `broken`, one more that parse() reports.
  void end_cut(Chunk* chunk, uint64_t begin, uint64_t end, uint64_t records, bool broken);

  // Parsing.
  template <bool Swap>
  void parse_binary(const Chunk& chunk, const Element& e, ParsedChunk* out) const;
  template <typename T, bool Swap>
  void fast_vertices(const char* p, uint64_t n, const Element& e, uint64_t base, ParsedChunk* out) const;
  template <typename T, bool Swap>
  void fast_faces(const Chunk& chunk, const Element& e, ParsedChunk* out) const;
  void parse_ascii(const Chunk& chunk, const Element& e, ParsedChunk* out) const;
  bool emit_face(int64_t* idx, uint64_t n, ParsedChunk* out, std::string* message) const;
  std::string truncation_message(const Element& e, uint64_t record, uint64_t offset) const;

  Fmt fmt_ = Fmt::ascii;
  bool opened_ = false;
  std::vector<Element> elements_;
  uint64_t data_start_ = 0;
  uint64_t data_line_ = 1;  // 1-based line of the first data byte (ascii)
  uint64_t header_lines_ = 0;
  uint64_t vertex_count_ = 0;
  int vertex_element_ = -1;
  bool single_ = false;  // x, y and z all of a type float holds exactly
  bool colors_ = false;  // the vertex element has red, green and blue
  // The face element has red, green and blue: each distinct face colour becomes a material (resolve()).
  // parse() puts the packed RGBA (r | g << 8 | b << 16 | a << 24) in the materials vectors.
  bool face_colors_ = false;
  std::unordered_map<uint32_t, uint32_t> color_material_;  // packed RGBA -> material id
  // Records `rgba` as the colour of the triangles and segments of `out` from index `triangles` / `lines`
  // (counts before the face was added) on.
  void face_color(const uint8_t* rgba, size_t triangles, size_t lines, ParsedChunk* out) const;
  // Appends the colours of `n` fixed-size vertex records at p.
  template <bool Swap>
  void fixed_colors(const char* p, uint64_t n, const Element& e, ParsedChunk* out) const;

  // Splitter state.
  size_t elem_ = 0;
  uint64_t rec_ = 0;     // records of elements_[elem_] already cut
  uint64_t cursor_ = 0;  // byte offset of the next record
  uint64_t line_ = 1;    // ascii: line of cursor_
  bool broken_ = false;  // the last chunk ends in a truncated or broken record: no more chunks
  Window scan_;          // read-ahead window of the splitter
  uint64_t scan_bytes_ = kMinScanBytes;
};

// ------------------------------------------------------------------------------------------- header

void PlyReader::peek_format() {
  // A lenient look at the format line so format() means something before open(); open() checks it.
  const Window w = file_.map(0, 4096);
  const std::string_view head = w.view();
  const size_t at = head.find("\nformat ");
  if (at == std::string_view::npos) return;
  const std::string_view rest = head.substr(at + 8, 24);
  if (rest.substr(0, 20) == "binary_little_endian") fmt_ = Fmt::le;
  else if (rest.substr(0, 17) == "binary_big_endian") fmt_ = Fmt::be;
}

// Takes the parsed header: gives the properties this reader knows their roles, checks them, and plans the
// fast paths.
void PlyReader::finalize_header(ply::Header&& header) {
  fmt_ = header.format;
  data_start_ = header.data_start;
  header_lines_ = header.lines;
  data_line_ = header.lines + 1;
  elements_.clear();
  for (ply::Element& d : header.elements) elements_.push_back(Element{std::move(d)});
  for (size_t k = 0; k < elements_.size(); ++k) {
    Element& e = elements_[k];
    auto find = [&](std::string_view name) -> int {
      for (size_t i = 0; i < e.props.size(); ++i)
        if (e.props[i].name == name) return static_cast<int>(i);
      return -1;
    };
    // Scalar red, green, blue (and alpha) of a vertex or face: true, with their roles set, when all three are.
    auto find_colors = [&]() -> bool {
      const char* names[4] = {"red", "green", "blue", "alpha"};
      const Role roles[4] = {Role::red, Role::green, Role::blue, Role::alpha};
      for (int c = 0; c < 4; ++c) {
        const int i = find(names[c]);
        if (i >= 0 && !e.props[i].list) e.pc[c] = i;
      }
      const bool rgb = e.pc[0] >= 0 && e.pc[1] >= 0 && e.pc[2] >= 0;
      for (int c = 0; c < 4 && rgb; ++c)
        if (e.pc[c] >= 0) e.props[e.pc[c]].role = roles[c];
      return rgb;
    };
    if (e.count > 0 && e.props.empty())
      header_error(e.header_line, "element " + quoted(e.name) + " has records but no properties");
    if (e.name == "vertex") {
      e.kind = Kind::vertex;
      vertex_element_ = static_cast<int>(k);
      vertex_count_ = e.count;
      const char* names[3] = {"x", "y", "z"};
      int* slots[3] = {&e.px, &e.py, &e.pz};
      const Role roles[3] = {Role::x, Role::y, Role::z};
      for (int c = 0; c < 3; ++c) {
        const int i = find(names[c]);
        if (i < 0) header_error(e.header_line, std::string("element 'vertex' has no property '") + names[c] + "'");
        if (e.props[i].list)
          header_error(e.header_line, std::string("property '") + names[c] + "' of element 'vertex' is a list");
        e.props[i].role = roles[c];
        *slots[c] = i;
      }
      colors_ = find_colors();
      single_ = true;
      for (int c = 0; c < 3; ++c) {
        const Type t = e.props[*slots[c]].type;
        if (t != Type::f32 && t != Type::i8 && t != Type::u8 && t != Type::i16 && t != Type::u16) single_ = false;
      }
    } else if (e.name == "face") {
      e.kind = Kind::face;
      int i = find("vertex_indices");
      if (i < 0) i = find("vertex_index");
      if (i < 0) header_error(e.header_line, "element 'face' has no list property 'vertex_indices'");
      Property& pr = e.props[i];
      if (!pr.list) header_error(e.header_line, "property " + quoted(pr.name) + " of element 'face' is not a list");
      if (!is_integer(pr.type))
        header_error(e.header_line, "face indices must have an integer type, not " + std::string(type_name(pr.type)));
      pr.role = Role::indices;
      face_colors_ = find_colors();
      if (face_colors_ && materials_.empty()) {
        // Material 0: edge elements and anything without a face colour (see resolve()).
        core::Material white;
        white.name = "default";
        materials_.push_back(white);
      }
    } else if (e.name == "edge") {
      const int a = find("vertex1"), b = find("vertex2");
      if (a >= 0 && b >= 0) {
        for (int i : {a, b})
          if (e.props[i].list || !is_integer(e.props[i].type))
            header_error(e.header_line, "property " + quoted(e.props[i].name) +
                                            " of element 'edge' must be a scalar integer");
        e.kind = Kind::edge;
        e.pv1 = a;
        e.pv2 = b;
        e.props[a].role = Role::v1;
        e.props[b].role = Role::v2;
      }
    }
    // Binary layout (offsets and min_size: io/ply_header.cpp).
    e.record_size = e.fixed ? e.min_size : 0;
    if (e.kind == Kind::vertex && e.fixed) {
      const Type t = e.props[e.px].type;
      if (e.props[e.py].type == t && e.props[e.pz].type == t)
        e.fast_vertex = t == Type::f32 ? 1 : t == Type::f64 ? 2 : 0;
    }
    if (e.kind == Kind::face && e.props.size() == 1 && type_size(e.props[0].count_type) == 1 &&
        (e.props[0].type == Type::i32 || e.props[0].type == Type::u32))
      e.fast_face = e.props[0].type == Type::i32 ? 1 : 2;
  }
  if (vertex_element_ < 0) header_error(header_lines_, "the PLY header declares no element 'vertex'");
  // Fast faces emit 32-bit ids (ParsedChunk::triangles32); beyond 2^32 vertices the general path keeps 64.
  if (vertex_count_ > (uint64_t{1} << 32))
    for (Element& e : elements_) e.fast_face = 0;

  // Counts the remaining bytes cannot hold: checked before any data is read, so a lying count costs nothing.
  ply::check_counts(file_, header, elements_);

  // An ascii header over binary data: say so instead of reporting garbage numbers.
  const uint64_t avail = file_.size() - data_start_;
  if (fmt_ == Fmt::ascii && avail > 0) {
    const Window w = file_.map(data_start_, data_start_ + std::min<uint64_t>(avail, 4096));
    const char* d = w.data();
    for (uint64_t i = 0; i < w.size(); ++i) {
      if (!text::is_text_byte(static_cast<unsigned char>(d[i]))) {
        char hex[8];
        std::snprintf(hex, sizeof hex, "0x%02x", static_cast<unsigned char>(d[i]));
        fail_at_offset(file_, data_start_ + i,
                       std::string("binary data (byte ") + hex +
                           ") in a file whose header says 'format ascii': is it binary PLY under a wrong header?");
      }
    }
  }
}

void PlyReader::open() {
  if (opened_) return;
  ply::Header header;
  for (uint64_t want = kHeaderBytes;; want *= 2) {
    const Window w = file_.map(0, want);
    if (ply::parse_header(file_, w.view(), w.end() >= file_.size(), &header)) break;
  }
  finalize_header(std::move(header));
  cursor_ = data_start_;
  line_ = data_line_;
  elem_ = 0;
  rec_ = 0;
  opened_ = true;
}

// ---------------------------------------------------------------------------------------- splitting

// A pointer to `offset` in the scan window, remapping it so that [offset, offset + min_bytes) is covered
// (or as much of it as the file holds).
const char* PlyReader::scan(uint64_t offset, uint64_t min_bytes) {
  const uint64_t want_end = std::min(file_.size(), offset + min_bytes);
  if (scan_.data() == nullptr || offset < scan_.begin() || want_end > scan_.end() ||
      (offset == scan_.end() && offset < file_.size())) {
    scan_.reset();
    scan_ = file_.map(offset, offset + std::max(min_bytes, scan_bytes_));
  }
  return scan_.data() + (offset - scan_.begin());
}

std::string PlyReader::truncation_message(const Element& e, uint64_t record, uint64_t offset) const {
  return std::string("truncated: the file ends ") + (offset >= file_.size() ? "before " : "inside ") +
         record_text(record, e);
}

bool PlyReader::next_chunk(uint64_t target_bytes, Chunk* chunk) {
  if (!opened_) open();
  if (broken_) return false;
  while (elem_ < elements_.size() && rec_ >= elements_[elem_].count) {
    ++elem_;
    rec_ = 0;
  }
  if (elem_ >= elements_.size()) {
    scan_.reset();
    return false;
  }
  if (target_bytes == 0) target_bytes = 1;
  scan_bytes_ = std::clamp(target_bytes < kMaxScanBytes / 8 ? 8 * target_bytes : kMaxScanBytes, kMinScanBytes,
                           kMaxScanBytes);
  const Element& e = elements_[elem_];
  chunk->section = static_cast<uint32_t>(elem_);
  chunk->first_record = rec_;
  chunk->first_line = 0;
  if (fmt_ == Fmt::ascii) cut_ascii(e, target_bytes, chunk);
  else if (e.fixed) cut_fixed(e, target_bytes, chunk);
  else if (fmt_ == Fmt::be) cut_variable<true>(e, target_bytes, chunk);
  else cut_variable<false>(e, target_bytes, chunk);
  return true;
}

void PlyReader::cut_fixed(const Element& e, uint64_t target, Chunk* chunk) {
  const uint64_t rs = e.record_size;
  const uint64_t left = e.count - rec_;
  uint64_t n = std::min(left, std::max<uint64_t>(1, target / rs));
  const uint64_t avail = (file_.size() - cursor_) / rs;
  if (avail == 0) {
    // Not one whole record left: a chunk claiming one record over the tail, for parse() to report.
    chunk->bytes = file_.map(cursor_, file_.size());
    chunk->record_count = 1;
    broken_ = true;
    return;
  }
  n = std::min(n, avail);
  chunk->bytes = file_.map(cursor_, cursor_ + n * rs);
  chunk->record_count = n;
  cursor_ += n * rs;
  rec_ += n;
}

template <bool Swap>
void PlyReader::cut_variable(const Element& e, uint64_t target, Chunk* chunk) {
  const uint64_t left = e.count - rec_;
  const uint64_t begin = cursor_;
  uint64_t o = begin;
  uint64_t k = 0;
  uint64_t need = 1;
  bool broken = false;
  uint64_t broken_end = 0;
  while (k < left) {
    const char* p0 = scan(o, need);
    const char* p = p0;
    const char* const wend = scan_.data() + scan_.size();
    const bool window_at_eof = scan_.end() >= file_.size();
    bool stop = false;
    if (e.fast_face) {
      // A single `list (u)char ...` property: hop from count to count. Runs of faces of one size (all
      // triangles, all quads) are confirmed 16 at a time with independent loads, not a chain of hops.
      const bool negative_ok = e.props[0].count_type == Type::u8;
      const uint64_t done_before = o - begin;
      while (k < left) {
        if (p >= wend) break;
        const unsigned n = static_cast<unsigned char>(*p);
        const uint64_t size = 1 + 4 * static_cast<uint64_t>(n);
        if (negative_ok || n <= 127) {
          constexpr uint64_t kRun = 16;
          bool run = false;
          while (left - k >= kRun && static_cast<uint64_t>(wend - p) >= kRun * size) {
            unsigned diff = 0;
            for (uint64_t j = 1; j < kRun; ++j) diff |= static_cast<unsigned char>(p[j * size]) ^ n;
            if (diff != 0) break;
            run = true;
            p += kRun * size;
            k += kRun;
            if (done_before + static_cast<uint64_t>(p - p0) >= target) break;
          }
          if (run) {
            if (done_before + static_cast<uint64_t>(p - p0) >= target) {
              stop = true;
              break;
            }
            continue;
          }
        }
        if (!negative_ok && n > 127) {
          broken = true;
          broken_end = o + static_cast<uint64_t>(p - p0) + 1;
          break;
        }
        if (static_cast<uint64_t>(wend - p) < size) break;
        p += size;
        ++k;
        if (done_before + static_cast<uint64_t>(p - p0) >= target) {
          stop = true;
          break;
        }
      }
    } else {
      while (k < left) {
        const char* q = p;
        const Rec r = read_binary_record<Swap, false>(q, wend, e, nullptr, nullptr, nullptr);
        if (r == Rec::truncated) break;
        if (r == Rec::negative_count) {
          broken = true;
          broken_end = o + static_cast<uint64_t>(q - p0);
          break;
        }
        p = q;
        ++k;
        if (static_cast<uint64_t>(o - begin) + static_cast<uint64_t>(p - p0) >= target) {
          stop = true;
          break;
        }
      }
    }
    o += static_cast<uint64_t>(p - p0);
    if (stop || broken || k == left) break;
    // The next record runs past the scan window: past the end of the file, or remap and go on.
    if (window_at_eof) {
      broken = true;
      broken_end = file_.size();
      break;
    }
    need = 2 * static_cast<uint64_t>(wend - p) + 1;
  }
  // A truncated record, or one with a negative list count: claim it, so parse() reports it.
  end_cut(chunk, begin, broken ? broken_end : o, k, broken);
}

void PlyReader::end_cut(Chunk* chunk, uint64_t begin, uint64_t end, uint64_t records, bool broken) {
  chunk->bytes = file_.map(begin, end);
  if (broken) {
    chunk->record_count = records + 1;
    broken_ = true;
    return;
  }
  chunk->record_count = records;
  cursor_ = end;
  rec_ += records;
}

void PlyReader::cut_ascii(const Element& e, uint64_t target, Chunk* chunk) {
  const uint64_t left = e.count - rec_;
  const uint64_t begin = cursor_;
  const uint64_t size = file_.size();
  uint64_t o = begin;
  uint64_t k = 0, lines = 0;
  uint64_t need = 1;
  while (k < left && o < size) {
    const char* p = scan(o, need);
    const char* const wend = scan_.data() + scan_.size();
    const bool window_at_eof = scan_.end() >= size;
    bool more = false;
    while (k < left && p < wend) {
      const char* nl = static_cast<const char*>(std::memchr(p, '\n', static_cast<size_t>(wend - p)));
      if (!nl && !window_at_eof) {
        // A line longer than what is left of the window: remap from its start.
        need = 2 * static_cast<uint64_t>(wend - p) + 1;
        more = true;
        break;
      }
      const char* le = nl ? nl : wend;
      if (text::skip_blanks(p, le) != le) ++k;
      p = nl ? nl + 1 : wend;
      if (nl) ++lines;
      o = scan_.begin() + static_cast<uint64_t>(p - scan_.data());
      if (o - begin >= target && k > 0) break;
    }
    if (!more && (k == left || (k > 0 && o - begin >= target) || o >= size)) break;
  }
  chunk->first_line = line_;
  // If the file ends before the element does, claim one record more for parse() to report.
  const bool broken = k < left && o >= size;
  end_cut(chunk, begin, broken ? size : o, k, broken);
  if (!broken) line_ += lines;
}

// ------------------------------------------------------------------------------------------ parsing

void PlyReader::parse(const Chunk& chunk, ParsedChunk* out) const {
  out->reader_state = static_cast<int64_t>(chunk.first_line);
  if (chunk.section >= elements_.size()) return;
  const Element& e = elements_[chunk.section];
  if (fmt_ == Fmt::ascii) parse_ascii(chunk, e, out);
  else if (fmt_ == Fmt::be) parse_binary<true>(chunk, e, out);
  else parse_binary<false>(chunk, e, out);
  out->triangle_objects.resize((out->triangles.size() + out->triangles32.size()) / 3, 0);
  out->line_objects.resize(out->lines.size() / 2, 0);  // edge elements and two-index faces
}

bool PlyReader::emit_face(int64_t* idx, uint64_t n, ParsedChunk* out, std::string* message) const {
  if (n < 2) {
    *message = small_face_message(n);
    return false;
  }
  for (uint64_t i = 0; i < n; ++i) {
    if (static_cast<uint64_t>(idx[i]) >= vertex_count_) {
      *message = index_message(idx[i], vertex_count_);
      return false;
    }
  }
  if (n == 2) {
    // A two-index face is an edge (as OBJ exporters write loose edges): kept as a line segment.
    out->lines.push_back(idx[0]);
    out->lines.push_back(idx[1]);
    return true;
  }
  add_face(idx, n, 0, &out->triangles, out);
  ++out->polygons;
  return true;
}

template <bool Swap>
void PlyReader::fixed_colors(const char* p, uint64_t n, const Element& e, ParsedChunk* out) const {
  const size_t at = out->colors.size();
  out->colors.resize(at + 4 * n, 255);  // no alpha property: 255
  uint8_t* rgba = out->colors.data() + at;
  for (uint64_t i = 0; i < n; ++i, p += e.record_size, rgba += 4)
    for (int c = 0; c < 4; ++c)
      if (e.pc[c] >= 0) {
        const Property& pr = e.props[e.pc[c]];
        rgba[c] = color_byte(load_double<Swap>(p + pr.offset, pr.type), pr.type);
      }
}

template <typename T, bool Swap>
void PlyReader::fast_vertices(const char* p, uint64_t n, const Element& e, uint64_t base, ParsedChunk* out) const {
  const uint64_t rs = e.record_size;
  const uint32_t ox = e.props[e.px].offset, oy = e.props[e.py].offset, oz = e.props[e.pz].offset;
  const bool packed = rs == 3 * sizeof(T) && ox == 0 && oy == sizeof(T) && oz == 2 * sizeof(T);
  // float coordinates go to the exact compact form (see ParsedChunk::positions32), doubles as they are.
  std::vector<T>* target;
  if constexpr (std::is_same_v<T, float>) target = &out->positions32;
  else target = &out->positions;
  std::vector<T>& pos = *target;
  pos.reserve(pos.size() + 3 * n);
  // Converted through a small buffer: appending whole batches avoids both a zero-filling resize and a
  // capacity check per value.
  constexpr uint64_t kBatch = 512;
  T buf[3 * kBatch];
  for (uint64_t i0 = 0; i0 < n; i0 += kBatch) {
    const uint64_t m = std::min(kBatch, n - i0);
    const char* r = p + i0 * rs;
    bool finite = true;
    if (packed) {
      // x y z are the whole record, in order: one flat conversion the compiler vectorizes.
      // Finiteness is tested on the bits (exponent all ones), which vectorizes where a float compare does not.
      using U = std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>;
      constexpr U kExponent = sizeof(T) == 4 ? U(0x7f800000u) : U(0x7ff0000000000000ull);
      U bad = 0;
      for (uint64_t j = 0; j < 3 * m; ++j) {
        const U u = load<U, Swap>(r + j * sizeof(T));
        T v;
        std::memcpy(&v, &u, sizeof v);
        buf[j] = v;
        bad |= static_cast<U>((u & kExponent) == kExponent);
      }
      finite = bad == 0;
    } else {
      for (uint64_t i = 0; i < m; ++i, r += rs) {
      const T x = load<T, Swap>(r + ox), y = load<T, Swap>(r + oy), z = load<T, Swap>(r + oz);
      buf[3 * i] = x;
      buf[3 * i + 1] = y;
      buf[3 * i + 2] = z;
      finite &= ((x - x) == 0) & ((y - y) == 0) & ((z - z) == 0);
      }
    }
    if (!finite) [[unlikely]] {
      for (uint64_t i = 0; i < m; ++i) {
        const double v[3] = {buf[3 * i], buf[3 * i + 1], buf[3 * i + 2]};
        if (!text::finite3(v)) {
          pos.insert(pos.end(), buf, buf + 3 * i);
          set_error(out, base + (i0 + i) * rs, 0, not_finite_message(v));
          return;
        }
      }
    }
    pos.insert(pos.end(), buf, buf + 3 * m);
  }
}

template <typename T, bool Swap>
void PlyReader::fast_faces(const Chunk& chunk, const Element& e, ParsedChunk* out) const {
  const char* const b = chunk.bytes.data();
  const char* const end = b + chunk.bytes.size();
  const uint64_t base = chunk.bytes.begin();
  const uint64_t rc = chunk.record_count;
  const uint64_t vc = vertex_count_;
  const bool signed_count = e.props[0].count_type == Type::i8;
  // Indices are checked against the vertex count here, so they go straight to the final compact form
  // (ParsedChunk::triangles32); the header check keeps fast faces for vertex counts that fit 32 bits.
  std::vector<uint32_t>& tri = out->triangles32;
  tri.reserve(tri.size() + 3 * rc);
  // Triangles go through a small buffer, appended a batch at a time (see fast_vertices).
  constexpr size_t kBatch = 3 * 512;
  uint32_t buf[kBatch + 3];
  size_t t = 0;
  const char* p = b;
  uint64_t i = 0, edges = 0;
  for (; i < rc; ++i) {
    if (t >= kBatch) {
      tri.insert(tri.end(), buf, buf + t);
      t = 0;
    }
    __builtin_prefetch(p + 1024);
    if (end - p >= 13 && *p == 3) {
      const int64_t a = load<T, Swap>(p + 1), c1 = load<T, Swap>(p + 5), c2 = load<T, Swap>(p + 9);
      if ((static_cast<uint64_t>(a) < vc) & (static_cast<uint64_t>(c1) < vc) & (static_cast<uint64_t>(c2) < vc) &
          (a != c1) & (c1 != c2) & (a != c2)) {
        buf[t] = static_cast<uint32_t>(a);
        buf[t + 1] = static_cast<uint32_t>(c1);
        buf[t + 2] = static_cast<uint32_t>(c2);
        t += 3;
        p += 13;
        continue;
      }
    }
    // Anything else: other sizes, truncation, bad counts and bad indices.
    const uint64_t offset = base + static_cast<uint64_t>(p - b);
    if (p >= end) {
      set_error(out, offset, 0, truncation_message(e, chunk.first_record + i + 1, offset));
      break;
    }
    const unsigned n = static_cast<unsigned char>(*p);
    if (signed_count && n > 127) {
      set_error(out, offset, 0, "negative list count " + std::to_string(static_cast<int>(static_cast<int8_t>(n))));
      break;
    }
    if (static_cast<uint64_t>(end - p - 1) / 4 < n) {
      set_error(out, offset, 0, truncation_message(e, chunk.first_record + i + 1, offset));
      break;
    }
    int64_t idx[255];
    for (unsigned j = 0; j < n; ++j) idx[j] = load<T, Swap>(p + 1 + 4 * j);
    if (n < 2) {
      set_error(out, offset, 0, small_face_message(n));
      break;
    }
    bool ok = true;
    for (unsigned j = 0; j < n; ++j) {
      if (static_cast<uint64_t>(idx[j]) >= vc) {
        set_error(out, offset, 0, index_message(idx[j], vc));
        ok = false;
        break;
      }
    }
    if (!ok) break;
    if (n == 2) {  // an edge, as in emit_face()
      out->lines.push_back(idx[0]);
      out->lines.push_back(idx[1]);
      ++edges;
      p += 9;
      continue;
    }
    // Quads, n-gons and faces repeating a vertex: split by add_face, after the batch (planar_faces
    // numbers the face's triangles in `tri`).
    tri.insert(tri.end(), buf, buf + t);
    t = 0;
    add_face(idx, n, 0, &tri, out);
    p += 1 + 4 * static_cast<uint64_t>(n);
  }
  tri.insert(tri.end(), buf, buf + t);
  out->polygons += i - edges;
}

template <bool Swap>
void PlyReader::parse_binary(const Chunk& chunk, const Element& e, ParsedChunk* out) const {
  const char* const b = chunk.bytes.data();
  const uint64_t bytes = chunk.bytes.size();
  const char* const end = b + bytes;
  const uint64_t base = chunk.bytes.begin();
  const uint64_t rc = chunk.record_count;

  if (e.fixed) {
    const uint64_t rs = e.record_size;
    const uint64_t complete = std::min(rc, bytes / rs);
    if (e.kind == Kind::vertex) {
      if (e.fast_vertex == 1) {
        fast_vertices<float, Swap>(b, complete, e, base, out);
      } else if (e.fast_vertex == 2) {
        fast_vertices<double, Swap>(b, complete, e, base, out);
      } else {
        const Property &px = e.props[e.px], &py = e.props[e.py], &pz = e.props[e.pz];
        for (uint64_t i = 0; i < complete; ++i) {
          const char* r = b + i * rs;
          const double v[3] = {load_double<Swap>(r + px.offset, px.type), load_double<Swap>(r + py.offset, py.type),
                               load_double<Swap>(r + pz.offset, pz.type)};
          if (!text::finite3(v)) {
            set_error(out, base + i * rs, 0, not_finite_message(v));
            return;
          }
          out->positions.insert(out->positions.end(), v, v + 3);
        }
      }
      if (colors_) fixed_colors<Swap>(b, (out->positions.size() + out->positions32.size()) / 3, e, out);
      if (out->error.set) return;
    } else if (e.kind == Kind::edge) {
      const Property &p1 = e.props[e.pv1], &p2 = e.props[e.pv2];
      for (uint64_t i = 0; i < complete; ++i) {
        const char* r = b + i * rs;
        const int64_t v[2] = {load_int<Swap>(r + p1.offset, p1.type), load_int<Swap>(r + p2.offset, p2.type)};
        for (int64_t x : v) {
          if (static_cast<uint64_t>(x) >= vertex_count_) {
            set_error(out, base + i * rs, 0, "edge " + index_message(x, vertex_count_));
            return;
          }
        }
        out->lines.push_back(v[0]);
        out->lines.push_back(v[1]);
      }
    } else {
      out->skipped += complete;
    }
    if (complete < rc) {
      const uint64_t offset = base + complete * rs;
      set_error(out, offset, 0, truncation_message(e, chunk.first_record + complete + 1, offset));
    }
    return;
  }

  if (e.fast_face == 1) return fast_faces<int32_t, Swap>(chunk, e, out);
  if (e.fast_face == 2) return fast_faces<uint32_t, Swap>(chunk, e, out);

  // Variable-size records, any element.
  std::vector<int64_t> idx;
  double xyz[3] = {0, 0, 0};
  int64_t v12[2] = {0, 0};
  std::string message;
  const char* p = b;
  for (uint64_t i = 0; i < rc; ++i) {
    const char* r = p;
    const uint64_t offset = base + static_cast<uint64_t>(r - b);
    uint8_t rgba[4] = {255, 255, 255, 255};
    const Rec st = read_binary_record<Swap, true>(p, end, e, xyz, v12, &idx, rgba);
    if (st == Rec::truncated) {
      set_error(out, offset, 0, truncation_message(e, chunk.first_record + i + 1, offset));
      return;
    }
    if (st == Rec::negative_count) {
      set_error(out, offset, 0, "negative list count in " + record_text(chunk.first_record + i + 1, e));
      return;
    }
    switch (e.kind) {
      case Kind::vertex:
        if (!text::finite3(xyz)) {
          set_error(out, offset, 0, not_finite_message(xyz));
          return;
        }
        out->positions.insert(out->positions.end(), xyz, xyz + 3);
        if (colors_) out->colors.insert(out->colors.end(), rgba, rgba + 4);
        break;
      case Kind::face: {
        const size_t t = out->triangles.size() / 3, l = out->lines.size() / 2;
        if (!emit_face(idx.data(), idx.size(), out, &message)) {
          set_error(out, offset, 0, message);
          return;
        }
        if (face_colors_) face_color(rgba, t, l, out);
        break;
      }
      case Kind::edge:
        for (int64_t x : v12) {
          if (static_cast<uint64_t>(x) >= vertex_count_) {
            set_error(out, offset, 0, "edge " + index_message(x, vertex_count_));
            return;
          }
        }
        out->lines.push_back(v12[0]);
        out->lines.push_back(v12[1]);
        break;
      case Kind::other: ++out->skipped; break;
    }
  }
}

void PlyReader::parse_ascii(const Chunk& chunk, const Element& e, ParsedChunk* out) const {
  const char* const b = chunk.bytes.data();
  const char* const end = b + chunk.bytes.size();
  const uint64_t base = chunk.bytes.begin();
  const uint64_t rc = chunk.record_count;
  std::vector<int64_t> idx;
  std::string message;
  const char* p = b;
  uint64_t line = 1, done = 0;
  while (p < end) {
    const char* const le = text::line_end(p, end);
    const char* q = text::skip_blanks(p, le);
    if (q != le) {
      const uint64_t offset = base + static_cast<uint64_t>(p - b);
      if (done == rc) {  // cannot happen with chunks cut by next_chunk()
        set_error(out, offset, line, "unexpected record after the records of element '" + e.name + "'");
        return;
      }
      auto fail_line = [&](std::string m) {
        if (has_binary_bytes(p, le))
          m = "binary data in an ascii PLY file (the header says 'format ascii'): " + m;
        set_error(out, offset, line, std::move(m));
      };
      double xyz[3] = {0, 0, 0};
      int64_t v12[2] = {0, 0};
      uint8_t rgba[4] = {255, 255, 255, 255};
      idx.clear();
      for (const Property& pr : e.props) {
        double d = 0;
        int64_t iv = 0;
        auto value = [&](Type t, const std::string& what) -> bool {
          const char* tok = text::skip_blanks(q, le);
          const Val r = ascii_value(q, le, t, &d, &iv);
          if (r == Val::ok) return true;
          if (r == Val::missing) {
            fail_line("too few values in " + record_text(chunk.first_record + done + 1, e) + ": no value for " + what);
          } else {
            const char* te = tok;
            while (te < le && !text::is_blank(*te)) ++te;
            fail_line(std::string(r == Val::range ? "value out of range for " : "bad value for ") + what + " (" +
                      type_name(t) + "): " + quoted(std::string_view(tok, static_cast<size_t>(te - tok))));
          }
          return false;
        };
        if (pr.list) {
          if (!value(pr.count_type, "the count of list '" + pr.name + "'")) return;
          if (iv < 0) {
            fail_line("negative list count " + std::to_string(iv) + " for list '" + pr.name + "'");
            return;
          }
          const int64_t n = iv;
          for (int64_t j = 0; j < n; ++j) {
            if (!value(pr.type, "item " + std::to_string(j + 1) + " of list '" + pr.name + "'")) return;
            if (pr.role == Role::indices) idx.push_back(iv);
          }
        } else {
          if (!value(pr.type, "property '" + pr.name + "'")) return;
          switch (pr.role) {
            case Role::x: xyz[0] = d; break;
            case Role::y: xyz[1] = d; break;
            case Role::z: xyz[2] = d; break;
            case Role::v1: v12[0] = iv; break;
            case Role::v2: v12[1] = iv; break;
            case Role::red: rgba[0] = color_byte(d, pr.type); break;
            case Role::green: rgba[1] = color_byte(d, pr.type); break;
            case Role::blue: rgba[2] = color_byte(d, pr.type); break;
            case Role::alpha: rgba[3] = color_byte(d, pr.type); break;
            default: break;
          }
        }
      }
      q = text::skip_blanks(q, le);
      if (q != le) {
        fail_line("extra values after the last property of element '" + e.name + "': " +
                  quoted(std::string_view(q, static_cast<size_t>(le - q))));
        return;
      }
      switch (e.kind) {
        case Kind::vertex:
          if (!text::finite3(xyz)) {
            set_error(out, offset, line, not_finite_message(xyz));
            return;
          }
          out->positions.insert(out->positions.end(), xyz, xyz + 3);
          if (colors_) out->colors.insert(out->colors.end(), rgba, rgba + 4);
          break;
        case Kind::face: {
          const size_t t = out->triangles.size() / 3, l = out->lines.size() / 2;
          if (!emit_face(idx.data(), idx.size(), out, &message)) {
            set_error(out, offset, line, message);
            return;
          }
          if (face_colors_) face_color(rgba, t, l, out);
          break;
        }
        case Kind::edge:
          for (int64_t x : v12) {
            if (static_cast<uint64_t>(x) >= vertex_count_) {
              set_error(out, offset, line, "edge " + index_message(x, vertex_count_));
              return;
            }
          }
          out->lines.push_back(v12[0]);
          out->lines.push_back(v12[1]);
          break;
        case Kind::other: ++out->skipped; break;
      }
      ++done;
    }
    if (le == end) break;
    p = le + 1;
    ++line;
  }
  out->newlines = line - 1;
  if (done < rc) {
    // Only the last chunk of a file that ends early claims a record it does not hold.
    set_error(out, base + chunk.bytes.size(), line,
              "truncated: the file ends before " + record_text(chunk.first_record + done + 1, e));
  }
}

// ---------------------------------------------------------------------------------- resolve, finish

void PlyReader::face_color(const uint8_t* rgba, size_t triangles, size_t lines, ParsedChunk* out) const {
  const uint32_t packed = rgba[0] | uint32_t{rgba[1]} << 8 | uint32_t{rgba[2]} << 16 | uint32_t{rgba[3]} << 24;
  // Every earlier primitive of a face chunk came from an earlier face, which filled its entries (edge
  // elements come in chunks of their own, whose empty line_materials mean material 0).
  out->triangle_materials.resize(triangles, 0);
  out->line_materials.resize(lines, 0);
  out->triangle_materials.resize(out->triangles.size() / 3, packed);
  out->line_materials.resize(out->lines.size() / 2, packed);
}

// Face colours become materials in order of first appearance in the file (resolve() runs in file order),
// so the table does not depend on the chunking. Segments of edge elements take material 0.
void PlyReader::resolve(ParsedChunk* chunk) {
  if (face_colors_ && !chunk->error.set) {
    for (std::vector<uint32_t>* v : {&chunk->triangle_materials, &chunk->line_materials}) {
      for (uint32_t& m : *v) {
        const auto [it, fresh] = color_material_.try_emplace(m, static_cast<uint32_t>(materials_.size()));
        if (fresh) {
          if (materials_.size() > kMaxFaceColors)
            fail(Status::bad_data, file_.path() + ": more than " + std::to_string(kMaxFaceColors) +
                                       " distinct face colours (each becomes a material)");
          core::Material c;
          char name[16];
          std::snprintf(name, sizeof name, "rgba_%02x%02x%02x%02x", m & 255, m >> 8 & 255, m >> 16 & 255, m >> 24);
          c.name = name;
          for (int k = 0; k < 4; ++k) c.base_color[k] = static_cast<float>((m >> (8 * k) & 255) / 255.0);
          if ((m >> 24) < 255) c.alpha = core::Material::Alpha::blend;
          materials_.push_back(c);
        }
        m = it->second;
      }
    }
  }
  const ParseError& err = chunk->error;
  if (!err.set) return;
  if (err.line != 0) fail_at_line(file_, static_cast<uint64_t>(chunk->reader_state) + err.line - 1, err.message);
  fail_at_offset(file_, err.offset, err.message);
}

void PlyReader::finish(uint64_t vertex_records) {
  if (broken_) fail_at_offset(file_, cursor_, "the data ends before the records the header declares");
  if (elem_ < elements_.size())
    fail_at_offset(file_, cursor_, "the data ends before " + record_text(rec_ + 1, elements_[elem_]));
  if (vertex_records != vertex_count_)
    fail_at_offset(file_, cursor_, "the file holds " + std::to_string(vertex_records) +
                                       " vertex records but the header declares " + std::to_string(vertex_count_));
  const uint64_t size = file_.size();
  if (cursor_ >= size) return;
  if (fmt_ != Fmt::ascii)
    fail_at_offset(file_, cursor_, std::to_string(size - cursor_) + " bytes after the last element");
  // Ascii: whitespace may follow the last record, nothing else.
  uint64_t line = line_;
  for (uint64_t o = cursor_; o < size;) {
    const Window w = file_.map(o, o + kMaxScanBytes);
    const char* d = w.data();
    for (uint64_t i = 0; i < w.size(); ++i) {
      if (d[i] == '\n') {
        ++line;
      } else if (!text::is_blank(d[i])) {
        fail_at_line(file_, line, "data after the last element the header declares (element '" +
                                      elements_.back().name + "' has " + std::to_string(elements_.back().count) +
                                      " records)");
      }
    }
    o = w.end();
  }
}

}  // namespace

std::unique_ptr<Reader> make_ply_reader(const MappedFile& file) { return std::make_unique<PlyReader>(file); }

}  // namespace lodstream::io
