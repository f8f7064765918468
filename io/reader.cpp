#include "io/reader.h"

#include <algorithm>
#include <cctype>
#include <cstring>

#include "core/status.h"
#include "io/text.h"

namespace lodstream::io {

void ParsedChunk::clear() {
  positions.clear();
  triangles.clear();
  positions32.clear();
  triangles32.clear();
  lines.clear();
  points.clear();
  triangle_objects.clear();
  triangle_materials.clear(), line_materials.clear(), point_materials.clear();
  colors.clear();
  line_objects.clear();
  point_objects.clear();
  object_names.clear();
  planar_faces.clear();
  polygons = skipped = newlines = 0;
  degenerate = face_segments = 0;
  reader_state = 0;
  error = ParseError{};
}

template <class T>
void add_face(int64_t* c, size_t n, uint32_t object, std::vector<T>* triangles, ParsedChunk* out) {
  auto triangle = [&](int64_t a, int64_t b, int64_t d) {
    triangles->push_back(static_cast<T>(a));
    triangles->push_back(static_cast<T>(b));
    triangles->push_back(static_cast<T>(d));
    out->triangle_objects.push_back(object);
  };
  auto segment = [&](int64_t a, int64_t b) {
    out->lines.push_back(a);
    out->lines.push_back(b);
    out->line_objects.push_back(object);
    ++out->face_segments;
  };
  if (n == 3 && c[0] != c[1] && c[1] != c[2] && c[0] != c[2]) {
    triangle(c[0], c[1], c[2]);
    return;
  }
  size_t m = 1;
  for (size_t i = 1; i < n; ++i)
    if (c[i] != c[m - 1]) c[m++] = c[i];
  while (m > 1 && c[m - 1] == c[0]) --m;
  if (m == 1) {
    out->degenerate += n - 2;
    return;
  }
  if (m == 2) {
    segment(c[0], c[1]);
    out->degenerate += n - 2;
    return;
  }
  bool distinct = true;
  if (m <= 32) {
    for (size_t i = 0; i < m && distinct; ++i)
      for (size_t j = i + 1; j < m; ++j)
        if (c[i] == c[j]) {
          distinct = false;
          break;
        }
  } else {
    std::vector<int64_t>& sorted = out->face_scratch;
    if (sorted.data() == c) {
      // The caller collected the corners in face_scratch: sort a copy at its end.
      sorted.resize(n + m);
      c = sorted.data();
      std::copy(c, c + m, c + n);
      std::sort(c + n, c + n + m);
      distinct = std::adjacent_find(c + n, c + n + m) == c + n + m;
    } else {
      sorted.assign(c, c + m);
      std::sort(sorted.begin(), sorted.end());
      distinct = std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end();
    }
  }
  out->degenerate += n - m;
  if (distinct) {
    if (m >= 4) {
      out->planar_faces.push_back(triangles->size() / 3);
      out->planar_faces.push_back(m);
    }
    for (size_t i = 1; i + 1 < m; ++i) triangle(c[0], c[i], c[i + 1]);
    return;
  }
  for (size_t i = 1; i + 1 < m; ++i) {
    // c[i] != c[i + 1] and c[0] differs from c[1] and c[m - 1], by the reduction.
    if (c[0] != c[i] && c[0] != c[i + 1]) {
      triangle(c[0], c[i], c[i + 1]);
    } else {
      segment(c[0], c[0] == c[i] ? c[i + 1] : c[i]);
      ++out->degenerate;
    }
  }
}

template void add_face<int64_t>(int64_t*, size_t, uint32_t, std::vector<int64_t>*, ParsedChunk*);
template void add_face<uint32_t>(int64_t*, size_t, uint32_t, std::vector<uint32_t>*, ParsedChunk*);

void fail_at_line(const MappedFile& file, uint64_t line, const std::string& message) {
  fail(Status::bad_data, file.path() + ":" + std::to_string(line) + ": " + message);
}

void fail_at_offset(const MappedFile& file, uint64_t offset, const std::string& message) {
  fail(Status::bad_data, file.path() + ": byte " + std::to_string(offset) + ": " + message);
}

bool next_line_chunk(const MappedFile& file, uint64_t* cursor, uint64_t target_bytes, Chunk* chunk) {
  const uint64_t begin = *cursor;
  if (begin >= file.size()) return false;
  if (target_bytes == 0) target_bytes = 1;
  // Map a little past the target and cut after the last '\n' inside it; a line longer than the window
  // doubles the window until the line ends or the file does.
  uint64_t want = target_bytes;
  for (;;) {
    const uint64_t end = std::min(file.size(), begin + want);
    Window w = file.map(begin, end);
    if (end == file.size()) {
      chunk->bytes = std::move(w);
      break;
    }
    const char* d = w.data();
    const size_t n = static_cast<size_t>(w.size());
    const void* last = memrchr(d, '\n', n);
    if (last) {
      const uint64_t cut = begin + static_cast<uint64_t>(static_cast<const char*>(last) - d) + 1;
      if (cut == end) {
        chunk->bytes = std::move(w);
      } else {
        w.reset();
        chunk->bytes = file.map(begin, cut);
      }
      break;
    }
    want = want * 2;
  }
  *cursor = chunk->bytes.end();
  return true;
}

namespace {

std::string lower_extension(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return {};
  std::string ext = path.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

// "solid" in any case, after an optional UTF-8 byte-order mark and blanks.
bool starts_with_solid(std::string_view head) {
  size_t i = head.substr(0, 3) == "\xEF\xBB\xBF" ? 3 : 0;
  while (i < head.size() && text::is_blank(head[i])) ++i;
  if (head.size() < i + 5) return false;
  for (size_t k = 0; k < 5; ++k)
    if (std::tolower(static_cast<unsigned char>(head[i + k])) != "solid"[k]) return false;
  return i + 5 == head.size() || text::is_blank(head[i + 5]) || head[i + 5] == '\n';
}

// OBJ has no magic number: accept a file whose first statement is an OBJ keyword.
bool looks_like_obj(std::string_view head) {
  static const char* const keywords[] = {"v", "vt", "vn", "vp", "f", "l", "p", "o", "g", "s", "mtllib", "usemtl", "#"};
  size_t i = 0;
  while (i < head.size()) {
    while (i < head.size() && (text::is_blank(head[i]) || head[i] == '\n')) ++i;
    size_t j = i;
    while (j < head.size() && !text::is_blank(head[j]) && head[j] != '\n') ++j;
    const std::string_view word = head.substr(i, j - i);
    if (word.empty()) return false;
    if (word[0] == '#') {
      const size_t nl = head.find('\n', j);
      if (nl == std::string_view::npos) return false;
      i = nl + 1;
      continue;
    }
    return std::find(std::begin(keywords), std::end(keywords), word) != std::end(keywords);
  }
  return false;
}

}  // namespace

std::unique_ptr<Reader> open_reader(const MappedFile& file) {
  if (file.size() == 0) fail_at_offset(file, 0, "empty file");
  const Window head_window = file.map(0, 4096);
  const std::string_view head = head_window.view();
  const std::string ext = lower_extension(file.path());

  if (head.substr(0, 4) == "ply\n" || head.substr(0, 5) == "ply\r\n") return make_ply_reader(file);
  if (ext == "ply") fail_at_offset(file, 0, "not a PLY file: it does not start with the line 'ply'");

  if (ext == "stl" || starts_with_solid(head)) {
    // Binary STL may also start with "solid": its exact size decides, as it does in every STL reader.
    if (file.size() >= 84) {
      uint32_t count = 0;
      std::memcpy(&count, head.data() + 80, 4);
      if (84 + 50 * static_cast<uint64_t>(count) == file.size()) return make_stl_reader(file, false);
    }
    if (starts_with_solid(head)) return make_stl_reader(file, true);
    return make_stl_reader(file, false);  // reports the size mismatch with both numbers
  }

  if (head.substr(0, 4) == "glTF") return make_gltf_reader(file, true);
  if (ext == "glb") fail_at_offset(file, 0, "not a GLB file: it does not start with the magic 'glTF'");
  if (ext == "gltf") return make_gltf_reader(file, false);

  if (ext == "obj" || looks_like_obj(head)) return make_obj_reader(file);
  fail(Status::usage, file.path() + ": unrecognised format (supported: .obj, .ply, .stl, .gltf, .glb)");
}

}  // namespace lodstream::io
