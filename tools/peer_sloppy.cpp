// Peer benchmark: meshoptimizer's meshopt_simplifySloppy (vertex clustering on a uniform grid, in
// core), run on a binary little-endian PLY file, to compare with `lodstream simplify`.
// Standalone on purpose: it does not use the lodstream library, only libmeshoptimizer.
//
// usage: peer_sloppy FILE TARGET_TRIANGLES [--out OUT.ply] [--target-error E] [--simplify]
//
// --simplify runs meshopt_simplify instead (Garland-Heckbert quadric edge collapse, topology kept): it
// stops short of the target where no collapse is left within the error (separate parts are never merged),
// so the triangle count it reaches is part of the result.
//
// Loads FILE (mmap; float x y z vertices, other vertex properties skipped by size; faces as
// `list uchar|ushort|uint8|... int|uint vertex_indices`, fan-triangulated; other elements and other
// fixed-size face properties skipped), runs meshopt_simplifySloppy to TARGET_TRIANGLES (meshoptimizer
// 0.18 takes a target index count and a relative target error, which defaults here to 1.0 = the whole
// extent, so the triangle count alone decides), optionally writes the result as binary PLY with the
// vertices compacted, and prints one JSON line:
//   {"tool":"meshopt_simplifySloppy","load_s":..,"simplify_s":..,"write_s":..,"total_s":..,
//    "triangles_in":..,"triangles_out":..,"vertices_in":..,"vertices_out":..,"result_error":..,
//    "peak_rss_bytes":..}
// total_s is the wall time of the whole program (load + simplify + write when --out is given).
// peak_rss_bytes is VmHWM from /proc/self/status. The mapped file's pages are released from this
// process (madvise MADV_DONTNEED, the page cache keeps them) as soon as they are parsed, so the peak
// is that of the in-core arrays, as if the file had been read with read(2) in chunks.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <meshoptimizer.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace {

[[noreturn]] void die(const std::string& msg) {
  std::fprintf(stderr, "peer_sloppy: %s\n", msg.c_str());
  std::exit(1);
}

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

uint64_t peak_rss_bytes() {
  FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return 0;
  char line[256];
  uint64_t kb = 0;
  while (std::fgets(line, sizeof line, f))
    if (std::strncmp(line, "VmHWM:", 6) == 0) kb = std::strtoull(line + 6, nullptr, 10);
  std::fclose(f);
  return kb * 1024;
}

// Size in bytes of a PLY scalar type name, 0 if unknown.
int type_size(std::string_view t) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "int32" || t == "uint32" || t == "float" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  return 0;
}

bool is_float32(std::string_view t) { return t == "float" || t == "float32"; }
bool is_int32(std::string_view t) { return t == "int" || t == "uint" || t == "int32" || t == "uint32"; }

struct Property {
  std::string name;
  bool is_list = false;
  int size = 0;        // scalar size, or list item size
  int count_size = 0;  // list count size
  std::string type;    // scalar type, or list item type
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Property> props;
  bool fixed() const {
    for (const auto& p : props)
      if (p.is_list) return false;
    return true;
  }
  uint64_t fixed_size() const {
    uint64_t s = 0;
    for (const auto& p : props) s += static_cast<uint64_t>(p.size);
    return s;
  }
};

uint64_t read_uint(const unsigned char* p, int size) {
  switch (size) {
    case 1: return p[0];
    case 2: { uint16_t v; std::memcpy(&v, p, 2); return v; }
    case 4: { uint32_t v; std::memcpy(&v, p, 4); return v; }
    default: { uint64_t v; std::memcpy(&v, p, 8); return v; }
  }
}

// A read-only mapping of the whole file whose parsed pages are handed back as parsing moves on.
class Mapping {
 public:
  explicit Mapping(const char* path) {
    fd_ = ::open(path, O_RDONLY);
    if (fd_ < 0) die(std::string("cannot open ") + path);
    struct stat st {};
    if (fstat(fd_, &st) != 0) die("cannot stat input");
    size_ = static_cast<size_t>(st.st_size);
    if (size_ == 0) die("empty input");
    void* p = mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd_, 0);
    if (p == MAP_FAILED) die("mmap failed");
    data_ = static_cast<const unsigned char*>(p);
    madvise(p, size_, MADV_SEQUENTIAL);
  }
  ~Mapping() {
    munmap(const_cast<unsigned char*>(data_), size_);
    ::close(fd_);
  }
  const unsigned char* data() const { return data_; }
  size_t size() const { return size_; }
  // Drops [begin, end) (rounded inwards to pages) from this process's resident set.
  void release(size_t begin, size_t end) const {
    const size_t page = 4096;
    begin = (begin + page - 1) / page * page;
    end = end / page * page;
    if (end > begin) madvise(const_cast<unsigned char*>(data_) + begin, end - begin, MADV_DONTNEED);
  }

 private:
  int fd_ = -1;
  size_t size_ = 0;
  const unsigned char* data_ = nullptr;
};

constexpr size_t kChunk = size_t(64) << 20;  // release granularity

struct Mesh {
  std::vector<float> positions;  // x y z per vertex
  std::vector<uint32_t> indices;  // 3 per triangle
};

// Parses the header; returns the offset of the body.
size_t parse_header(const Mapping& m, std::vector<Element>& elements) {
  const char* s = reinterpret_cast<const char*>(m.data());
  const size_t limit = std::min<size_t>(m.size(), size_t(1) << 20);
  std::string_view all(s, limit);
  if (all.substr(0, 4) != "ply\n" && all.substr(0, 5) != "ply\r\n") die("not a PLY file");
  size_t end = all.find("end_header");
  if (end == std::string_view::npos) die("no end_header");
  size_t body = all.find('\n', end);
  if (body == std::string_view::npos) die("truncated header");
  ++body;
  size_t pos = all.find('\n') + 1;
  bool format_ok = false;
  while (pos < end) {
    size_t nl = all.find('\n', pos);
    std::string_view line = all.substr(pos, nl - pos);
    pos = nl + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    std::vector<std::string_view> w;
    size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      size_t j = i;
      while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
      if (j > i) w.push_back(line.substr(i, j - i));
      i = j;
    }
    if (w.empty() || w[0] == "comment" || w[0] == "obj_info") continue;
    if (w[0] == "format") {
      if (w.size() < 2 || w[1] != "binary_little_endian") die("only binary_little_endian PLY is supported");
      format_ok = true;
    } else if (w[0] == "element") {
      if (w.size() < 3) die("bad element line");
      Element e;
      e.name = std::string(w[1]);
      e.count = std::strtoull(std::string(w[2]).c_str(), nullptr, 10);
      elements.push_back(std::move(e));
    } else if (w[0] == "property") {
      if (elements.empty()) die("property before element");
      Property p;
      if (w.size() >= 5 && w[1] == "list") {
        p.is_list = true;
        p.count_size = type_size(w[2]);
        p.size = type_size(w[3]);
        p.type = std::string(w[3]);
        p.name = std::string(w[4]);
        if (!p.count_size || !p.size) die("bad list property type");
      } else if (w.size() >= 3) {
        p.size = type_size(w[1]);
        p.type = std::string(w[1]);
        p.name = std::string(w[2]);
        if (!p.size) die("bad property type");
      } else {
        die("bad property line");
      }
      elements.back().props.push_back(std::move(p));
    }
  }
  if (!format_ok) die("no format line");
  return body;
}

// Skips one element instance with list properties; returns the new offset.
size_t skip_record(const Mapping& m, const Element& e, size_t off) {
  for (const auto& p : e.props) {
    if (off + p.count_size > m.size()) die("truncated body");
    if (p.is_list) {
      const uint64_t n = read_uint(m.data() + off, p.count_size);
      off += p.count_size + n * p.size;
    } else {
      off += p.size;
    }
  }
  if (off > m.size()) die("truncated body");
  return off;
}

size_t load_vertices(const Mapping& m, const Element& e, size_t off, Mesh& mesh) {
  if (!e.fixed()) die("list properties in the vertex element are not supported");
  int ox = -1, oy = -1, oz = -1, o = 0;
  for (const auto& p : e.props) {
    if (p.name == "x" || p.name == "y" || p.name == "z") {
      if (!is_float32(p.type)) die("vertex coordinates must be float");
      (p.name == "x" ? ox : p.name == "y" ? oy : oz) = o;
    }
    o += p.size;
  }
  if (ox < 0 || oy < 0 || oz < 0) die("vertex element lacks x, y or z");
  const size_t stride = static_cast<size_t>(o);
  const size_t n = e.count;
  if (off + n * stride > m.size()) die("truncated vertex data");
  mesh.positions.resize(n * 3);
  float* dst = mesh.positions.data();
  const unsigned char* src = m.data() + off;
  const size_t per_chunk = std::max<size_t>(1, kChunk / stride);
  for (size_t first = 0; first < n; first += per_chunk) {
    const size_t last = std::min(n, first + per_chunk);
    if (stride == 12 && ox == 0 && oy == 4 && oz == 8) {
      std::memcpy(dst + first * 3, src + first * 12, (last - first) * 12);
    } else {
      for (size_t v = first; v < last; ++v) {
        const unsigned char* r = src + v * stride;
        std::memcpy(dst + v * 3 + 0, r + ox, 4);
        std::memcpy(dst + v * 3 + 1, r + oy, 4);
        std::memcpy(dst + v * 3 + 2, r + oz, 4);
      }
    }
    m.release(off + first * stride, off + last * stride);
  }
  return off + n * stride;
}

// Fast path: every face is `3 i j k` with a 1-byte count, 4-byte indices, no other property.
// Records then have a fixed size of 13 bytes; verified while copying, in parallel. Returns false
// (having written nothing that matters) if some face is not a triangle.
bool load_triangles_fixed(const Mapping& m, const Element& e, size_t off, size_t nverts, Mesh& mesh) {
  const size_t n = e.count, rec = 13;
  if (off + n * rec > m.size()) return false;
  mesh.indices.resize(n * 3);
  const unsigned nthreads = std::max(1u, std::min(4u, std::thread::hardware_concurrency()));
  std::vector<int> ok(nthreads, 1);
  std::vector<std::thread> threads;
  for (unsigned t = 0; t < nthreads; ++t) {
    threads.emplace_back([&, t] {
      const size_t begin = n * t / nthreads, end = n * (t + 1) / nthreads;
      const unsigned char* src = m.data() + off;
      uint32_t* dst = mesh.indices.data();
      const size_t per_chunk = kChunk / rec;
      uint32_t bad = 0, maxi = 0;
      for (size_t first = begin; first < end && !bad; first += per_chunk) {
        const size_t last = std::min(end, first + per_chunk);
        for (size_t f = first; f < last; ++f) {
          const unsigned char* r = src + f * rec;
          bad |= r[0] ^ 3u;
          uint32_t a, b, c;
          std::memcpy(&a, r + 1, 4);
          std::memcpy(&b, r + 5, 4);
          std::memcpy(&c, r + 9, 4);
          dst[f * 3] = a;
          dst[f * 3 + 1] = b;
          dst[f * 3 + 2] = c;
          maxi = std::max(maxi, std::max(a, std::max(b, c)));
        }
        m.release(off + first * rec, off + last * rec);
      }
      if (bad) ok[t] = 0;  // some face is not a triangle: the caller takes the general path
      else if (begin < end && maxi >= nverts) ok[t] = -1;
    });
  }
  for (auto& th : threads) th.join();
  for (int v : ok)
    if (v < 0) die("vertex index out of range");
  for (int v : ok)
    if (v == 0) return false;
  return true;
}

size_t load_faces(const Mapping& m, const Element& e, size_t off, size_t nverts, Mesh& mesh) {
  int list = -1;
  for (size_t i = 0; i < e.props.size(); ++i)
    if (e.props[i].is_list && (e.props[i].name == "vertex_indices" || e.props[i].name == "vertex_index")) list = int(i);
  if (list < 0) die("face element lacks vertex_indices");
  const Property& lp = e.props[list];
  if (!is_int32(lp.type)) die("vertex_indices must be int or uint");
  if (e.props.size() == 1 && lp.count_size == 1 && load_triangles_fixed(m, e, off, nverts, mesh))
    return off + e.count * 13;
  // General path: sequential, fan triangulation, other properties skipped.
  mesh.indices.clear();
  mesh.indices.reserve(e.count * 3);
  size_t released = off;
  for (uint64_t f = 0; f < e.count; ++f) {
    for (size_t i = 0; i < e.props.size(); ++i) {
      const Property& p = e.props[i];
      if (off + (p.is_list ? p.count_size : p.size) > m.size()) die("truncated face data");
      if (!p.is_list) { off += p.size; continue; }
      const uint64_t k = read_uint(m.data() + off, p.count_size);
      off += p.count_size;
      if (off + k * p.size > m.size()) die("truncated face data");
      if (int(i) == list) {
        const unsigned char* r = m.data() + off;
        uint32_t v0 = 0, prev = 0;
        for (uint64_t j = 0; j < k; ++j) {
          uint32_t v;
          std::memcpy(&v, r + j * 4, 4);
          if (v >= nverts) die("vertex index out of range");
          if (j == 0) v0 = v;
          else if (j >= 2) {
            mesh.indices.push_back(v0);
            mesh.indices.push_back(prev);
            mesh.indices.push_back(v);
          }
          prev = v;
        }
      }
      off += k * p.size;
    }
    if (off - released >= kChunk) {
      m.release(released, off);
      released = off / 4096 * 4096;
    }
  }
  return off;
}

Mesh load_ply(const char* path) {
  Mapping m(path);
  std::vector<Element> elements;
  size_t off = parse_header(m, elements);
  Mesh mesh;
  bool have_v = false, have_f = false;
  for (const auto& e : elements) {
    if (e.name == "vertex") {
      off = load_vertices(m, e, off, mesh);
      have_v = true;
    } else if (e.name == "face") {
      if (!have_v) die("faces before vertices are not supported");
      off = load_faces(m, e, off, mesh.positions.size() / 3, mesh);
      have_f = true;
    } else if (e.fixed()) {
      off += e.count * e.fixed_size();
      if (off > m.size()) die("truncated body");
    } else {
      for (uint64_t i = 0; i < e.count; ++i) off = skip_record(m, e, off);
    }
  }
  if (!have_v || !have_f) die("PLY needs vertex and face elements");
  return mesh;
}

// Writes the triangles `idx` with only the vertices they use, as binary little-endian PLY.
void write_ply(const char* path, const std::vector<float>& pos, const uint32_t* idx, size_t index_count, bool full) {
  const size_t nv = pos.size() / 3;
  std::vector<uint32_t> remap(nv);
  const size_t unique = meshopt_optimizeVertexFetchRemap(remap.data(), idx, index_count, nv);
  std::vector<float> out_pos(unique * 3);
  for (size_t v = 0; v < nv; ++v)
    if (remap[v] != ~0u) std::memcpy(&out_pos[size_t(remap[v]) * 3], &pos[v * 3], 12);
  FILE* f = std::fopen(path, "wb");
  if (!f) die(std::string("cannot write ") + path);
  std::fprintf(f,
               "ply\nformat binary_little_endian 1.0\ncomment %s (peer_sloppy)\n"
               "element vertex %zu\nproperty float x\nproperty float y\nproperty float z\n"
               "element face %zu\nproperty list uchar int vertex_indices\nend_header\n",
               full ? "meshopt_simplify" : "meshopt_simplifySloppy", unique, index_count / 3);
  std::fwrite(out_pos.data(), 4, out_pos.size(), f);
  std::vector<unsigned char> buf;
  buf.reserve(size_t(13) << 16);
  for (size_t t = 0; t < index_count / 3; ++t) {
    unsigned char r[13];
    r[0] = 3;
    for (int k = 0; k < 3; ++k) std::memcpy(r + 1 + 4 * k, &remap[idx[t * 3 + k]], 4);
    buf.insert(buf.end(), r, r + 13);
    if (buf.size() >= (size_t(13) << 16)) {
      std::fwrite(buf.data(), 1, buf.size(), f);
      buf.clear();
    }
  }
  std::fwrite(buf.data(), 1, buf.size(), f);
  if (std::fclose(f) != 0) die("write failed");
}

}  // namespace

int main(int argc, char** argv) {
  const double t0 = now_s();
  const char* file = nullptr;
  const char* out = nullptr;
  long long target = -1;
  float target_error = 1.0f;
  bool full = false;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) out = argv[++i];
    else if (a == "--target-error" && i + 1 < argc) target_error = std::strtof(argv[++i], nullptr);
    else if (a == "--simplify") full = true;
    else if (a == "-h" || a == "--help") { file = nullptr; break; }
    else if (!file) file = argv[i];
    else if (target < 0) target = std::atoll(argv[i]);
    else die("unexpected argument " + a);
  }
  if (!file || target < 0) {
    std::fprintf(stderr, "usage: peer_sloppy FILE TARGET_TRIANGLES [--out OUT.ply] [--target-error E] [--simplify]\n");
    return 2;
  }

  Mesh mesh = load_ply(file);
  const double t1 = now_s();

  const size_t index_count = mesh.indices.size();
  std::vector<uint32_t> dst(index_count);  // worst case is index_count, not the target (header)
  float result_error = 0;
  const size_t target_indices = std::min<size_t>(index_count, size_t(target) * 3);
  const size_t out_count =
      full ? meshopt_simplify(dst.data(), mesh.indices.data(), index_count, mesh.positions.data(), mesh.positions.size() / 3,
                              sizeof(float) * 3, target_indices, target_error, 0, &result_error)
           : meshopt_simplifySloppy(dst.data(), mesh.indices.data(), index_count, mesh.positions.data(),
                                    mesh.positions.size() / 3, sizeof(float) * 3, target_indices, target_error, &result_error);
  const double t2 = now_s();

  size_t vertices_out = 0;
  double write_s = 0;
  if (out) {
    write_ply(out, mesh.positions, dst.data(), out_count, full);
    write_s = now_s() - t2;
  }
  {
    std::vector<unsigned char> seen(mesh.positions.size() / 3, 0);
    for (size_t i = 0; i < out_count; ++i) seen[dst[i]] = 1;
    for (unsigned char s : seen) vertices_out += s;
  }
  std::printf(
      "{\"tool\":\"%s\",\"load_s\":%.3f,\"simplify_s\":%.3f,\"write_s\":%.3f,"
      "\"total_s\":%.3f,\"triangles_in\":%zu,\"triangles_out\":%zu,\"vertices_in\":%zu,\"vertices_out\":%zu,"
      "\"target_triangles\":%lld,\"result_error\":%.6g,\"peak_rss_bytes\":%llu}\n",
      full ? "meshopt_simplify" : "meshopt_simplifySloppy", t1 - t0, t2 - t1, write_s, (t2 - t0) + write_s, index_count / 3, out_count / 3,
      mesh.positions.size() / 3, vertices_out, target, result_error,
      static_cast<unsigned long long>(peak_rss_bytes()));
  return 0;
}
