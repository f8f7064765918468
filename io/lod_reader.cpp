// Whole-file reader for one level of detail (see io/lod_reader.h): PLY (Greg Turk, "The PLY Polygon File
// Format") and Wavefront OBJ, into core::LodMesh.
//
// The file is mapped once and parsed in one pass. Memory is the result's arrays: they are reserved from
// PLY header counts only after the counts are checked against the bytes the file holds (a record takes at
// least its fixed-size properties and list counts in binary, one character and a separator per property in
// ascii), and otherwise grow with the data. Indices are checked as they are read (PLY declares the vertex
// count up front); OBJ may refer to vertices defined later, so the few references that reach past the
// vertices read so far are remembered and checked at the end, reported at the first such line in file order.
//
// Coordinates and thicknesses are parsed straight to float where the file declares float (and in OBJ,
// whose writer prints the shortest decimal of a float), so they read back bit for bit; other types are
// converted once, and a value a float cannot hold is an error, not an infinity.
#include "io/lod_reader.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/status.h"
#include "io/mapped_file.h"
#include "io/ply_header.h"
#include "io/ply_types.h"
#include "io/reader.h"
#include "io/text.h"

namespace lodstream::io {
namespace {

constexpr uint64_t kMaxVertices = uint64_t{UINT32_MAX} + 1;  // ids must fit uint32

// Parses a number at p (no blanks skipped; a leading '+' accepted) as float, correctly rounded from the
// decimal, with no detour through double. Returns the end of the number, or nullptr if none starts there.
// Overflow gives infinity and underflow its rounded value (as text::parse_double).
const char* float_at(const char* p, const char* end, float* out) {
  if (p < end && *p == '+') ++p;
  const auto [q, ec] = std::from_chars(p, end, *out, std::chars_format::general);
  if (ec == std::errc::result_out_of_range) {
    *out = static_cast<float>(text::out_of_range_value(p, q));
    return q;
  }
  return ec == std::errc() ? q : nullptr;
}

using ply::quoted;  // a token for an error message (io/ply_header.h), in PLY and OBJ alike

std::string vertices_text(uint64_t n) { return std::to_string(n) + (n == 1 ? " vertex" : " vertices"); }

bool is_control(unsigned char c) { return c < 0x20 && c != '\t' && c != '\n' && c != '\r' && c != '\f' && c != '\v'; }

std::string control_message(unsigned char c) {
  char hex[8];
  std::snprintf(hex, sizeof hex, "0x%02x", c);
  return std::string("binary data in a text file (byte ") + hex + ")";
}

// ================================================================================================ PLY

using namespace ply;  // Type, type_size, ... (io/ply_types.h); Property, Role, ... (io/ply_header.h)


enum class Kind : uint8_t { vertex, face, edge, point, other };

// A header element (name, count, properties with their roles, min_size) and how it is read.
struct Element : ply::Element {
  Kind kind = Kind::other;
  unsigned index_size = 0;  // face: bytes of one index
  bool sized = false;       // point: has a size property (read through Role::thickness)
};

// A polygon being fan-triangulated as its indices arrive: (first, previous, current) per index after the
// second.
struct Fan {
  uint32_t first = 0, prev = 0;
  uint64_t n = 0;

  // The next index (in range): from the third on, the triangle (first, prev, v) goes to the mesh, or is
  // counted as degenerate if it repeats a vertex.
  void add(uint32_t v, core::LodMesh& mesh, LodFileStats& stats) {
    if (n >= 2) {
      if (first == prev || prev == v || first == v) {
        ++stats.degenerate_triangles;
      } else {
        const uint32_t t[3] = {first, prev, v};
        mesh.triangles.insert(mesh.triangles.end(), t, t + 3);
      }
    } else if (n == 0) {
      first = v;
    }
    prev = v;
    ++n;
  }
};

class PlyParser {
 public:
  PlyParser(const MappedFile& file, std::string_view bytes, core::LodMesh* mesh, LodFileStats* stats)
      : file_(file), data_(bytes.data()), size_(bytes.size()), mesh_(*mesh), stats_(*stats) {}

  void run() {
    ply::Header header;
    ply::parse_header(file_, std::string_view(data_, size_), true, &header, ply::MissingEndLine::after_last);
    check_header(std::move(header));
    stats_.format = format_name(fmt_);
    reserve();
    constexpr bool little = std::endian::native == std::endian::little;
    if (fmt_ == Fmt::ascii) parse_ascii();
    else if ((fmt_ == Fmt::le) == little) parse_binary<false>();
    else parse_binary<true>();
    if (mesh_.point_size.size() != mesh_.points.size()) mesh_.point_size.clear();  // some point element unsized
    if (materials_) material_table();
  }

 private:
  using Fmt = ply::Format;

  void check_header(ply::Header&& header);
  // The material table of io/ply_writer.h's comment lines ("comment material I r g b a metallic roughness
  // OPAQUE|MASK|BLEND double-sided name"), extended by default materials to every id a primitive names;
  // primitives of elements without material_index take material 0.
  void material_table() {
    std::string_view head(data_, data_start_);
    for (size_t at = 0; at < head.size();) {
      size_t e = head.find('\n', at);
      if (e == std::string_view::npos) e = head.size();
      const std::string line(head.substr(at, e - at));
      at = e + 1;
      if (line.rfind("comment material ", 0) != 0) continue;
      unsigned long id = 0;
      float f[6];
      char mode[16] = {0};
      int ds = 1, used = 0;
      if (std::sscanf(line.c_str() + 17, "%lu %f %f %f %f %f %f %15s %d %n", &id, &f[0], &f[1], &f[2], &f[3], &f[4], &f[5], mode, &ds,
                      &used) < 9 || id != mesh_.materials.size())
        continue;
      core::Material m;
      for (int k = 0; k < 4; ++k) m.base_color[k] = f[k];
      m.metallic = f[4], m.roughness = f[5];
      m.alpha = std::string_view(mode) == "MASK" ? core::Material::Alpha::mask
                : std::string_view(mode) == "BLEND" ? core::Material::Alpha::blend : core::Material::Alpha::opaque;
      m.double_sided = ds != 0;
      m.name = line.substr(17 + static_cast<size_t>(used));
      mesh_.materials.push_back(std::move(m));
    }
    if (mesh_.materials.size() <= max_material_) mesh_.materials.resize(uint64_t{max_material_} + 1);
    mesh_.triangle_materials.resize(mesh_.triangle_count());
    mesh_.edge_materials.resize(mesh_.edge_count());
    mesh_.point_materials.resize(mesh_.point_count());
  }
  void reserve();
  template <bool Swap>
  void parse_binary();
  void parse_ascii();

  [[noreturn]] void header_error(uint64_t line, const std::string& message) const {
    fail_at_line(file_, line, message);
  }
  // An error in the current record: at its line (ascii) or its first byte (binary).
  [[noreturn]] void data_error(const std::string& message) const {
    if (fmt_ == Fmt::ascii) fail_at_line(file_, line_, message);
    fail_at_offset(file_, offset_, message);
  }
  std::string record_text() const {
    return "record " + std::to_string(record_ + 1) + " of " + std::to_string(element_->count) + " of element '" +
           element_->name + "'";
  }
  [[noreturn]] void truncated() const {
    data_error(std::string("truncated: the file ends ") + (offset_ >= size_ ? "before " : "inside ") + record_text());
  }

  uint32_t index(int64_t i) const {
    if (static_cast<uint64_t>(i) >= vertex_count_)
      data_error("vertex index " + std::to_string(i) + " out of range in " + record_text() + ": the file has " +
                 vertices_text(vertex_count_));
    return static_cast<uint32_t>(i);
  }
  void fan_add(Fan& f, int64_t i) { f.add(index(i), mesh_, stats_); }
  void add_edge(uint32_t a, uint32_t b, double thickness) {
    const float t = static_cast<float>(thickness);
    if (!(t >= 0) || !std::isfinite(t)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%g", thickness);
      data_error(std::string("edge thickness ") + buf + " is negative or not finite in " + record_text());
    }
    if (a == b) {
      ++stats_.degenerate_edges;
      return;
    }
    mesh_.edges.push_back(a);
    mesh_.edges.push_back(b);
    mesh_.thickness.push_back(t);
  }
  // A point, with its size when the element has one (sizes are kept only when every point has one).
  void add_point(uint32_t v, double size) {
    const float s = static_cast<float>(size);
    if (!(s >= 0) || !std::isfinite(s)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%g", size);
      data_error(std::string("point size ") + buf + " is negative or not finite in " + record_text());
    }
    mesh_.points.push_back(v);
    if (element_->sized) mesh_.point_size.push_back(s);
  }
  // What a record's roles collected, once the whole record is read.
  void finish_record(const double* xyz, const int64_t* v, double thickness, const Fan& fan, const double* rgba,
                     int64_t material) {
    finish_record(xyz, v, thickness, fan);
    if (element_->kind == Kind::vertex && colors_) {
      for (int k = 0; k < 4; ++k) mesh_.colors.push_back(static_cast<uint8_t>(std::clamp(rgba[k], 0.0, 255.0) + 0.5));
      return;
    }
    if (!materials_) return;
    if (material < 0 || material > UINT32_MAX) data_error("material_index " + std::to_string(material) + " out of range in " + record_text());
    const uint32_t m = static_cast<uint32_t>(material);
    max_material_ = std::max(max_material_, m);
    while (mesh_.triangle_materials.size() < mesh_.triangle_count()) mesh_.triangle_materials.push_back(m);
    while (mesh_.edge_materials.size() < mesh_.edge_count()) mesh_.edge_materials.push_back(m);
    while (mesh_.point_materials.size() < mesh_.point_count()) mesh_.point_materials.push_back(m);
  }
  void finish_record(const double* xyz, const int64_t* v, double thickness, const Fan& fan) {
    switch (element_->kind) {
      case Kind::vertex: {
        const float f[3] = {static_cast<float>(xyz[0]), static_cast<float>(xyz[1]), static_cast<float>(xyz[2])};
        if (!std::isfinite(f[0]) || !std::isfinite(f[1]) || !std::isfinite(f[2])) {
          char buf[160];
          std::snprintf(buf, sizeof buf, "vertex coordinate is not finite%s (%g, %g, %g) in ",
                        text::finite3(xyz) ? " as a float" : "", xyz[0], xyz[1], xyz[2]);
          data_error(buf + record_text());
        }
        mesh_.positions.insert(mesh_.positions.end(), f, f + 3);
        break;
      }
      case Kind::face:
        ++stats_.faces;
        if (fan.n < 2)
          data_error("face with " + vertices_text(fan.n) + " (a face needs at least 2) in " + record_text());
        if (fan.n == 2) add_edge(fan.first, fan.prev, 0);  // a loose edge, as the ingest readers keep it
        break;
      case Kind::edge: add_edge(index(v[0]), index(v[1]), thickness); break;
      case Kind::point: add_point(index(v[0]), thickness); break;
      case Kind::other: ++stats_.skipped; break;
    }
  }

  const MappedFile& file_;
  const char* const data_;
  const uint64_t size_;
  core::LodMesh& mesh_;
  LodFileStats& stats_;

  Fmt fmt_ = Fmt::ascii;
  std::vector<Element> elements_;
  uint64_t data_start_ = 0;
  uint64_t data_line_ = 0;
  uint64_t header_lines_ = 0;
  uint64_t vertex_count_ = 0;
  bool colors_ = false, materials_ = false;  // vertex red, green, blue; material_index on some primitive
  uint32_t max_material_ = 0;

  // The record being read, for error messages.
  const Element* element_ = nullptr;
  uint64_t record_ = 0;
  uint64_t offset_ = 0;
  uint64_t line_ = 0;
};

// Takes the parsed header: gives the properties this reader knows their roles and checks them.
void PlyParser::check_header(ply::Header&& header) {
  fmt_ = header.format;
  data_start_ = header.data_start;
  header_lines_ = header.lines;
  data_line_ = header.lines + 1;
  for (ply::Element& d : header.elements) elements_.push_back(Element{std::move(d)});
  bool have_vertex = false;
  for (Element& e : elements_) {
    auto find = [&](std::string_view name) -> Property* {
      for (Property& pr : e.props)
        if (pr.name == name) return &pr;
      return nullptr;
    };
    auto scalar = [&](Property* pr, bool integer) {
      if (pr->list || (integer && !is_integer(pr->type)))
        header_error(e.header_line, "property " + quoted(pr->name) + " of element " + quoted(e.name) +
                                        (integer ? " must be a scalar integer" : " must be a scalar"));
    };
    if (e.count > 0 && e.props.empty())
      header_error(e.header_line, "element " + quoted(e.name) + " has records but no properties");
    if (e.name == "vertex") {
      e.kind = Kind::vertex;
      have_vertex = true;
      vertex_count_ = e.count;
      if (e.count > kMaxVertices)
        header_error(e.header_line, "element 'vertex' declares " + std::to_string(e.count) +
                                        " records: more than 32-bit indices can address");
      const std::pair<const char*, Role> coords[3] = {{"x", Role::x}, {"y", Role::y}, {"z", Role::z}};
      for (const auto& [name, role] : coords) {
        Property* pr = find(name);
        if (!pr) header_error(e.header_line, std::string("element 'vertex' has no property '") + name + "'");
        scalar(pr, false);
        pr->role = role;
      }
      const std::pair<const char*, Role> channels[4] = {{"red", Role::red}, {"green", Role::green}, {"blue", Role::blue}, {"alpha", Role::alpha}};
      colors_ = find("red") && find("green") && find("blue");
      for (const auto& [name, role] : channels)
        if (Property* pr = find(name); pr && colors_) scalar(pr, false), pr->role = role;
    } else if (e.name == "face") {
      e.kind = Kind::face;
      Property* pr = find("vertex_indices");
      if (!pr) pr = find("vertex_index");
      if (!pr) header_error(e.header_line, "element 'face' has no list property 'vertex_indices'");
      if (!pr->list) header_error(e.header_line, "property " + quoted(pr->name) + " of element 'face' is not a list");
      if (!is_integer(pr->type))
        header_error(e.header_line, "face indices must have an integer type, not " + std::string(type_name(pr->type)));
      pr->role = Role::indices;
      e.index_size = type_size(pr->type);
    } else if (e.name == "edge") {
      Property* a = find("vertex1");
      Property* b = find("vertex2");
      if (a && b) {
        e.kind = Kind::edge;
        scalar(a, true);
        scalar(b, true);
        a->role = Role::v1;
        b->role = Role::v2;
        if (Property* t = find("thickness")) {
          scalar(t, false);
          t->role = Role::thickness;
        }
      }
    } else if (e.name == "point") {
      if (Property* v = find("vertex")) {
        e.kind = Kind::point;
        scalar(v, true);
        v->role = Role::v1;
        if (Property* t = find("size")) {
          scalar(t, false);
          t->role = Role::thickness;
          e.sized = true;
        }
      }
    }
  }
  for (Element& e : elements_) {
    if (e.kind != Kind::face && e.kind != Kind::edge && e.kind != Kind::point) continue;
    for (Property& pr : e.props)
      if (pr.name == "material_index") {
        if (pr.list || !is_integer(pr.type))
          header_error(e.header_line, "property 'material_index' of element " + quoted(e.name) + " must be a scalar integer");
        pr.role = Role::material_index;
        materials_ = true;
      }
  }
  if (!have_vertex) header_error(header_lines_, "the PLY header declares no element 'vertex'");
  // Counts the data cannot hold, rejected before anything is allocated.
  ply::check_counts(file_, header, elements_);
}

void PlyParser::reserve() {
  const uint64_t avail = size_ - data_start_;
  for (const Element& e : elements_) {
    switch (e.kind) {
      case Kind::vertex: mesh_.positions.reserve(3 * e.count); break;
      case Kind::face: {
        // As many triangles as records the bytes could hold if every record were a triangle.
        const uint64_t per = fmt_ == Fmt::ascii ? 2 * (e.props.size() + 3) : e.min_size + 3 * e.index_size;
        mesh_.triangles.reserve(3 * std::min(e.count, avail / per));
        break;
      }
      case Kind::edge:
        mesh_.edges.reserve(2 * e.count);
        mesh_.thickness.reserve(e.count);
        break;
      case Kind::point: mesh_.points.reserve(e.count); break;
      case Kind::other: break;
    }
  }
}

template <bool Swap>
void PlyParser::parse_binary() {
  const char* p = data_ + data_start_;
  const char* const end = data_ + size_;
  for (const Element& e : elements_) {
    element_ = &e;
    if (e.kind == Kind::other && e.fixed) {
      // Nothing to read: step over the records at once.
      const uint64_t left = static_cast<uint64_t>(end - p);
      if (e.min_size > 0 && left / e.min_size < e.count) {  // an element without properties takes no bytes
        record_ = left / e.min_size;
        offset_ = static_cast<uint64_t>(p - data_) + record_ * e.min_size;
        truncated();
      }
      p += e.count * e.min_size;
      stats_.skipped += e.count;
      continue;
    }
    for (uint64_t k = 0; k < e.count; ++k) {
      record_ = k;
      offset_ = static_cast<uint64_t>(p - data_);
      double xyz[3] = {0, 0, 0};
      int64_t v[2] = {0, 0};
      double thickness = 0;
      double rgba[4] = {255, 255, 255, 255};
      int64_t material = 0;
      Fan fan;
      for (const Property& pr : e.props) {
        if (pr.list) {
          const unsigned cs = type_size(pr.count_type);
          if (static_cast<uint64_t>(end - p) < cs) truncated();
          const int64_t n = load_int<Swap>(p, pr.count_type);
          p += cs;
          if (n < 0)
            data_error("negative list count " + std::to_string(n) + " for list '" + pr.name + "' in " + record_text());
          const unsigned is = type_size(pr.type);
          if (static_cast<uint64_t>(end - p) / is < static_cast<uint64_t>(n)) truncated();
          if (pr.role == Role::indices)
            for (int64_t i = 0; i < n; ++i) fan_add(fan, load_int<Swap>(p + i * is, pr.type));
          p += static_cast<uint64_t>(n) * is;
        } else {
          const unsigned s = type_size(pr.type);
          if (static_cast<uint64_t>(end - p) < s) truncated();
          switch (pr.role) {
            case Role::x: xyz[0] = load_double<Swap>(p, pr.type); break;
            case Role::y: xyz[1] = load_double<Swap>(p, pr.type); break;
            case Role::z: xyz[2] = load_double<Swap>(p, pr.type); break;
            case Role::v1: v[0] = load_int<Swap>(p, pr.type); break;
            case Role::v2: v[1] = load_int<Swap>(p, pr.type); break;
            case Role::thickness: thickness = load_double<Swap>(p, pr.type); break;
            case Role::red: case Role::green: case Role::blue: case Role::alpha:
              rgba[static_cast<int>(pr.role) - static_cast<int>(Role::red)] =
                  load_double<Swap>(p, pr.type) * (is_integer(pr.type) ? 1 : 255);
              break;
            case Role::material_index: material = load_int<Swap>(p, pr.type); break;
            default: break;
          }
          p += s;
        }
      }
      finish_record(xyz, v, thickness, fan, rgba, material);
    }
  }
  if (p < end)
    fail_at_offset(file_, static_cast<uint64_t>(p - data_),
                   std::to_string(end - p) + " bytes after the last element the header declares");
}

enum class Val : uint8_t { ok, missing, bad, range };

// One ascii value of type t at p, within a line ending at e: an integer in range for integer types, a
// number rounded once to the declared type for float types.
Val ascii_value(const char*& p, const char* e, Type t, double* d, int64_t* i) {
  p = text::skip_blanks(p, e);
  if (p == e) return Val::missing;
  const char* q = p;
  if (is_integer(t)) {
    int64_t v = 0;
    if (!text::parse_int64(q, e, &v) || (q < e && !text::is_blank(*q))) return Val::bad;
    if (v < type_min(t) || v > type_max(t)) return Val::range;
    *i = v;
    *d = static_cast<double>(v);
  } else if (t == Type::f32) {
    float f = 0;
    q = float_at(q, e, &f);
    if (!q || (q < e && !text::is_blank(*q))) return Val::bad;
    *d = f;
  } else {
    if (!text::parse_double(q, e, d)) return Val::bad;
  }
  p = q;
  return Val::ok;
}

void PlyParser::parse_ascii() {
  const char* p = data_ + data_start_;
  const char* const end = data_ + size_;
  uint64_t line = data_line_;
  for (const Element& e : elements_) {
    element_ = &e;
    for (uint64_t k = 0; k < e.count; ++k) {
      record_ = k;
      const char* le;
      const char* q;
      for (;;) {  // the next line that is not blank
        offset_ = static_cast<uint64_t>(p - data_);
        line_ = line;
        if (p >= end) data_error("truncated: the file ends before " + record_text());
        le = text::line_end(p, end);
        q = text::skip_blanks(p, le);
        if (q != le) break;
        p = le < end ? le + 1 : end;
        ++line;
      }
      double xyz[3] = {0, 0, 0};
      int64_t v[2] = {0, 0};
      double thickness = 0;
      double rgba[4] = {255, 255, 255, 255};
      int64_t material = 0;
      Fan fan;
      for (const Property& pr : e.props) {
        double d = 0;
        int64_t iv = 0;
        auto value = [&](Type t, const std::string& what) {
          const char* tok = text::skip_blanks(q, le);
          const Val r = ascii_value(q, le, t, &d, &iv);
          if (r == Val::ok) return;
          if (r == Val::missing) data_error("too few values in " + record_text() + ": no value for " + what);
          const char* te = tok;
          while (te < le && !text::is_blank(*te)) ++te;
          data_error(std::string(r == Val::range ? "value out of range for " : "bad value for ") + what + " (" +
                     type_name(t) + ") in " + record_text() + ": " +
                     quoted(std::string_view(tok, static_cast<size_t>(te - tok))));
        };
        if (pr.list) {
          value(pr.count_type, "the count of list '" + pr.name + "'");
          if (iv < 0)
            data_error("negative list count " + std::to_string(iv) + " for list '" + pr.name + "' in " + record_text());
          const int64_t n = iv;
          for (int64_t j = 0; j < n; ++j) {
            value(pr.type, "item " + std::to_string(j + 1) + " of list '" + pr.name + "'");
            if (pr.role == Role::indices) fan_add(fan, iv);
          }
        } else {
          value(pr.type, "property '" + pr.name + "'");
          switch (pr.role) {
            case Role::x: xyz[0] = d; break;
            case Role::y: xyz[1] = d; break;
            case Role::z: xyz[2] = d; break;
            case Role::v1: v[0] = iv; break;
            case Role::v2: v[1] = iv; break;
            case Role::thickness: thickness = d; break;
            case Role::red: case Role::green: case Role::blue: case Role::alpha:
              rgba[static_cast<int>(pr.role) - static_cast<int>(Role::red)] = d * (is_integer(pr.type) ? 1 : 255);
              break;
            case Role::material_index: material = iv; break;
            default: break;
          }
        }
      }
      q = text::skip_blanks(q, le);
      if (q != le)
        data_error("extra values after the last property in " + record_text() + ": " +
                   quoted(std::string_view(q, static_cast<size_t>(le - q))));
      finish_record(xyz, v, thickness, fan, rgba, material);
      p = le < end ? le + 1 : end;
      ++line;
    }
  }
  // Whitespace may follow the last record, nothing else.
  for (; p < end; ++p) {
    if (*p == '\n') {
      ++line;
    } else if (!text::is_blank(*p)) {
      fail_at_line(file_, line, "data after the last element the header declares");
    }
  }
}

// ================================================================================================ OBJ

// If p (at a backslash) continues the statement on the next line, the position after the line break (or
// end, for a backslash ending the file); else nullptr.
const char* continuation(const char* p, const char* end) {
  const char* q = p + 1;
  if (q < end && *q == '\r') ++q;
  if (q == end) return end;
  return *q == '\n' ? q + 1 : nullptr;
}

class ObjParser {
 public:
  ObjParser(const MappedFile& file, std::string_view bytes, core::LodMesh* mesh, LodFileStats* stats)
      : file_(file), p_(bytes.data()), end_(bytes.data() + bytes.size()), mesh_(*mesh), stats_(*stats) {}

  void run();

 private:
  [[noreturn]] void error(const std::string& message) const { fail_at_line(file_, stmt_line_, message); }

  // What may end a token: a blank, the end of the statement, a comment, a continuation.
  bool is_sep(const char* p) const {
    if (p >= end_) return true;
    const char c = *p;
    return text::is_blank(c) || c == '\n' || c == '#' || (c == '\\' && continuation(p, end_));
  }
  bool at_statement_end() const { return p_ >= end_ || *p_ == '\n' || *p_ == '#'; }
  void skip_ws() {
    for (;;) {
      while (p_ < end_ && text::is_blank(*p_)) ++p_;
      if (p_ < end_ && *p_ == '\\') {
        if (const char* q = continuation(p_, end_)) {
          if (q[-1] == '\n') ++line_;
          p_ = q;
          continue;
        }
      }
      return;
    }
  }
  std::string token_at(const char* p) const {
    const char* e = p;
    while (!is_sep(e)) ++e;
    return quoted(std::string_view(p, static_cast<size_t>(e - p)));
  }
  // A token that does not parse: binary bytes in it are the better explanation.
  [[noreturn]] void bad_token(const char* p, const std::string& message) const {
    for (const char* e = p; !is_sep(e); ++e)
      if (is_control(static_cast<unsigned char>(*e))) error(control_message(static_cast<unsigned char>(*e)));
    error(message);
  }
  void skip_statement();
  void vertex();
  uint32_t reference(const char* what);
  void face();
  void polyline();
  void point();

  const MappedFile& file_;
  const char* p_;
  const char* const end_;
  core::LodMesh& mesh_;
  LodFileStats& stats_;
  uint64_t line_ = 1;
  uint64_t stmt_line_ = 1;
  uint64_t vertices_ = 0;
  // References past the vertices read so far, each larger than the one before, with their lines: the first
  // whose index is past the last vertex of the file is the first such reference in file order.
  std::vector<std::pair<uint32_t, uint64_t>> forward_;
};

// Moves p_ to the '\n' ending the statement (or the end), across continuations; any comment ends at its
// physical line. Checks the bytes on the way.
void ObjParser::skip_statement() {
  for (;;) {
    const char* const le = text::line_end(p_, end_);
    const char* comment = nullptr;
    for (const char* c = p_; c < le; ++c) {
      if (*c == '#' && !comment) comment = c;
      if (is_control(static_cast<unsigned char>(*c))) error(control_message(static_cast<unsigned char>(*c)));
    }
    const char* last = le;
    if (last > p_ && last[-1] == '\r') --last;
    if (!comment && le < end_ && last > p_ && last[-1] == '\\') {
      p_ = le + 1;
      ++line_;
      continue;
    }
    p_ = le;
    return;
  }
}

void ObjParser::vertex() {
  float xyz[3];
  for (int c = 0; c < 3; ++c) {
    skip_ws();
    if (at_statement_end())
      error("vertex has " + std::to_string(c) + " coordinate" + (c == 1 ? "" : "s") + ", needs 3");
    const char* q = float_at(p_, end_, &xyz[c]);
    if (!q || !is_sep(q)) bad_token(p_, "bad vertex coordinate " + token_at(p_));
    p_ = q;
  }
  if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2]))
    error("vertex coordinate is not finite (or out of float range)");
  if (vertices_ == kMaxVertices) error("more vertices than 32-bit indices can address");
  mesh_.positions.insert(mesh_.positions.end(), xyz, xyz + 3);
  ++vertices_;
  skip_statement();
}

// One corner: v, v/vt, v//vn or v/vt/vn, 1-based or negative (relative to the vertices read so far).
uint32_t ObjParser::reference(const char* what) {
  const char* const b = p_;
  int64_t v = 0;
  const auto [q, ec] = std::from_chars(p_, end_, v);
  bool ok = ec == std::errc();
  p_ = ok ? q : p_;
  if (ok && p_ < end_ && *p_ == '/') {
    // Texture and normal indices: digits and signs between the slashes, not used.
    while (p_ < end_ && (*p_ == '/' || *p_ == '-' || *p_ == '+' || (*p_ >= '0' && *p_ <= '9'))) ++p_;
  }
  if (!ok || !is_sep(p_))
    bad_token(b, std::string("bad vertex reference ") + token_at(b) + " in '" + what + "' statement");
  if (v == 0) error(std::string("vertex index 0 in '") + what + "' statement (OBJ indices start at 1)");
  if (v < 0) {
    if (static_cast<uint64_t>(-(v + 1)) >= vertices_)
      error("relative vertex index " + std::to_string(v) + " reaches before the first vertex");
    return static_cast<uint32_t>(vertices_ - static_cast<uint64_t>(-(v + 1)) - 1);
  }
  const uint64_t id = static_cast<uint64_t>(v) - 1;
  if (id >= kMaxVertices) error("vertex index " + std::to_string(v) + " is past what 32-bit indices can address");
  if (id >= vertices_ && (forward_.empty() || id > forward_.back().first))
    forward_.emplace_back(static_cast<uint32_t>(id), stmt_line_);
  return static_cast<uint32_t>(id);
}

void ObjParser::face() {
  Fan f;
  for (;;) {
    skip_ws();
    if (at_statement_end()) break;
    f.add(reference("f"), mesh_, stats_);
  }
  ++stats_.faces;
  if (f.n < 2) error("face with " + std::to_string(f.n) + " corner" + (f.n == 1 ? "" : "s") + " (needs at least 2)");
  if (f.n == 2) {  // an exporter's loose edge
    if (f.first == f.prev) {
      ++stats_.degenerate_edges;
    } else {
      mesh_.edges.push_back(f.first);
      mesh_.edges.push_back(f.prev);
      mesh_.thickness.push_back(0);
    }
  }
  skip_statement();
}

void ObjParser::polyline() {
  uint64_t n = 0;
  uint32_t prev = 0;
  for (;;) {
    skip_ws();
    if (at_statement_end()) break;
    const uint32_t v = reference("l");
    if (n > 0) {
      if (v == prev) {
        ++stats_.degenerate_edges;
      } else {
        mesh_.edges.push_back(prev);
        mesh_.edges.push_back(v);
        mesh_.thickness.push_back(0);
      }
    }
    prev = v;
    ++n;
  }
  if (n < 2) error("line with " + vertices_text(n) + " (needs at least 2)");
  skip_statement();
}

void ObjParser::point() {
  uint64_t n = 0;
  for (;;) {
    skip_ws();
    if (at_statement_end()) break;
    mesh_.points.push_back(reference("p"));
    ++n;
  }
  if (n == 0) error("point statement without vertices");
  skip_statement();
}

void ObjParser::run() {
  stats_.format = "obj";
  while (p_ < end_) {
    skip_ws();
    stmt_line_ = line_;
    if (p_ >= end_) break;
    if (*p_ == '#') {
      skip_statement();  // a comment is text too: its bytes are checked
    } else if (*p_ != '\n') {
      const char* k = p_;
      while (!is_sep(p_)) ++p_;
      const std::string_view keyword(k, static_cast<size_t>(p_ - k));
      if (keyword == "v") vertex();
      else if (keyword == "f") face();
      else if (keyword == "l") polyline();
      else if (keyword == "p") point();
      else {
        for (const char c : keyword)
          if (is_control(static_cast<unsigned char>(c))) error(control_message(static_cast<unsigned char>(c)));
        ++stats_.skipped;
        skip_statement();
      }
    }
    if (p_ < end_) {  // at the '\n' ending the statement
      ++p_;
      ++line_;
    }
  }
  for (const auto& [id, line] : forward_) {
    if (id >= vertices_) {
      stmt_line_ = line;
      error("vertex index " + std::to_string(uint64_t{id} + 1) + " is past the last vertex (the file has " +
            vertices_text(vertices_) + ")");
    }
  }
}

// `ext` is ".obj" or ".ply": the file name ends with it in any case, after a name of its own.
bool has_extension(const std::string& path, std::string_view ext) {
  const size_t slash = path.find_last_of('/');
  const std::string_view name = std::string_view(path).substr(slash == std::string::npos ? 0 : slash + 1);
  if (name.size() <= ext.size()) return false;
  for (size_t i = 0; i < ext.size(); ++i) {
    const char c = name[name.size() - ext.size() + i];
    if ((c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c) != ext[i]) return false;
  }
  return true;
}

}  // namespace

core::LodMesh read_lod_mesh(const std::string& path) { return read_lod_mesh(path, nullptr); }

core::LodMesh read_lod_mesh(const std::string& path, LodFileStats* stats) {
  LodFileStats local;
  LodFileStats& st = stats ? *stats : local;
  st = LodFileStats{};
  const MappedFile file(path);
  const Window all = file.map(0, file.size());
  const std::string_view bytes = all.view();
  core::LodMesh mesh;
  if (bytes.starts_with("ply\n") || bytes.starts_with("ply\r\n")) {
    PlyParser(file, bytes, &mesh, &st).run();
  } else if (has_extension(path, ".obj")) {
    ObjParser(file, bytes, &mesh, &st).run();
  } else if (has_extension(path, ".ply")) {
    // Named PLY but not one: malformed rather than a usage mistake, as the ingest readers say.
    fail_at_offset(file, 0, bytes.empty() ? "empty file" : "not a PLY file: it does not start with the line 'ply'");
  } else {
    fail(Status::usage, path + ": unsupported LOD format (expected PLY, or OBJ named *.obj)");
  }
  return mesh;
}

}  // namespace lodstream::io
