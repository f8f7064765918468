// Wavefront OBJ reader.
//
// Chunks are whole lines (io::next_line_chunk), extended so that a line continued with a trailing
// backslash never ends a chunk. parse() is a single pass over the chunk, one statement per logical line:
//   v x y z [...]          position (extra values such as w or r g b are ignored)
//   f a b c [...]          polygon, split by io::add_face (n-gons triangulated in their plane at ingest);
//                          corners v, v/vt, v//vn or v/vt/vn; a two-corner face (an exporter's loose
//                          edge) becomes a line segment
//   l a b [...]            polyline, split into segments
//   p a [...]              points
//   o name / g name...     current object = the rest of the line, trimmed, comment removed
//   usemtl name            current material (io/mtl.h): every later f, l, p carries it
//   mtllib file...         material library, read in file order when resolve() meets it (io/mtl.h)
//   anything else          counted in `skipped` (vt, vn, ... and unknown exporter keywords)
// A '#' starts a comment (whole line or after a statement); a backslash right before a line break joins
// the next line to the statement (not to a whole-line comment); bytes below 0x20 other than tab, CR, LF,
// FF and VT are an error.
//
// Vertex references are encoded by parse() so that resolve(), which knows how many vertices the earlier
// chunks had, can finish them cheaply:
//   absolute index a (1-based)           -> a - 1                       (>= 0)
//   relative index r < 0, after k        -> kRelBias + k + r            (< 0)
//   vertices parsed in this chunk
// resolve() turns the second form into base + k + r. Errors that only resolve() or finish() can see
// (relative index before the first vertex, index past the last vertex) are located by parsing the
// chunk's byte range again, serially, with a check on every reference.
//
// Object ids: parse() numbers the objects of a chunk locally: 0 = the object current when the chunk
// starts, i >= 1 = the object of the i-th o/g statement of the chunk, named in out->object_names[i - 1].
// resolve() maps names to global ids in order of first appearance. usemtl and mtllib statements take a
// local id too (as if they were objects), their name marked by a first byte that no name can hold (control
// bytes are an error): kMaterialMark, kLibraryMark; resolve() keeps per local id the pair (object,
// material), so that add_face and the statements' object ids need not know about materials.
// Materials: id 0 is the material of what comes before any usemtl (core::Material's defaults); names get
// ids in order of first use. When the file has no usemtl, materials() is empty and nothing changes.
//
// Repeated corners are recognised by their encoded references, so a face naming one vertex once by an
// absolute and once by a relative index is not seen as repeating it; ingest then finds the repeat in the
// global ids and keeps that face's fan (dropping its triangles that name a vertex twice).
#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <system_error>
#include <unordered_map>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core/status.h"
#include "io/mtl.h"
#include "io/reader.h"
#include "io/text.h"

namespace lodstream::io {
namespace {

constexpr int64_t kRelBias = std::numeric_limits<int64_t>::min() / 2;  // -2^62
constexpr int kMaxIndexDigits = 18;                                    // |index| < 10^18 < 2^60
constexpr int64_t kEndMask = (int64_t(1) << 56) - 1;                   // reader_state: chunk end offset
constexpr int64_t kHasRelative = int64_t(1) << 60;                     // reader_state: relative refs seen
constexpr char kMaterialMark = '\x01', kLibraryMark = '\x02';

inline bool is_blank(char c) { return text::is_blank(c); }
inline bool is_digit(char c) { return static_cast<unsigned char>(c - '0') < 10; }
// A byte that has no business in a text file: below 0x20 and not a tab or line break.
inline bool is_control(unsigned char c) {
  return c < 0x20 && c != '\t' && c != '\n' && c != '\r' && c != '\f' && c != '\v';
}

// Pointer to the '\n' ending the physical line at p (or end). *bad is set to the first control byte met
// before it, if any, and that byte is returned.
inline const char* find_eol(const char* p, const char* end, const char** bad) {
#if defined(__SSE2__)
  const __m128i limit = _mm_set1_epi8(0x1F);
  while (end - p >= 16) {
    const __m128i x = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
    unsigned mask = static_cast<unsigned>(_mm_movemask_epi8(_mm_cmpeq_epi8(_mm_min_epu8(x, limit), x)));
    while (mask) {
      const int i = __builtin_ctz(mask);
      const unsigned char c = static_cast<unsigned char>(p[i]);
      if (c == '\n') return p + i;
      if (is_control(c)) {
        *bad = p + i;
        return p + i;
      }
      mask &= mask - 1;
    }
    p += 16;
  }
#endif
  for (; p < end; ++p) {
    const unsigned char c = static_cast<unsigned char>(*p);
    if (c < 0x20) {
      if (c == '\n') return p;
      if (is_control(c)) {
        *bad = p;
        return p;
      }
    }
  }
  return end;
}

// If p (pointing at a backslash) continues the line, returns the position after the line break (or end,
// for a backslash ending the data); else nullptr.
inline const char* continuation(const char* p, const char* end) {
  const char* q = p + 1;
  if (q < end && *q == '\r') ++q;
  if (q == end) return end;
  return *q == '\n' ? q + 1 : nullptr;
}

std::string printable(std::string_view s) {
  std::string r;
  for (char c : s.substr(0, 40)) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      static const char* const hex = "0123456789abcdef";
      r += "\\x";
      r += hex[(static_cast<unsigned char>(c) >> 4) & 15];
      r += hex[c & 15];
    } else {
      r += c;
    }
  }
  if (s.size() > 40) r += "...";
  return r;
}

// What the serial re-parse looks for: the first reference that resolves before the first vertex (given
// the global vertex count `base` at the chunk start) or at or past `limit`.
struct Locate {
  int64_t base = 0;
  int64_t limit = std::numeric_limits<int64_t>::max();
  bool found = false;
  uint64_t line = 0;
  std::string message;
};

// One pass over one chunk. kLocate adds the Locate check on every reference.
template <bool kLocate>
class Parser {
 public:
  Parser(const char* data, const char* end, uint64_t offset, ParsedChunk* out, Locate* locate)
      : data_(data), end_(end), offset_(offset), out_(out), locate_(locate) {}

  // Returns false on error (out->error set) or, in locate mode, when the reference was found.
  bool run() {
    const char* p = data_;
    while (p < end_) {
      stmt_ = p;
      stmt_line_ = line_;
      while (p < end_ && is_blank(*p)) ++p;
      if (p == end_) break;
      const char c = *p;
      if (c == '\n') {
        ++p;
        ++line_;
        continue;
      }
      if (c == '#') {  // whole-line comment: no continuation
        const char* bad = nullptr;
        p = find_eol(p, end_, &bad);
        if (bad) return binary(bad);
      } else if (is_sep(p + 1)) {
        switch (c) {
          case 'v': p = vertex(p + 1); break;
          case 'f': p = face(p + 1); break;
          case 'l': p = polyline(p + 1); break;
          case 'p': p = point(p + 1); break;
          case 'o':
          case 'g': p = object(p + 1); break;
          default: p = skip(p); break;
        }
        if (!p) return false;
      } else if (keyword(p, "usemtl")) {
        p = object(p + 6, kMaterialMark);
        if (!p) return false;
      } else if (keyword(p, "mtllib")) {
        p = object(p + 6, kLibraryMark);
        if (!p) return false;
      } else {
        p = skip(p);
        if (!p) return false;
      }
      // p is at the '\n' ending the statement, or at end.
      if (p < end_) {
        ++p;
        ++line_;
      }
    }
    out_->newlines = line_ - 1;
    return true;
  }

  bool has_relative() const { return has_relative_; }

 private:
  // Blank, line end, comment, continuation or end of data: what may follow a token.
  bool is_sep(const char* p) const {
    if (p >= end_) return true;
    const char c = *p;
    return is_blank(c) || c == '\n' || c == '#' || (c == '\\' && continuation(p, end_));
  }

  bool keyword(const char* p, const char (&word)[7]) const {
    return end_ - p > 6 && std::memcmp(p, word, 6) == 0 && is_sep(p + 6);
  }

  // Skips blanks and line continuations.
  const char* skip_ws(const char* p) {
    for (;;) {
      while (p < end_ && is_blank(*p)) ++p;
      if (p < end_ && *p == '\\') {
        const char* q = continuation(p, end_);
        if (q) {
          if (q[-1] == '\n') ++line_;
          p = q;
          continue;
        }
      }
      return p;
    }
  }

  // The rest of a statement, continuation lines included: returns its final '\n' (or end), nullptr on
  // a control byte.
  const char* rest(const char* p) {
    for (;;) {
      const char* bad = nullptr;
      const char* e = find_eol(p, end_, &bad);
      if (bad) return binary(bad), nullptr;
      if (e == end_) return e;
      const char* q = e;
      if (q > p && q[-1] == '\r') --q;
      if (q > p && q[-1] == '\\') {
        ++line_;
        p = e + 1;
        continue;
      }
      return e;
    }
  }

  // Records the first error of the chunk. If the statement holds a control byte, that is the problem.
  bool error(const char* at, std::string message) {
    if (out_->error.set) return false;
    const char* bad = nullptr;
    const char* scan = stmt_;
    for (;;) {
      const char* e = find_eol(scan, end_, &bad);
      if (bad || e >= at || e == end_) break;
      scan = e + 1;
    }
    if (bad) {
      at = bad;
      char hex[8];
      std::snprintf(hex, sizeof(hex), "0x%02x", static_cast<unsigned char>(*bad));
      message = std::string("binary data in a text file (byte ") + hex + ")";
    }
    out_->error.set = true;
    out_->error.offset = offset_ + static_cast<uint64_t>(at - data_);
    out_->error.line = stmt_line_;
    out_->error.message = std::move(message);
    out_->newlines = text::count_newlines(data_, end_);
    return false;
  }
  bool binary(const char* at) { return error(at, "binary data in a text file"); }

  std::string_view token_at(const char* p) const {
    const char* e = p;
    while (e < end_ && !is_blank(*e) && *e != '\n') ++e;
    return {p, static_cast<size_t>(e - p)};
  }

  // A number at p (no leading blanks); accepts a leading '+'. Advances p.
  bool number(const char*& p, double* out) {
    const char* b = p;
    if (b < end_ && *b == '+') {
      ++b;
      if (b < end_ && (*b == '-' || *b == '+')) return false;
    }
    auto [q, ec] = std::from_chars(b, end_, *out, std::chars_format::general);
    if (ec == std::errc::result_out_of_range) {
      *out = text::out_of_range_value(b, q);  // underflow gives 0 or a denormal, overflow infinity
    } else if (ec != std::errc()) {
      return false;
    }
    if (!is_sep(q)) return false;
    p = q;
    return true;
  }

  // A signed decimal integer at p of at most kMaxIndexDigits digits. Advances p.
  bool integer(const char*& p, int64_t* out) const {
    const char* q = p;
    bool negative = false;
    if (q < end_ && (*q == '-' || *q == '+')) negative = *q++ == '-';
    const char* digits = q;
    uint64_t v = 0;  // wraps harmlessly on too many digits, which are rejected
    while (q < end_ && is_digit(*q)) v = v * 10 + static_cast<uint64_t>(*q++ - '0');
    if (q == digits || q - digits > kMaxIndexDigits) return false;
    *out = negative ? -static_cast<int64_t>(v) : static_cast<int64_t>(v);
    p = q;
    return true;
  }

  // A vertex reference v, v/vt, v//vn or v/vt/vn at p; stores the encoded vertex reference.
  bool reference(const char*& p, const char* what, int64_t* ref) {
    const char* b = p;
    int64_t v = 0, unused = 0;
    bool ok = integer(p, &v);
    if (ok && p < end_ && *p == '/') {
      ++p;
      if (p < end_ && *p == '/') {
        ++p;
        ok = integer(p, &unused);
      } else {
        ok = integer(p, &unused);
        if (ok && p < end_ && *p == '/') {
          ++p;
          ok = integer(p, &unused);
        }
      }
    }
    if (!ok || !is_sep(p)) {
      return error(b, std::string("bad vertex reference '") + printable(token_at(b)) + "' in '" + what + "' statement");
    }
    if (v > 0) {
      *ref = v - 1;
      if constexpr (kLocate) {
        if (*ref >= locate_->limit) {
          return found(std::string("vertex index ") + std::to_string(v) + " is past the last vertex (the file has " +
                       std::to_string(locate_->limit) + " vertices)");
        }
      }
    } else if (v < 0) {
      *ref = kRelBias + (vertices_ + v);
      has_relative_ = true;
      if constexpr (kLocate) {
        if (locate_->base + vertices_ + v < 0) {
          return found(std::string("relative vertex index ") + std::to_string(v) + " reaches before the first vertex");
        }
      }
    } else {
      return error(b, std::string("vertex index 0 in '") + what + "' statement (OBJ indices start at 1)");
    }
    return true;
  }

  bool found(std::string message) {
    locate_->found = true;
    locate_->line = stmt_line_;
    locate_->message = std::move(message);
    return false;
  }

  // After the last token of a statement: a comment or the line end.
  const char* finish_statement(const char* p) {
    if (p < end_ && *p == '#') return rest(p);
    return p;
  }

  bool at_statement_end(const char* p) const { return p >= end_ || *p == '\n' || *p == '#'; }

  const char* vertex(const char* p) {
    double xyz[3];
    for (int i = 0; i < 3; ++i) {
      p = skip_ws(p);
      if (at_statement_end(p)) {
        return error(p, "vertex has " + std::to_string(i) + " coordinate" + (i == 1 ? "" : "s") + ", needs 3"), nullptr;
      }
      if (!number(p, &xyz[i])) {
        return error(p, "bad vertex coordinate '" + printable(token_at(p)) + "'"), nullptr;
      }
    }
    if (!text::finite3(xyz)) return error(stmt_, "vertex coordinate is not finite"), nullptr;
    out_->positions.insert(out_->positions.end(), xyz, xyz + 3);
    ++vertices_;
    return rest(p);  // extra values (w, colours) are ignored
  }

  const char* face(const char* p) {
    std::vector<int64_t>& corners = out_->face_scratch;
    corners.clear();
    for (;;) {
      p = skip_ws(p);
      if (at_statement_end(p)) break;
      int64_t ref;
      if (!reference(p, "f", &ref)) return nullptr;
      corners.push_back(ref);
    }
    const size_t n = corners.size();
    if (n == 2) {
      // Exporters (Blender among them) write loose edges as two-corner faces: keep the edge as a line
      // segment rather than refuse real files or drop what the user gave.
      out_->lines.push_back(corners[0]);
      out_->lines.push_back(corners[1]);
      out_->line_objects.push_back(object_);
      return finish_statement(p);
    }
    if (n < 3) {
      return error(stmt_, "face with " + std::to_string(n) + " corner" + (n == 1 ? "" : "s") + " (needs at least 2)"),
             nullptr;
    }
    add_face(corners.data(), n, object_, &out_->triangles, out_);
    ++out_->polygons;
    return finish_statement(p);
  }

  const char* polyline(const char* p) {
    int64_t previous = 0;
    uint64_t count = 0;
    for (;;) {
      p = skip_ws(p);
      if (at_statement_end(p)) break;
      int64_t ref;
      if (!reference(p, "l", &ref)) return nullptr;
      if (count > 0) {
        out_->lines.push_back(previous);
        out_->lines.push_back(ref);
        out_->line_objects.push_back(object_);
      }
      previous = ref;
      ++count;
    }
    if (count < 2) {
      return error(stmt_, "line with " + std::to_string(count) + " vertex" + (count == 1 ? "" : "es") +
                              " (needs at least 2)"),
             nullptr;
    }
    return finish_statement(p);
  }

  const char* point(const char* p) {
    uint64_t count = 0;
    for (;;) {
      p = skip_ws(p);
      if (at_statement_end(p)) break;
      int64_t ref;
      if (!reference(p, "p", &ref)) return nullptr;
      out_->points.push_back(ref);
      out_->point_objects.push_back(object_);
      ++count;
    }
    if (count == 0) return error(stmt_, "point statement without vertices"), nullptr;
    return finish_statement(p);
  }

  // o / g: the object is named by the rest of the logical line, trimmed, without its comment.
  const char* object(const char* p, char mark = 0) {
    std::string name;
    if (mark) name += mark;
    while (p < end_ && *p != '\n') {
      const char c = *p;
      if (c == '#') {
        p = rest(p);
        if (!p) return nullptr;
        break;
      }
      if (c == '\\') {
        if (const char* q = continuation(p, end_)) {
          if (q[-1] == '\n') ++line_;
          name += ' ';
          p = q;
          continue;
        }
      }
      if (is_control(static_cast<unsigned char>(c))) return binary(p), nullptr;
      name += c;
      ++p;
    }
    size_t b = mark ? 1 : 0, e = name.size();
    while (b < e && is_blank(name[b])) ++b;
    while (e > b && is_blank(name[e - 1])) --e;
    out_->object_names.emplace_back(mark ? std::string(1, mark) + name.substr(b, e - b) : name.substr(b, e - b));
    object_ = static_cast<uint32_t>(out_->object_names.size());
    return p;
  }

  // Statements recognised and not used (vt, vn, usemtl, ...) and unknown keywords.
  const char* skip(const char* p) {
    ++out_->skipped;
    return rest(p);
  }

  const char* const data_;
  const char* const end_;
  const uint64_t offset_;
  ParsedChunk* const out_;
  Locate* const locate_;
  const char* stmt_ = nullptr;  // start of the current statement's line
  uint64_t line_ = 1;           // current line, 1-based within the chunk
  uint64_t stmt_line_ = 1;      // line of the current statement's start
  int64_t vertices_ = 0;        // vertices parsed so far in this chunk
  uint32_t object_ = 0;         // chunk-local object id
  bool has_relative_ = false;
};

// A chunk resolve() may need to parse again to locate an index past the last vertex: it references a
// vertex beyond those defined by its end.
struct ForwardChunk {
  uint64_t begin, end, first_line;
  int64_t base;     // global vertex count at the chunk start
  int64_t max_ref;  // largest 0-based reference in the chunk
};

class ObjReader final : public Reader {
 public:
  explicit ObjReader(const MappedFile& file) : Reader(file) { ids_.emplace(std::string(), 0u); }

  std::string format() const override { return "obj"; }

  bool next_chunk(uint64_t target_bytes, Chunk* chunk) override {
    if (!next_line_chunk(file_, &cursor_, target_bytes, chunk)) return false;
    // A statement continued with a backslash stays in one chunk.
    while (cursor_ < file_.size() && ends_with_continuation(chunk->bytes)) {
      Chunk more;
      next_line_chunk(file_, &cursor_, 1, &more);
      const uint64_t begin = chunk->bytes.begin();
      more.bytes.reset();
      chunk->bytes.reset();
      chunk->bytes = file_.map(begin, cursor_);
    }
    return true;
  }

  void parse(const Chunk& chunk, ParsedChunk* out) const override {
    const char* data = chunk.bytes.data();
    const uint64_t size = chunk.bytes.size();
    // Sized from the bytes (a vertex or a triangle line takes 20 bytes or more), never from the content.
    out->positions.reserve(size / 24 * 3);
    out->triangles.reserve(size / 48 * 3);
    out->triangle_objects.reserve(size / 48);
    Parser<false> parser(data, data + size, chunk.bytes.begin(), out, nullptr);
    parser.run();
    out->reader_state = static_cast<int64_t>(chunk.bytes.end()) | (parser.has_relative() ? kHasRelative : 0);
  }

  void resolve(ParsedChunk* chunk) override {
    const uint64_t begin = resolved_bytes_;
    const uint64_t end = static_cast<uint64_t>(chunk->reader_state & kEndMask);
    const uint64_t first_line = lines_before_ + 1;
    const int64_t base = vertices_before_;

    int64_t max_ref = -1;
    if (chunk->reader_state & kHasRelative) {
      int64_t min_ref = 0;
      auto convert = [&](std::vector<int64_t>& refs) {
        for (int64_t& r : refs) {
          if (r < 0) {
            r = base + (r - kRelBias);
            min_ref = std::min(min_ref, r);
          }
          max_ref = std::max(max_ref, r);
        }
      };
      convert(chunk->triangles);
      convert(chunk->lines);
      convert(chunk->points);
      if (min_ref < 0) {
        Locate locate;
        locate.base = base;
        relocate(begin, end, first_line, &locate);
      }
    } else {
      for (const auto* refs : {&chunk->triangles, &chunk->lines, &chunk->points}) {
        for (int64_t r : *refs) max_ref = std::max(max_ref, r);
      }
    }
    if (chunk->error.set) fail_at_line(file_, lines_before_ + chunk->error.line, chunk->error.message);

    const int64_t vertices = static_cast<int64_t>(chunk->positions.size() / 3);
    if (max_ref >= base + vertices && max_ref > forward_max_) {
      forward_.push_back(ForwardChunk{begin, end, first_line, base, max_ref});
      forward_max_ = max_ref;
    }

    // Objects and materials: local 0 = the state at the chunk start, i = after the i-th o/g/usemtl/mtllib.
    if (chunk->object_names.empty()) {
      if (!materials_.empty()) fill_materials(chunk, {current_material_});
      fill(chunk, current_object_);
    } else {
      local_.assign(1, current_object_);
      local_materials_.assign(1, current_material_);
      for (std::string& name : chunk->object_names) {
        if (!name.empty() && name[0] == kMaterialMark) {
          use_material(name.substr(1));
        } else if (!name.empty() && name[0] == kLibraryMark) {
          libraries_.read(file_.path(), name.substr(1));
        } else {
          auto [it, inserted] = ids_.try_emplace(name, static_cast<uint32_t>(object_names_.size()));
          if (inserted) object_names_.push_back(name);
          current_object_ = it->second;
        }
        local_.push_back(current_object_);
        local_materials_.push_back(current_material_);
      }
      if (!materials_.empty()) fill_materials(chunk, local_materials_);
      for (auto* ids : {&chunk->triangle_objects, &chunk->line_objects, &chunk->point_objects}) {
        for (uint32_t& id : *ids) id = local_[id];
      }
    }

    vertices_before_ += vertices;
    lines_before_ += chunk->newlines;
    resolved_bytes_ = end;
  }

  void finish(uint64_t vertex_records) override {
    // Libraries may come after the usemtl statements that name their materials: look names up at the end.
    for (size_t i = 1; i < materials_.size(); ++i) libraries_.find(materials_[i].name, &materials_[i]);
    const int64_t count = static_cast<int64_t>(vertex_records);
    for (const ForwardChunk& f : forward_) {
      if (f.max_ref < count) continue;
      Locate locate;
      locate.base = f.base;
      locate.limit = count;
      relocate(f.begin, f.end, f.first_line, &locate);
    }
  }

 private:
  static bool ends_with_continuation(const Window& w) {
    const char* d = w.data();
    uint64_t n = w.size();
    if (n < 2 || d[n - 1] != '\n') return false;
    --n;
    if (n >= 2 && d[n - 1] == '\r') --n;
    return d[n - 1] == '\\';
  }

  // The first usemtl creates material 0 (what came before it) and gives every earlier chunk's primitives
  // material 0 after the fact: ingest reads an empty material vector as all 0.
  void use_material(const std::string& name) {
    if (materials_.empty()) materials_.emplace_back();
    auto [it, inserted] = material_ids_.try_emplace(name, static_cast<uint32_t>(materials_.size()));
    if (inserted) {
      materials_.emplace_back();
      materials_.back().name = name;
    }
    current_material_ = it->second;
  }

  // Per primitive, its material from its chunk-local id (the primitives' object ids are still local here:
  // all 0 when the chunk names no object or material).
  static void fill_materials(ParsedChunk* chunk, const std::vector<uint32_t>& local) {
    auto fill_kind = [&](const std::vector<uint32_t>& objects, std::vector<uint32_t>& materials) {
      materials.resize(objects.size());
      for (size_t i = 0; i < objects.size(); ++i) materials[i] = local[objects[i]];
    };
    fill_kind(chunk->triangle_objects, chunk->triangle_materials);
    fill_kind(chunk->line_objects, chunk->line_materials);
    fill_kind(chunk->point_objects, chunk->point_materials);
  }

  static void fill(ParsedChunk* chunk, uint32_t id) {
    std::fill(chunk->triangle_objects.begin(), chunk->triangle_objects.end(), id);
    std::fill(chunk->line_objects.begin(), chunk->line_objects.end(), id);
    std::fill(chunk->point_objects.begin(), chunk->point_objects.end(), id);
  }

  // Parses [begin, end) again with the Locate check and throws at the first offending line.
  [[noreturn]] void relocate(uint64_t begin, uint64_t end, uint64_t first_line, Locate* locate) {
    const Window w = file_.map(begin, end);
    ParsedChunk scratch;
    Parser<true> parser(w.data(), w.data() + w.size(), begin, &scratch, locate);
    parser.run();
    if (locate->found) fail_at_line(file_, first_line - 1 + locate->line, locate->message);
    if (scratch.error.set) fail_at_line(file_, first_line - 1 + scratch.error.line, scratch.error.message);
    fail_at_line(file_, first_line, "vertex reference out of range");  // not reached
  }

  uint64_t cursor_ = 0;
  // resolve() state, in file order.
  uint64_t resolved_bytes_ = 0;
  uint64_t lines_before_ = 0;
  int64_t vertices_before_ = 0;
  uint32_t current_object_ = 0, current_material_ = 0;
  std::unordered_map<std::string, uint32_t> ids_, material_ids_;
  std::vector<uint32_t> local_materials_;
  MtlLibraries libraries_;
  std::vector<uint32_t> local_;
  std::vector<ForwardChunk> forward_;  // increasing max_ref
  int64_t forward_max_ = -1;
};

}  // namespace

std::unique_ptr<Reader> make_obj_reader(const MappedFile& file) { return std::make_unique<ObjReader>(file); }

}  // namespace lodstream::io
