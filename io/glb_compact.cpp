// Compact tile GLBs (see io/glb_compact.h): KHR_mesh_quantization and EXT_meshopt_compression over what
// io/glb_writer.cpp writes for one level.
#include "io/glb_compact.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <vector>

#include <nlohmann/json.hpp>

#ifdef LODSTREAM_HAVE_MESHOPT
#include <meshoptimizer.h>
#endif

#include "core/status.h"

namespace lodstream::io {

namespace {

using Json = nlohmann::ordered_json;

constexpr int kByte = 5120, kShort = 5122, kUnsignedShort = 5123, kUnsignedInt = 5125, kFloat = 5126;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr int kTriangles = 4;

uint64_t align4(uint64_t n) { return (n + 3) & ~uint64_t{3}; }

[[noreturn]] void bad(const std::string& what) { fail(Status::internal, "compact_glb: " + what); }

uint32_t u32_at(std::string_view b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

// One accessor re-encoded: its element bytes at `stride`, and the JSON fields that change.
struct Stream {
  std::vector<unsigned char> data;
  uint64_t count = 0;
  uint32_t stride = 0;        // bytes per element, a multiple of 4 for vertex streams
  bool indices = false;
  int component_type = kFloat;
  bool normalized = false;
  Json min, max;              // only for POSITION
};

// The elements of accessor `a` as packed bytes (`elem` bytes each), from the BIN chunk.
std::vector<unsigned char> read_accessor(const Json& gltf, std::string_view bin, int a, uint32_t elem, uint64_t* count) {
  const Json& acc = gltf.at("accessors").at(static_cast<size_t>(a));
  const Json& view = gltf.at("bufferViews").at(acc.at("bufferView").get<size_t>());
  if (view.value("buffer", 0) != 0 || view.contains("byteStride") || acc.value("byteOffset", 0) != 0) bad("unexpected buffer view");
  *count = acc.at("count").get<uint64_t>();
  const uint64_t offset = view.value("byteOffset", uint64_t{0});
  if (offset + *count * elem > bin.size() || *count * elem > view.at("byteLength").get<uint64_t>()) bad("accessor out of range");
  const auto* p = reinterpret_cast<const unsigned char*>(bin.data() + offset);
  return std::vector<unsigned char>(p, p + *count * elem);
}

uint32_t element_bytes(const Json& acc) {
  const std::string type = acc.at("type").get<std::string>();
  const int n = type == "SCALAR" ? 1 : type == "VEC2" ? 2 : type == "VEC3" ? 3 : type == "VEC4" ? 4 : 0;
  const int ct = acc.at("componentType").get<int>();
  const int size = ct == kFloat || ct == kUnsignedInt ? 4 : ct == kShort || ct == kUnsignedShort ? 2 : 1;
  if (n == 0) bad("accessor type " + type);
  return static_cast<uint32_t>(n * size);
}

// Snapped grid coordinates of every POSITION of the mesh: k = round(x / quantum) per axis.
struct Grid {
  int64_t lo[3] = {INT64_MAX, INT64_MAX, INT64_MAX}, hi[3] = {INT64_MIN, INT64_MIN, INT64_MIN};
  int64_t origin[3] = {0, 0, 0};
  bool fits = false;  // every k - origin within SHORT
};

int64_t grid_k(float x, double quantum) { return static_cast<int64_t>(std::nearbyint(static_cast<double>(x) / quantum)); }

Stream encode_positions(const std::vector<unsigned char>& raw, uint64_t count, const Grid& g, double quantum) {
  Stream s;
  s.count = count;
  const float* x = reinterpret_cast<const float*>(raw.data());
  int64_t lo[3] = {INT64_MAX, INT64_MAX, INT64_MAX}, hi[3] = {INT64_MIN, INT64_MIN, INT64_MIN};
  if (g.fits) {
    s.stride = 8;
    s.component_type = kShort;
    s.data.assign(count * 8, 0);
    for (uint64_t v = 0; v < count; ++v)
      for (int k = 0; k < 3; ++k) {
        const int64_t q = grid_k(x[3 * v + k], quantum) - g.origin[k];
        lo[k] = std::min(lo[k], q), hi[k] = std::max(hi[k], q);
        const int16_t q16 = static_cast<int16_t>(q);
        std::memcpy(&s.data[8 * v + 2 * k], &q16, 2);
      }
    s.min = Json::array(), s.max = Json::array();
    for (int k = 0; k < 3; ++k) s.min.push_back(lo[k]), s.max.push_back(hi[k]);
  } else {
    s.stride = 12;
    s.data.resize(count * 12);
    float flo[3] = {INFINITY, INFINITY, INFINITY}, fhi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint64_t v = 0; v < count; ++v)
      for (int k = 0; k < 3; ++k) {
        const float f = snap_to_grid(x[3 * v + k], quantum);
        flo[k] = std::min(flo[k], f), fhi[k] = std::max(fhi[k], f);
        std::memcpy(&s.data[12 * v + 4 * k], &f, 4);
      }
    s.min = Json::array(), s.max = Json::array();
    for (int k = 0; k < 3; ++k) s.min.push_back(static_cast<double>(flo[k])), s.max.push_back(static_cast<double>(fhi[k]));
  }
  return s;
}

Stream encode_normals(const std::vector<unsigned char>& raw, uint64_t count) {
  Stream s;
  s.count = count, s.stride = 4, s.component_type = kByte, s.normalized = true;
  s.data.assign(count * 4, 0);
  const float* n = reinterpret_cast<const float*>(raw.data());
  for (uint64_t v = 0; v < count; ++v)
    for (int k = 0; k < 3; ++k) {
      const double q = std::clamp(std::nearbyint(127.0 * n[3 * v + k]), -127.0, 127.0);
      s.data[4 * v + k] = static_cast<unsigned char>(static_cast<int8_t>(q));
    }
  return s;
}

Stream encode_indices(const std::vector<uint32_t>& idx, uint64_t vertices) {
  Stream s;
  s.indices = true;
  s.count = idx.size();
  // 65535 is the primitive-restart value of UNSIGNED_SHORT, which glTF forbids as an index.
  if (vertices <= 65535) {
    s.stride = 2, s.component_type = kUnsignedShort;
    s.data.resize(idx.size() * 2);
    for (size_t i = 0; i < idx.size(); ++i) {
      const uint16_t v = static_cast<uint16_t>(idx[i]);
      std::memcpy(&s.data[2 * i], &v, 2);
    }
  } else {
    s.stride = 4, s.component_type = kUnsignedInt;
    s.data.resize(idx.size() * 4);
    std::memcpy(s.data.data(), idx.data(), s.data.size());
  }
  return s;
}

// Reorders a triangle primitive for the vertex cache and then for fetch (deterministic), applying the vertex
// order to every stream of its vertices (`elem` bytes each).
void reorder(std::vector<uint32_t>& idx, std::vector<std::vector<unsigned char>*>& streams, const std::vector<uint32_t>& elem,
             uint64_t vertices) {
#ifdef LODSTREAM_HAVE_MESHOPT
  std::vector<uint32_t> cached(idx.size());
  meshopt_optimizeVertexCache(cached.data(), idx.data(), idx.size(), vertices);
  std::vector<uint32_t> remap(vertices);
  const size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), cached.data(), cached.size(), vertices);
  if (used != vertices) bad("a primitive's vertex is unused");
  meshopt_remapIndexBuffer(idx.data(), cached.data(), cached.size(), remap.data());
  for (size_t s = 0; s < streams.size(); ++s) {
    std::vector<unsigned char> out(streams[s]->size());
    meshopt_remapVertexBuffer(out.data(), streams[s]->data(), vertices, elem[s], remap.data());
    streams[s]->swap(out);
  }
#else
  (void)idx, (void)streams, (void)elem, (void)vertices;
#endif
}

std::vector<unsigned char> compress(const Stream& s) {
#ifdef LODSTREAM_HAVE_MESHOPT
  std::vector<unsigned char> out;
  if (s.indices) {
    std::vector<uint32_t> idx(s.count);
    uint32_t top = 0;
    for (uint64_t i = 0; i < s.count; ++i) {
      if (s.stride == 2) {
        uint16_t v;
        std::memcpy(&v, &s.data[2 * i], 2);
        idx[i] = v;
      } else {
        std::memcpy(&idx[i], &s.data[4 * i], 4);
      }
      top = std::max(top, idx[i]);
    }
    out.resize(meshopt_encodeIndexBufferBound(idx.size(), size_t{top} + 1));
    out.resize(meshopt_encodeIndexBuffer(out.data(), out.size(), idx.data(), idx.size()));
  } else {
    out.resize(meshopt_encodeVertexBufferBound(s.count, s.stride));
    out.resize(meshopt_encodeVertexBuffer(out.data(), out.size(), s.data.data(), s.count, s.stride));
  }
  if (out.empty()) bad("meshopt encoding failed");
  return out;
#else
  (void)s;
  fail(Status::usage, "EXT_meshopt_compression tiles need meshoptimizer (libmeshoptimizer-dev), absent from this build");
#endif
}

}  // namespace

float snap_to_grid(float x, double quantum) { return static_cast<float>(quantum * static_cast<double>(grid_k(x, quantum))); }

double power_of_two_below(double x) {
  int e;
  const double m = std::frexp(x, &e);  // x = m · 2^e, m in [0.5, 1)
  (void)m;
  return std::ldexp(1.0, e - 1);
}

std::string compact_glb(std::string_view glb, double quantum, TileEncoding encoding) {
  if (encoding == TileEncoding::plain) return std::string(glb);
  if (!(quantum > 0) || power_of_two_below(quantum) != quantum) bad("the quantum must be a power of two");
  if (glb.size() < 28 || u32_at(glb, 0) != 0x46546C67) bad("not a GLB");
  const uint32_t json_len = u32_at(glb, 12);
  if (20 + uint64_t{json_len} + 8 > glb.size()) bad("truncated");
  Json g = Json::parse(glb.substr(20, json_len));
  const uint32_t bin_len = u32_at(glb, 20 + json_len);
  const std::string_view bin = glb.substr(28 + json_len, bin_len);
  if (!g.contains("meshes") || g["meshes"].size() != 1 || g["nodes"].size() != 1 || g["buffers"].size() != 1)
    bad("a tile is one node with one mesh in one buffer");
  Json& node = g["nodes"][0];
  if (node.contains("matrix") || node.contains("translation") || node.contains("scale")) bad("the node already has a transform");
  const bool meshopt = encoding == TileEncoding::meshopt;
  Json& prims = g["meshes"][0]["primitives"];
  const size_t accessors = g["accessors"].size();

  // The grid over every POSITION of the mesh (one node transform serves all its primitives).
  Grid grid;
  for (const Json& p : prims) {
    uint64_t n;
    const std::vector<unsigned char> raw = read_accessor(g, bin, p["attributes"]["POSITION"].get<int>(), 12, &n);
    const float* x = reinterpret_cast<const float*>(raw.data());
    for (uint64_t v = 0; v < n; ++v)
      for (int k = 0; k < 3; ++k) {
        const int64_t q = grid_k(x[3 * v + k], quantum);
        grid.lo[k] = std::min(grid.lo[k], q), grid.hi[k] = std::max(grid.hi[k], q);
      }
  }
  grid.fits = true;
  for (int k = 0; k < 3; ++k) {
    grid.origin[k] = grid.lo[k] + (grid.hi[k] - grid.lo[k]) / 2;
    grid.fits = grid.fits && grid.lo[k] - grid.origin[k] >= -32768 && grid.hi[k] - grid.origin[k] <= 32767;
  }
  bool quantized = grid.fits;

  std::vector<Stream> streams(accessors);
  std::vector<char> done(accessors, 0);
  for (Json& p : prims) {
    Json& attrs = p["attributes"];
    const int position = attrs["POSITION"].get<int>();
    uint64_t vertices;
    std::vector<unsigned char> pos = read_accessor(g, bin, position, 12, &vertices);
    std::vector<std::pair<int, std::vector<unsigned char>>> others;  // (accessor, packed bytes)
    std::vector<uint32_t> elem_of;
    for (auto it = attrs.begin(); it != attrs.end(); ++it) {
      const int a = it.value().get<int>();
      if (a == position) continue;
      const Json& acc = g["accessors"][static_cast<size_t>(a)];
      uint64_t n;
      others.emplace_back(a, read_accessor(g, bin, a, element_bytes(acc), &n));
      if (n != vertices) bad("attribute counts differ");
      elem_of.push_back(element_bytes(acc));
    }
    std::vector<uint32_t> idx;
    const int indices = p.contains("indices") ? p["indices"].get<int>() : -1;
    if (indices >= 0) {
      if (g["accessors"][static_cast<size_t>(indices)]["componentType"] != kUnsignedInt) bad("indices must be uint32");
      uint64_t n;
      const std::vector<unsigned char> raw = read_accessor(g, bin, indices, 4, &n);
      idx.resize(n);
      std::memcpy(idx.data(), raw.data(), raw.size());
    }
    for (int a : {position, indices})
      if (a >= 0 && done[static_cast<size_t>(a)]) bad("an accessor is shared by two primitives");
    for (const auto& o : others)
      if (done[static_cast<size_t>(o.first)]) bad("an accessor is shared by two primitives");
    if (meshopt && indices >= 0 && p.value("mode", kTriangles) == kTriangles && !idx.empty()) {
      std::vector<std::vector<unsigned char>*> vs{&pos};
      std::vector<uint32_t> es{12};
      for (size_t i = 0; i < others.size(); ++i) vs.push_back(&others[i].second), es.push_back(elem_of[i]);
      reorder(idx, vs, es, vertices);
    }
    streams[static_cast<size_t>(position)] = encode_positions(pos, vertices, grid, quantum);
    done[static_cast<size_t>(position)] = 1;
    for (size_t i = 0; i < others.size(); ++i) {
      const auto a = static_cast<size_t>(others[i].first);
      const Json& acc = g["accessors"][a];
      if (attrs.contains("NORMAL") && attrs["NORMAL"].get<size_t>() == a && acc["componentType"] == kFloat) {
        streams[a] = encode_normals(others[i].second, vertices);
        quantized = true;
      } else {
        Stream s;
        s.count = vertices, s.stride = elem_of[i], s.component_type = acc["componentType"].get<int>();
        s.normalized = acc.value("normalized", false);
        if (s.stride % 4 != 0) bad("a vertex attribute is not 4-byte aligned");
        s.data = std::move(others[i].second);
        streams[a] = std::move(s);
      }
      done[a] = 1;
    }
    if (indices >= 0) {
      streams[static_cast<size_t>(indices)] = encode_indices(idx, vertices);
      done[static_cast<size_t>(indices)] = 1;
    }
  }
  for (size_t a = 0; a < accessors; ++a)
    if (!done[a]) bad("an accessor is used by no primitive");

  // One view per accessor, in accessor order: data in the BIN chunk, or (meshopt) compressed there with the
  // uncompressed layout in the fallback buffer.
  std::string out_bin;
  uint64_t fallback = 0;
  Json views = Json::array();
  for (size_t a = 0; a < accessors; ++a) {
    const Stream& s = streams[a];
    Json& acc = g["accessors"][a];
    acc["bufferView"] = a;
    acc["componentType"] = s.component_type;
    if (s.normalized) acc["normalized"] = true;
    else acc.erase("normalized");
    if (!s.min.is_null()) acc["min"] = s.min, acc["max"] = s.max;
    Json v;
    const uint64_t bytes = s.data.size();
    if (meshopt) {
      const std::vector<unsigned char> c = compress(s);
      v["buffer"] = 1;
      v["byteOffset"] = fallback;
      v["byteLength"] = bytes;
      if (!s.indices) v["byteStride"] = s.stride;
      v["target"] = s.indices ? kElementArrayBuffer : kArrayBuffer;
      Json e;
      e["buffer"] = 0;
      e["byteOffset"] = out_bin.size();
      e["byteLength"] = c.size();
      e["byteStride"] = s.stride;
      e["count"] = s.count;
      e["mode"] = s.indices ? "TRIANGLES" : "ATTRIBUTES";
      v["extensions"]["EXT_meshopt_compression"] = std::move(e);
      out_bin.append(reinterpret_cast<const char*>(c.data()), c.size());
      fallback += align4(bytes);
    } else {
      v["buffer"] = 0;
      v["byteOffset"] = out_bin.size();
      v["byteLength"] = bytes;
      if (!s.indices) v["byteStride"] = s.stride;
      v["target"] = s.indices ? kElementArrayBuffer : kArrayBuffer;
      out_bin.append(reinterpret_cast<const char*>(s.data.data()), bytes);
    }
    out_bin.resize(align4(out_bin.size()), '\0');
    views.push_back(std::move(v));
  }
  g["bufferViews"] = std::move(views);
  g["buffers"] = Json::array();
  g["buffers"].push_back(Json{{"byteLength", out_bin.size()}});
  if (meshopt) {
    Json fb;
    fb["byteLength"] = fallback;
    fb["extensions"]["EXT_meshopt_compression"]["fallback"] = true;
    g["buffers"].push_back(std::move(fb));
  }
  if (grid.fits) {
    node["translation"] = Json::array();
    for (int k = 0; k < 3; ++k) node["translation"].push_back(quantum * static_cast<double>(grid.origin[k]));
    node["scale"] = Json::array({quantum, quantum, quantum});
  }
  std::vector<std::string> required;
  if (quantized) required.push_back("KHR_mesh_quantization");
  if (meshopt) required.push_back("EXT_meshopt_compression");
  if (!required.empty()) {
    Json used = g.contains("extensionsUsed") ? g["extensionsUsed"] : Json::array();
    for (const std::string& r : required) used.push_back(r);
    g["extensionsUsed"] = std::move(used);
    g["extensionsRequired"] = required;
  }

  std::string json = g.dump();
  json.resize(align4(json.size()), ' ');
  std::string out;
  const uint32_t total = static_cast<uint32_t>(12 + 8 + json.size() + 8 + out_bin.size());
  auto put = [&](uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
  put(0x46546C67), put(2), put(total);
  put(static_cast<uint32_t>(json.size())), put(0x4E4F534A);
  out += json;
  put(static_cast<uint32_t>(out_bin.size())), put(0x004E4942);
  out += out_bin;
  return out;
}

}  // namespace lodstream::io
