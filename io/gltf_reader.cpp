// glTF 2.0 (Khronos, https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html), binary (.glb) and JSON
// (.gltf with .bin files or base64 data URIs), plus KHR_mesh_quantization and EXT_meshopt_compression
// (decoded with meshoptimizer when the build has it).
//
// The JSON is small next to the buffers and is parsed whole (nlohmann-json). open() validates it once:
// buffers, buffer views and every accessor a drawn primitive uses, with the JSON pointer at fault, and
// walks the scene's node trees (the default scene, or every root node when there is none) into a list of
// instances: (node, mesh, world matrix), one object id each. Nothing is expanded: an instanced mesh is
// read from its accessors again for every node that draws it.
//
// The work is the sequence, in instance order, of every (instance, primitive): first its POSITION
// elements (vertex chunks), then its primitives (element chunks: triangles, segments or points), each cut
// into chunks of a bounded number of elements, so a single huge primitive still streams. parse() maps
// only the buffer bytes of its chunk's element range (a window of the GLB, of a .bin, or a slice of a
// decoded data URI / meshopt view). Chunk fields: section = kind (bit 0: 0 vertices, 1 elements) |
// primitive index << 1; first_line = instance; first_record/record_count = element range. Chunks carry an
// empty window placed at the share of the work done, so the pipeline's progress (a file offset) advances.
//
// References are emitted local to their primitive's vertices; resolve() adds the global id of the
// primitive's first vertex (its first vertex chunk sets it, flagged by reader_state = 1).
//
// Modes (spec §3.7.2.1): strips p_i = (v_i, v_{i+1+i%2}, v_{i+2-i%2}), fans p_i = (v_{i+1}, v_{i+2}, v_0);
// strip triangles naming a vertex twice are left for the pipeline to count as degenerate.
// Bad data is exit 65 (Failure bad_data) with the JSON pointer ("FILE: /accessors/3: ...") or, for the
// GLB container, the byte offset. A buffer file that cannot be opened is bad data too (the glTF is
// incomplete), named by its pointer. Extensions in extensionsRequired that change geometry and are not
// supported are exit 64 (usage), named.
#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#ifdef LODSTREAM_HAVE_MESHOPT
#include <meshoptimizer.h>
#endif

#include "core/status.h"
#include "io/base64.h"
#include "io/reader.h"
#include "io/text.h"
#include "io/texture_mean.h"

namespace lodstream::io {
namespace {

using json = nlohmann::json;

constexpr uint32_t kChunkJson = 0x4E4F534A;
constexpr uint32_t kChunkBin = 0x004E4942;
// Data URIs are decoded into memory: they are small by nature (every byte is in the JSON, 4/3 larger).
constexpr uint64_t kMaxDataUriBytes = uint64_t{64} << 20;
// Decoded EXT_meshopt_compression views are held whole (meshopt decodes a view at once): this many bytes
// in all.
constexpr uint64_t kMaxMeshoptViewBytes = uint64_t{256} << 20;
// An accessor without a bufferView is zeros (plus sparse values): nothing in the file bounds its count, so
// this does, far above any real use (sparse morph targets and the like).
constexpr uint64_t kMaxZeroAccessorCount = uint64_t{1} << 24;

enum Mode : int { kPoints = 0, kLines = 1, kLineLoop = 2, kLineStrip = 3, kTriangles = 4, kStrip = 5, kFan = 6 };

uint32_t load_u32(const char* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  if constexpr (std::endian::native == std::endian::big) v = __builtin_bswap32(v);
  return v;
}

// Printable ASCII of at most 60 bytes, for names and URIs quoted in messages.
std::string printable(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size() && i < 60; ++i) {
    const auto c = static_cast<unsigned char>(s[i]);
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (s.size() > 60) out += "...";
  return out;
}

struct Buffer {
  uint64_t length = 0;                // byteLength
  uint64_t glb_offset = 0;            // kind glb: where the BIN chunk's data starts in the file
  std::unique_ptr<MappedFile> file;   // kind file
  std::vector<uint8_t> data;          // kind data URI (or decoded meshopt view)
  enum Kind { glb, external, memory } kind = memory;
  bool fallback = false;  // EXT_meshopt_compression fallback buffer without data: only compressed views use it
};

struct View {
  uint32_t buffer = 0;  // index into buffers_ (decoded meshopt views get buffers of their own)
  uint64_t offset = 0, length = 0, stride = 0;  // stride 0: tightly packed
};

struct Accessor {
  bool checked = false;
  int64_t view = -1;  // -1: zeros (then sparse)
  uint64_t offset = 0, count = 0, stride = 0;
  uint32_t component = 0, component_bytes = 0, components = 0;
  bool normalized = false;
  // sparse
  uint64_t sparse_count = 0;
  uint32_t sparse_index_view = 0, sparse_value_view = 0;
  uint64_t sparse_index_offset = 0, sparse_value_offset = 0;
  uint32_t sparse_index_component = 0, sparse_index_bytes = 0;
};

struct Primitive {
  uint32_t position = 0;
  int64_t indices = -1;
  int mode = kTriangles;
  int64_t material = -1;  // index into /materials, or -1: the default material
  int64_t color = -1;     // COLOR_0 accessor, or -1: white (the spec's default, a factor of 1)
  uint64_t vertices = 0;  // POSITION count
  uint64_t refs = 0;      // index count, or vertices when not indexed
  uint64_t elements = 0;  // triangles, segments or points
};

struct Instance {
  uint32_t node = 0, mesh = 0;
  double m[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};  // rows of the affine world matrix
};

// The bytes [begin, end) of a buffer: a mapped window, or a pointer into memory.
struct Bytes {
  Window window;
  const uint8_t* p = nullptr;
};

class GltfReader final : public Reader {
 public:
  GltfReader(const MappedFile& file, bool glb) : Reader(file), glb_(glb) {}

  std::string format() const override { return glb_ ? "glb" : "gltf"; }

  void open() override;
  bool next_chunk(uint64_t target_bytes, Chunk* chunk) override;
  void parse(const Chunk& chunk, ParsedChunk* out) const override;
  void resolve(ParsedChunk* chunk) override;
  bool has_colors() const override { return colors_; }
  bool single_precision() const override { return single_; }

 private:
  [[noreturn]] void bad(const std::string& pointer, const std::string& message) const {
    fail(Status::bad_data, file_.path() + ": " + pointer + ": " + message);
  }
  // Members of the JSON, type-checked, with the pointer of the member in every error.
  const json& member(const json& obj, const char* key, const std::string& pointer) const;
  uint64_t get_uint(const json& obj, const char* key, const std::string& pointer, uint64_t fallback, bool required,
                    uint64_t max = (uint64_t{1} << 53)) const;
  const json& array_at(const char* key, uint64_t index, const std::string& from) const;

  void read_container();
  void load_buffers();
  void load_views();
  void check_extensions();
  const Accessor& accessor(uint64_t index, const std::string& from);
  void check_range(uint64_t view, uint64_t offset, uint64_t count, uint64_t stride, uint64_t elem,
                   const std::string& pointer, const char* what);
  void load_meshes();
  void walk_scene();
  void load_materials();
  // The mean colour of a pbrMetallicRoughness object's baseColorTexture; false when there is none or it
  // cannot be read.
  bool base_color_texture(const json& pbr, float rgba[4]) const;

  Bytes bytes(const View& v, uint64_t begin, uint64_t end) const;
  // Reads elements [first, first + n) of accessor `a` as doubles (components per element), dequantized
  // when normalized, with sparse substitution. open() checked every byte range it can touch.
  void read(const Accessor& a, uint64_t first, uint64_t n, double* out) const;

  bool glb_;
  json doc_;
  uint64_t json_offset_ = 0;  // where the JSON starts in the file (for syntax errors)
  uint64_t bin_offset_ = 0, bin_length_ = 0;
  bool has_bin_ = false;
  std::vector<Buffer> buffers_;
  std::vector<View> views_;
  std::vector<Accessor> accessors_;
  std::vector<std::vector<Primitive>> meshes_;
  uint32_t default_material_ = 0;  // materials_ id of primitives without a material
  bool colors_ = false;            // some drawn primitive has COLOR_0
  // Every drawn POSITION is float (or 8/16-bit integers, not normalized) and every instance's world matrix
  // is the identity: positions are then exact floats and the store keeps them as such (half the bytes).
  bool single_ = false;
  std::vector<Instance> instances_;
  uint64_t decoded_bytes_ = 0;  // of EXT_meshopt_compression views

  // Cursor of next_chunk: instance, primitive, kind, element.
  uint64_t at_instance_ = 0, at_element_ = 0;
  uint32_t at_primitive_ = 0, at_kind_ = 0;
  uint64_t work_total_ = 0, work_done_ = 0;

  uint64_t vertices_ = 0, primitive_base_ = 0;
};

const json& GltfReader::member(const json& obj, const char* key, const std::string& pointer) const {
  static const json null_value;
  if (!obj.is_object()) bad(pointer, "expected a JSON object");
  const auto it = obj.find(key);
  return it == obj.end() ? null_value : *it;
}

uint64_t GltfReader::get_uint(const json& obj, const char* key, const std::string& pointer, uint64_t fallback,
                              bool required, uint64_t max) const {
  const json& v = member(obj, key, pointer);
  if (v.is_null()) {
    if (required) bad(pointer, std::string("missing '") + key + "'");
    return fallback;
  }
  if (v.is_number_unsigned()) {
    const uint64_t u = v.get<uint64_t>();
    if (u <= max) return u;
  } else if (v.is_number_integer() && v.get<int64_t>() >= 0 && static_cast<uint64_t>(v.get<int64_t>()) <= max) {
    return static_cast<uint64_t>(v.get<int64_t>());
  } else if (v.is_number_float()) {
    const double d = v.get<double>();
    if (d >= 0 && d <= static_cast<double>(max) && d == std::floor(d)) return static_cast<uint64_t>(d);
  }
  bad(pointer + "/" + key, "expected an integer from 0 to " + std::to_string(max) + ", found " +
                               printable(v.dump(-1, ' ', true, json::error_handler_t::replace)));
}

const json& GltfReader::array_at(const char* key, uint64_t index, const std::string& from) const {
  const json& arr = member(doc_, key, "");
  if (!arr.is_array() || index >= arr.size()) {
    bad(from, std::string(key) + " " + std::to_string(index) + " does not exist (the file has " +
                  std::to_string(arr.is_array() ? arr.size() : 0) + ")");
  }
  return arr[index];
}

void GltfReader::read_container() {
  const uint64_t size = file_.size();
  uint64_t json_begin = 0, json_end = size;
  if (glb_) {
    if (size < 20) fail_at_offset(file_, size, "truncated GLB: " + std::to_string(size) + " bytes, less than the 12-byte header and a chunk header");
    const Window head = file_.map(0, 20);
    const uint32_t version = load_u32(head.data() + 4);
    const uint32_t length = load_u32(head.data() + 8);
    if (version != 2) fail_at_offset(file_, 4, "GLB version " + std::to_string(version) + " (only 2 is supported)");
    if (length != size)
      fail_at_offset(file_, 8, "the GLB header says " + std::to_string(length) + " bytes but the file has " + std::to_string(size));
    const uint64_t json_length = load_u32(head.data() + 12);
    if (load_u32(head.data() + 16) != kChunkJson) fail_at_offset(file_, 16, "the first GLB chunk is not JSON");
    if (20 + json_length > size)
      fail_at_offset(file_, 12, "the JSON chunk says " + std::to_string(json_length) + " bytes but only " +
                                    std::to_string(size - 20) + " follow");
    json_begin = 20;
    json_end = 20 + json_length;
    uint64_t at = (json_end + 3) / 4 * 4;
    if (at > size) at = size;
    if (at < size) {
      if (size - at < 8) fail_at_offset(file_, at, "truncated GLB chunk header");
      const Window ch = file_.map(at, at + 8);
      const uint64_t bin_length = load_u32(ch.data());
      if (load_u32(ch.data() + 4) == kChunkBin) {
        if (at + 8 + bin_length > size)
          fail_at_offset(file_, at, "the BIN chunk says " + std::to_string(bin_length) + " bytes but only " +
                                        std::to_string(size - at - 8) + " follow");
        has_bin_ = true;
        bin_offset_ = at + 8;
        bin_length_ = bin_length;
      }
      // Other chunk types are to be ignored (spec §4.4.3.1).
    }
  }
  json_offset_ = json_begin;
  const Window text = file_.map(json_begin, json_end);
  try {
    doc_ = json::parse(text.view());
  } catch (const json::parse_error& e) {
    const uint64_t at = json_begin + (e.byte > 0 ? e.byte - 1 : 0);
    std::string what = e.what();
    const size_t colon = what.find("syntax error");
    fail_at_offset(file_, at, "bad JSON: " + printable(colon == std::string::npos ? what : what.substr(colon)));
  }
  if (!doc_.is_object()) fail_at_offset(file_, json_begin, "the glTF JSON is not an object");
  const json& asset = member(doc_, "asset", "");
  if (!asset.is_object()) bad("/asset", "missing or not an object");
  const json& version = member(asset, "version", "/asset");
  if (!version.is_string() || version.get<std::string>().rfind("2.", 0) != 0)
    bad("/asset/version", "glTF version " + printable(version.dump(-1, ' ', true, json::error_handler_t::replace)) + " (only 2.x is supported)");
}

void GltfReader::check_extensions() {
  const json& required = member(doc_, "extensionsRequired", "");
  if (required.is_null()) return;
  if (!required.is_array()) bad("/extensionsRequired", "expected an array");
  std::string unsupported;
  for (size_t i = 0; i < required.size(); ++i) {
    if (!required[i].is_string()) bad("/extensionsRequired/" + std::to_string(i), "expected a string");
    const std::string name = required[i].get<std::string>();
    // Extensions that do not change positions or primitives (materials, textures, lights) are fine.
    const bool geometry_neutral = name.rfind("KHR_materials_", 0) == 0 || name.rfind("KHR_texture_", 0) == 0 ||
                                  name == "EXT_texture_webp" || name == "KHR_lights_punctual";
    bool supported = geometry_neutral || name == "KHR_mesh_quantization";
#ifdef LODSTREAM_HAVE_MESHOPT
    supported = supported || name == "EXT_meshopt_compression";
#endif
    if (!supported) unsupported += (unsupported.empty() ? "" : ", ") + printable(name);
  }
  if (!unsupported.empty())
    fail(Status::usage, file_.path() + ": /extensionsRequired: unsupported glTF extension(s): " + unsupported);
}

void GltfReader::load_buffers() {
  const json& list = member(doc_, "buffers", "");
  if (list.is_null()) return;
  if (!list.is_array()) bad("/buffers", "expected an array");
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string ptr = "/buffers/" + std::to_string(i);
    const json& b = list[i];
    Buffer buf;
    buf.length = get_uint(b, "byteLength", ptr, 0, true);
    const json& uri = member(b, "uri", ptr);
    uint64_t available = 0;
    const json& ext = member(b, "extensions", ptr);
    const json& meshopt = ext.is_object() ? member(ext, "EXT_meshopt_compression", ptr + "/extensions") : ext;
    if (uri.is_null() && meshopt.is_object() && member(meshopt, "fallback", ptr).is_boolean() &&
        meshopt["fallback"].get<bool>() && !(glb_ && i == 0 && has_bin_)) {
      buf.fallback = true;
      buffers_.push_back(std::move(buf));
      continue;
    }
    if (uri.is_null()) {
      if (!glb_ || i != 0 || !has_bin_) bad(ptr, "no uri, and it is not the GLB's BIN chunk (missing buffer)");
      buf.kind = Buffer::glb;
      buf.glb_offset = bin_offset_;
      available = bin_length_;
    } else {
      if (!uri.is_string()) bad(ptr + "/uri", "expected a string");
      const std::string u = uri.get<std::string>();
      if (u.rfind("data:", 0) == 0) {
        const size_t comma = u.find(',');
        if (comma == std::string::npos || u.substr(0, comma).find(";base64") == std::string::npos)
          bad(ptr + "/uri", "a data URI that is not base64");
        const uint64_t encoded = u.size() - comma - 1;
        if (encoded / 4 * 3 > kMaxDataUriBytes)
          fail(Status::usage, file_.path() + ": " + ptr + "/uri: a data URI of about " + std::to_string(encoded / 4 * 3) +
                                  " bytes; data URIs are decoded into memory and limited to " +
                                  std::to_string(kMaxDataUriBytes) + " bytes: store the buffer in a .bin file");
        if (!base64_decode(std::string_view(u).substr(comma + 1), &buf.data))
          bad(ptr + "/uri", "bad base64 in the data URI");
        buf.kind = Buffer::memory;
        available = buf.data.size();
      } else {
        const std::string rel = text::percent_decode(u);
        if (rel.empty() || rel[0] == '/' || rel.find("://") != std::string::npos)
          bad(ptr + "/uri", "'" + printable(u) + "' is not a relative file reference");
        const std::string path =
            (std::filesystem::path(file_.path()).parent_path() / std::filesystem::path(rel)).string();
        try {
          buf.file = std::make_unique<MappedFile>(path);
        } catch (const Failure& f) {
          bad(ptr + "/uri", "missing buffer file '" + printable(rel) + "': " + f.what());
        }
        buf.kind = Buffer::external;
        available = buf.file->size();
      }
    }
    if (buf.length > available)
      bad(ptr + "/byteLength", "says " + std::to_string(buf.length) + " bytes but the data has " + std::to_string(available));
    buffers_.push_back(std::move(buf));
  }
}

void GltfReader::load_views() {
  const json& list = member(doc_, "bufferViews", "");
  if (list.is_null()) return;
  if (!list.is_array()) bad("/bufferViews", "expected an array");
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string ptr = "/bufferViews/" + std::to_string(i);
    const json& j = list[i];
    View v;
    const uint64_t buffer = get_uint(j, "buffer", ptr, 0, true);
    v.offset = get_uint(j, "byteOffset", ptr, 0, false);
    v.length = get_uint(j, "byteLength", ptr, 0, true);
    v.stride = get_uint(j, "byteStride", ptr, 0, false, 252);
    const json& ext = member(j, "extensions", ptr);
    const json& meshopt = ext.is_object() ? member(ext, "EXT_meshopt_compression", ptr + "/extensions") : ext;
    if (meshopt.is_object()) {
      const std::string mp = ptr + "/extensions/EXT_meshopt_compression";
#ifdef LODSTREAM_HAVE_MESHOPT
      const uint64_t src = get_uint(meshopt, "buffer", mp, 0, true);
      const uint64_t src_offset = get_uint(meshopt, "byteOffset", mp, 0, false);
      const uint64_t src_length = get_uint(meshopt, "byteLength", mp, 0, true);
      const uint64_t stride = get_uint(meshopt, "byteStride", mp, 0, true, 256);
      const uint64_t count = get_uint(meshopt, "count", mp, 0, true);
      const json& mode = member(meshopt, "mode", mp);
      const json& filter = member(meshopt, "filter", mp);
      if (src >= buffers_.size() || buffers_[src].fallback)
        bad(mp + "/buffer", "buffer " + std::to_string(src) + " does not exist or has no data");
      if (src_offset + src_length > buffers_[src].length)
        bad(mp, "bytes " + std::to_string(src_offset) + " + " + std::to_string(src_length) + " past the end of buffer " +
                    std::to_string(src) + " (" + std::to_string(buffers_[src].length) + " bytes)");
      decoded_bytes_ += count * stride;
      if (stride == 0 || decoded_bytes_ > kMaxMeshoptViewBytes)
        fail(Status::usage, file_.path() + ": " + mp + ": a compressed view of " + std::to_string(count) + " x " +
                                std::to_string(stride) + " bytes; decoded views are held in memory and limited to " +
                                "a total of " +
                                std::to_string(kMaxMeshoptViewBytes) + " bytes");
      if (!mode.is_string()) bad(mp + "/mode", "expected a string");
      const std::string m = mode.get<std::string>();
      View whole{static_cast<uint32_t>(src), src_offset, src_length, 0};
      const Bytes in = bytes(whole, 0, src_length);
      Buffer decoded;
      decoded.kind = Buffer::memory;
      decoded.data.resize(count * stride);
      int rc = -1;
      if (m == "ATTRIBUTES") {
        if (stride % 4 != 0) bad(mp + "/byteStride", "ATTRIBUTES needs a multiple of 4");
        rc = meshopt_decodeVertexBuffer(decoded.data.data(), count, stride, in.p, src_length);
      } else if (m == "TRIANGLES" || m == "INDICES") {
        if (stride != 2 && stride != 4) bad(mp + "/byteStride", "indices need 2 or 4");
        if (m == "TRIANGLES" && count % 3 != 0) bad(mp + "/count", "TRIANGLES needs a multiple of 3");
        rc = m == "TRIANGLES" ? meshopt_decodeIndexBuffer(decoded.data.data(), count, stride, in.p, src_length)
                              : meshopt_decodeIndexSequence(decoded.data.data(), count, stride, in.p, src_length);
      } else {
        bad(mp + "/mode", "unknown mode '" + printable(m) + "'");
      }
      if (rc != 0) bad(mp, "meshopt decoding failed (code " + std::to_string(rc) + ")");
      if (filter.is_string() && filter.get<std::string>() != "NONE") {
        const std::string f = filter.get<std::string>();
        if (f == "OCTAHEDRAL" && (stride == 4 || stride == 8))
          meshopt_decodeFilterOct(decoded.data.data(), count, stride);
        else if (f == "QUATERNION" && stride == 8)
          meshopt_decodeFilterQuat(decoded.data.data(), count, stride);
        else if (f == "EXPONENTIAL" && stride % 4 == 0)
          meshopt_decodeFilterExp(decoded.data.data(), count, stride);
        else
          bad(mp + "/filter", "filter '" + printable(f) + "' with byteStride " + std::to_string(stride));
      }
      decoded.length = decoded.data.size();
      v.buffer = static_cast<uint32_t>(buffers_.size());
      v.offset = 0;
      if (v.length > decoded.length)
        bad(ptr + "/byteLength", std::to_string(v.length) + " bytes but the decoded view has " + std::to_string(decoded.length));
      buffers_.push_back(std::move(decoded));
      views_.push_back(v);
      continue;
#else
      fail(Status::usage, file_.path() + ": " + mp + ": EXT_meshopt_compression is not supported by this build "
                                                     "(built without meshoptimizer)");
#endif
    }
    if (buffer >= buffers_.size()) bad(ptr + "/buffer", "buffer " + std::to_string(buffer) + " does not exist");
    if (buffers_[buffer].fallback)
      bad(ptr + "/buffer", "buffer " + std::to_string(buffer) + " is an EXT_meshopt_compression fallback with no data");
    if (v.offset + v.length > buffers_[buffer].length)
      bad(ptr, "bytes " + std::to_string(v.offset) + " + " + std::to_string(v.length) + " past the end of buffer " +
                   std::to_string(buffer) + " (" + std::to_string(buffers_[buffer].length) + " bytes)");
    if (v.stride != 0 && v.stride < 4) bad(ptr + "/byteStride", "byteStride " + std::to_string(v.stride) + " below 4");
    v.buffer = static_cast<uint32_t>(buffer);
    views_.push_back(v);
  }
}

uint32_t component_bytes(uint64_t type) {
  switch (type) {
    case 5120: case 5121: return 1;  // byte, unsigned byte
    case 5122: case 5123: return 2;  // short, unsigned short
    case 5125: case 5126: return 4;  // unsigned int, float
    default: return 0;
  }
}

void GltfReader::check_range(uint64_t view, uint64_t offset, uint64_t count, uint64_t stride, uint64_t elem,
                             const std::string& pointer, const char* what) {
  if (view >= views_.size()) bad(pointer, std::string(what) + ": bufferView " + std::to_string(view) + " does not exist");
  const View& v = views_[view];
  if (count == 0) return;
  uint64_t need = 0;
  const bool overflow = __builtin_mul_overflow(stride, count - 1, &need) || __builtin_add_overflow(need, offset, &need) ||
                        __builtin_add_overflow(need, elem, &need);
  if (overflow || need > v.length)
    bad(pointer, std::string(what) + ": count " + std::to_string(count) + " past the end of bufferView " +
                     std::to_string(view) + " (needs " + (overflow ? std::string("more than 2^64") : std::to_string(need)) +
" bytes from byteOffset " + std::to_string(offset) + ", the view has " + std::to_string(v.length) + ")");
}

const Accessor& GltfReader::accessor(uint64_t index, const std::string& from) {
  const json& j = array_at("accessors", index, from);
  Accessor& a = accessors_[index];
  if (a.checked) return a;
  const std::string ptr = "/accessors/" + std::to_string(index);
  a.component = static_cast<uint32_t>(get_uint(j, "componentType", ptr, 0, true, 1u << 20));
  a.component_bytes = component_bytes(a.component);
  if (a.component_bytes == 0) bad(ptr + "/componentType", "unknown componentType " + std::to_string(a.component));
  const json& type = member(j, "type", ptr);
  if (!type.is_string()) bad(ptr + "/type", "expected a string");
  const std::string t = type.get<std::string>();
  a.components = t == "SCALAR" ? 1 : t == "VEC2" ? 2 : t == "VEC3" ? 3 : t == "VEC4" ? 4 : t == "MAT2" ? 4 : t == "MAT3" ? 9 : t == "MAT4" ? 16 : 0;
  if (a.components == 0) bad(ptr + "/type", "unknown type '" + printable(t) + "'");
  a.count = get_uint(j, "count", ptr, 0, true);
  a.offset = get_uint(j, "byteOffset", ptr, 0, false);
  const json& normalized = member(j, "normalized", ptr);
  if (!normalized.is_null() && !normalized.is_boolean()) bad(ptr + "/normalized", "expected true or false");
  a.normalized = normalized.is_boolean() && normalized.get<bool>();
  const uint64_t elem = uint64_t{a.components} * a.component_bytes;
  if (!member(j, "bufferView", ptr).is_null()) {
    a.view = static_cast<int64_t>(get_uint(j, "bufferView", ptr, 0, true));
    if (static_cast<uint64_t>(a.view) >= views_.size())
      bad(ptr + "/bufferView", "bufferView " + std::to_string(a.view) + " does not exist");
    const View& v = views_[static_cast<size_t>(a.view)];
    a.stride = v.stride ? v.stride : elem;
    if (a.stride < elem) bad("/bufferViews/" + std::to_string(a.view) + "/byteStride",
                             "byteStride " + std::to_string(a.stride) + " below the element size " + std::to_string(elem) + " of " + ptr);
    if (a.offset % a.component_bytes != 0) bad(ptr + "/byteOffset", "not a multiple of the component size");
    check_range(static_cast<uint64_t>(a.view), a.offset, a.count, a.stride, elem, ptr, "accessor");
  } else {
    a.stride = elem;
    if (a.count > kMaxZeroAccessorCount)
      fail(Status::usage, file_.path() + ": " + ptr + "/count: " + std::to_string(a.count) +
                              " elements without a bufferView (zeros); at most " + std::to_string(kMaxZeroAccessorCount) +
                              " are supported");
  }
  const json& sparse = member(j, "sparse", ptr);
  if (!sparse.is_null()) {
    const std::string sp = ptr + "/sparse";
    a.sparse_count = get_uint(sparse, "count", sp, 0, true);
    if (a.sparse_count > a.count) bad(sp + "/count", std::to_string(a.sparse_count) + " above the accessor's count " + std::to_string(a.count));
    const json& idx = member(sparse, "indices", sp);
    const json& val = member(sparse, "values", sp);
    if (!idx.is_object()) bad(sp + "/indices", "missing or not an object");
    if (!val.is_object()) bad(sp + "/values", "missing or not an object");
    a.sparse_index_view = static_cast<uint32_t>(get_uint(idx, "bufferView", sp + "/indices", 0, true, UINT32_MAX));
    a.sparse_index_offset = get_uint(idx, "byteOffset", sp + "/indices", 0, false);
    a.sparse_index_component = static_cast<uint32_t>(get_uint(idx, "componentType", sp + "/indices", 0, true, 1u << 20));
    if (a.sparse_index_component != 5121 && a.sparse_index_component != 5123 && a.sparse_index_component != 5125)
      bad(sp + "/indices/componentType", "not an unsigned integer type");
    a.sparse_index_bytes = component_bytes(a.sparse_index_component);
    a.sparse_value_view = static_cast<uint32_t>(get_uint(val, "bufferView", sp + "/values", 0, true, UINT32_MAX));
    a.sparse_value_offset = get_uint(val, "byteOffset", sp + "/values", 0, false);
    check_range(a.sparse_index_view, a.sparse_index_offset, a.sparse_count, a.sparse_index_bytes, a.sparse_index_bytes,
                sp + "/indices", "sparse indices");
    check_range(a.sparse_value_view, a.sparse_value_offset, a.sparse_count, elem, elem, sp + "/values", "sparse values");
    // Strictly increasing and below count (spec), so parse() can binary-search them.
    const View& iv = views_[a.sparse_index_view];
    const uint64_t step = uint64_t{1} << 16;
    uint64_t previous = 0;
    for (uint64_t first = 0; first < a.sparse_count; first += step) {
      const uint64_t n = std::min(step, a.sparse_count - first);
      const uint64_t b = a.sparse_index_offset + first * a.sparse_index_bytes;
      const Bytes span = bytes(iv, b, b + n * a.sparse_index_bytes);
      for (uint64_t k = 0; k < n; ++k) {
        const uint8_t* p = span.p + k * a.sparse_index_bytes;
        uint64_t v = a.sparse_index_bytes == 1 ? p[0] : a.sparse_index_bytes == 2 ? uint64_t{p[0]} | uint64_t{p[1]} << 8 : uint64_t{load_u32(reinterpret_cast<const char*>(p))};
        if (v >= a.count || (first + k > 0 && v <= previous))
          bad(sp + "/indices", "sparse index " + std::to_string(first + k) + " is " + std::to_string(v) +
                                   (v >= a.count ? ", not below the accessor's count " + std::to_string(a.count)
                                                 : ", not above the one before it"));
        previous = v;
      }
    }
  }
  a.checked = true;
  return a;
}

void GltfReader::load_meshes() {
  const json& list = member(doc_, "meshes", "");
  if (list.is_null()) return;
  if (!list.is_array()) bad("/meshes", "expected an array");
  meshes_.resize(list.size());  // primitives filled by walk_scene() when a node first draws the mesh
}

void multiply(const double* a, const double* b, double* out) {  // 3x4 affine rows: out = a * b
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      double s = a[r * 4 + 0] * b[0 * 4 + c] + a[r * 4 + 1] * b[1 * 4 + c] + a[r * 4 + 2] * b[2 * 4 + c];
      if (c == 3) s += a[r * 4 + 3];
      out[r * 4 + c] = s;
    }
  }
}

void GltfReader::walk_scene() {
  const json& nodes = member(doc_, "nodes", "");
  if (!nodes.is_null() && !nodes.is_array()) bad("/nodes", "expected an array");
  const size_t node_count = nodes.is_array() ? nodes.size() : 0;
  std::vector<bool> mesh_checked(meshes_.size(), false);

  auto check_mesh = [&](uint64_t mesh, const std::string& from) {
    if (mesh >= meshes_.size()) bad(from, "mesh " + std::to_string(mesh) + " does not exist");
    if (mesh_checked[mesh]) return;
    mesh_checked[mesh] = true;
    const std::string mp = "/meshes/" + std::to_string(mesh);
    const json& prims = member(doc_["meshes"][mesh], "primitives", mp);
    if (!prims.is_array()) bad(mp + "/primitives", "missing or not an array");
    for (size_t p = 0; p < prims.size(); ++p) {
      const std::string pp = mp + "/primitives/" + std::to_string(p);
      Primitive prim;
      prim.mode = static_cast<int>(get_uint(prims[p], "mode", pp, kTriangles, false, 6));
      if (!member(prims[p], "material", pp).is_null())
        prim.material = static_cast<int64_t>(get_uint(prims[p], "material", pp, 0, true));
      const json& attributes = member(prims[p], "attributes", pp);
      if (!attributes.is_object()) bad(pp + "/attributes", "missing or not an object");
      if (member(attributes, "POSITION", pp + "/attributes").is_null()) {
        meshes_[mesh].push_back(prim);  // nothing to draw (spec: the client ignores it); keeps indices aligned
        continue;
      }
      prim.position = static_cast<uint32_t>(get_uint(attributes, "POSITION", pp + "/attributes", 0, true, UINT32_MAX));
      const Accessor& pos = accessor(prim.position, pp + "/attributes/POSITION");
      if (pos.components != 3 || (pos.component == 5125))
        bad("/accessors/" + std::to_string(prim.position), "POSITION must be VEC3 of float or (KHR_mesh_quantization) 8/16-bit integers");
      prim.vertices = pos.count;
      prim.refs = pos.count;
      if (!member(attributes, "COLOR_0", pp + "/attributes").is_null()) {
        prim.color = static_cast<int64_t>(get_uint(attributes, "COLOR_0", pp + "/attributes", 0, true, UINT32_MAX));
        const Accessor& col = accessor(static_cast<uint64_t>(prim.color), pp + "/attributes/COLOR_0");
        const bool float_type = col.component == 5126 && !col.normalized;
        const bool unorm = (col.component == 5121 || col.component == 5123) && col.normalized;
        if ((col.components != 3 && col.components != 4) || !(float_type || unorm))
          bad("/accessors/" + std::to_string(prim.color), "COLOR_0 must be VEC3 or VEC4 of float, or of normalized unsigned byte or short");
        if (col.count != pos.count)
          bad("/accessors/" + std::to_string(prim.color), "COLOR_0 has " + std::to_string(col.count) + " elements, POSITION " +
                                                              std::to_string(pos.count));
        colors_ = true;
      }
      if (!member(prims[p], "indices", pp).is_null()) {
        prim.indices = static_cast<int64_t>(get_uint(prims[p], "indices", pp, 0, true, UINT32_MAX));
        const Accessor& idx = accessor(static_cast<uint64_t>(prim.indices), pp + "/indices");
        if (idx.components != 1 || (idx.component != 5121 && idx.component != 5123 && idx.component != 5125))
          bad("/accessors/" + std::to_string(prim.indices), "indices must be SCALAR unsigned byte, short or int");
        prim.refs = idx.count;
      }
      const uint64_t n = prim.refs;
      const std::string what = prim.indices >= 0 ? "index count " : "vertex count ";
      switch (prim.mode) {
        case kTriangles:
          if (n % 3) bad(pp, "TRIANGLES with " + what + std::to_string(n) + ", not a multiple of 3");
          prim.elements = n / 3;
          break;
        case kStrip: case kFan: prim.elements = n >= 3 ? n - 2 : 0; break;
        case kLines:
          if (n % 2) bad(pp, "LINES with " + what + std::to_string(n) + ", not a multiple of 2");
          prim.elements = n / 2;
          break;
        case kLineStrip: prim.elements = n >= 2 ? n - 1 : 0; break;
        case kLineLoop: prim.elements = n >= 2 ? n : 0; break;
        default: prim.elements = n; break;  // points
      }
      meshes_[mesh].push_back(prim);
    }
  };

  auto local_matrix = [&](size_t i, double* m) {
    const std::string np = "/nodes/" + std::to_string(i);
    const json& n = nodes[i];
    auto numbers = [&](const char* key, size_t count, double* out) {
      const json& a = member(n, key, np);
      if (a.is_null()) return false;
      if (!a.is_array() || a.size() != count) bad(np + "/" + key, "expected an array of " + std::to_string(count) + " numbers");
      for (size_t k = 0; k < count; ++k) {
        if (!a[k].is_number()) bad(np + "/" + key + "/" + std::to_string(k), "expected a number");
        out[k] = a[k].get<double>();
        if (!std::isfinite(out[k])) bad(np + "/" + key + "/" + std::to_string(k), "not finite");
      }
      return true;
    };
    double mat[16];
    if (numbers("matrix", 16, mat)) {  // column-major
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) m[r * 4 + c] = mat[c * 4 + r];
      return;
    }
    double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
    numbers("translation", 3, t);
    numbers("rotation", 4, q);
    numbers("scale", 3, s);
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
                         2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                         2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y)};
    for (int row = 0; row < 3; ++row) {
      for (int c = 0; c < 3; ++c) m[row * 4 + c] = r[row * 3 + c] * s[c];
      m[row * 4 + 3] = t[row];
    }
  };

  // Roots: the default scene's nodes, else every node no other node has as a child.
  std::vector<std::pair<uint64_t, std::string>> roots;
  const json& scene = member(doc_, "scene", "");
  if (!scene.is_null()) {
    const uint64_t s = get_uint(doc_, "scene", "", 0, true);
    const json& sc = array_at("scenes", s, "/scene");
    const std::string sp = "/scenes/" + std::to_string(s);
    const json& list = member(sc, "nodes", sp);
    if (!list.is_null() && !list.is_array()) bad(sp + "/nodes", "expected an array");
    for (size_t k = 0; list.is_array() && k < list.size(); ++k) {
      const std::string kp = sp + "/nodes/" + std::to_string(k);
      if (!list[k].is_number_unsigned() || list[k].get<uint64_t>() >= node_count)
        bad(kp, "not the index of a node (the file has " + std::to_string(node_count) + ")");
      roots.emplace_back(list[k].get<uint64_t>(), kp);
    }
  } else {
    std::vector<bool> child(node_count, false);
    for (size_t i = 0; i < node_count; ++i) {
      const json& c = member(nodes[i], "children", "/nodes/" + std::to_string(i));
      for (size_t k = 0; c.is_array() && k < c.size(); ++k)
        if (c[k].is_number_unsigned() && c[k].get<uint64_t>() < node_count) child[c[k].get<uint64_t>()] = true;
    }
    for (size_t i = 0; i < node_count; ++i)
      if (!child[i]) roots.emplace_back(i, "/nodes/" + std::to_string(i));
    if (node_count == 0) {
      // No nodes at all: every mesh once, untransformed.
      for (size_t mesh = 0; mesh < meshes_.size(); ++mesh) {
        check_mesh(mesh, "/meshes");
        Instance inst;
        inst.node = UINT32_MAX;
        inst.mesh = static_cast<uint32_t>(mesh);
        instances_.push_back(inst);
        object_names_.push_back("mesh " + std::to_string(mesh));
      }
    }
  }

  // Depth-first, iterative (deep chains do not overflow the stack): 1 = on the current path, 2 = done.
  std::vector<uint8_t> state(node_count, 0);
  struct Frame {
    uint64_t node;
    double m[12];
    size_t next_child;
  };
  std::vector<Frame> stack;
  for (const auto& [root, root_pointer] : roots) {
    if (state[root]) bad(root_pointer, "node " + std::to_string(root) + " is listed twice or is also a child");
    stack.push_back(Frame{root, {}, 0});
    local_matrix(root, stack.back().m);
    state[root] = 1;
    bool entered = true;
    while (!stack.empty()) {
      Frame& f = stack.back();
      const std::string np = "/nodes/" + std::to_string(f.node);
      if (entered) {
        entered = false;
        for (double v : f.m)
          if (!std::isfinite(v)) bad(np, "the world matrix overflows");
        const json& mesh = member(nodes[f.node], "mesh", np);
        if (!mesh.is_null()) {
          const uint64_t m = get_uint(nodes[f.node], "mesh", np, 0, true, UINT32_MAX);
          check_mesh(m, np + "/mesh");
          Instance inst;
          inst.node = static_cast<uint32_t>(f.node);
          inst.mesh = static_cast<uint32_t>(m);
          std::copy(f.m, f.m + 12, inst.m);
          instances_.push_back(inst);
          const json& name = member(nodes[f.node], "name", np);
          object_names_.push_back(name.is_string() && !name.get<std::string>().empty() ? name.get<std::string>()
                                                                                       : "node " + std::to_string(f.node));
        }
      }
      const json& children = member(nodes[f.node], "children", np);
      if (!children.is_null() && !children.is_array()) bad(np + "/children", "expected an array");
      if (children.is_null() || f.next_child >= children.size()) {
        state[f.node] = 2;
        stack.pop_back();
        continue;
      }
      const size_t k = f.next_child++;
      const std::string cp = np + "/children/" + std::to_string(k);
      if (!children[k].is_number_unsigned() || children[k].get<uint64_t>() >= node_count)
        bad(cp, "not the index of a node (the file has " + std::to_string(node_count) + ")");
      const uint64_t c = children[k].get<uint64_t>();
      if (state[c] == 1) bad(cp, "cycle: node " + std::to_string(c) + " is an ancestor of node " + std::to_string(f.node));
      if (state[c] == 2) bad(cp, "node " + std::to_string(c) + " has more than one parent");
      Frame child{c, {}, 0};
      double local[12];
      local_matrix(c, local);
      multiply(f.m, local, child.m);
      state[c] = 1;
      stack.push_back(child);
      entered = true;
    }
  }
}

void GltfReader::open() {
  object_names_.clear();
  read_container();
  check_extensions();
  load_buffers();
  load_views();
  const json& acc = member(doc_, "accessors", "");
  if (!acc.is_null() && !acc.is_array()) bad("/accessors", "expected an array");
  accessors_.resize(acc.is_array() ? acc.size() : 0);
  load_meshes();
  walk_scene();
  single_ = true;
  static const double identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  for (const Instance& inst : instances_) {
    if (!std::equal(inst.m, inst.m + 12, identity)) single_ = false;
    for (const Primitive& p : meshes_[inst.mesh]) {
      if (p.vertices == 0) continue;
      const Accessor& a = accessors_[p.position];
      if (!(a.component == 5126 || ((a.component == 5120 || a.component == 5121 || a.component == 5122 || a.component == 5123) && !a.normalized)))
        single_ = false;
    }
  }
  load_materials();
  if (object_names_.empty()) object_names_.emplace_back();
  for (const Instance& inst : instances_)
    for (const Primitive& p : meshes_[inst.mesh]) work_total_ += p.vertices + p.elements;
}

// Materials (glTF 2.0 §3.9): the metallic-roughness factors, alphaMode, alphaCutoff and doubleSided of every
// entry of /materials, in order; primitives without one get the spec's default material (white, metallic 1,
// roughness 1, opaque, single-sided), appended after them. The levels carry no texture coordinates, so a
// base colour texture is reduced to its mean colour (io/texture_mean.h), which multiplies the factor: the
// image of /textures/i/source, from a bufferView (GLB or .bin), a data URI or a file beside the glTF. A
// texture that cannot be found or decoded leaves the factor alone (the geometry still reads). No
// /materials and no primitive naming one: no materials at all.
void GltfReader::load_materials() {
  const json& mats = member(doc_, "materials", "");
  if (!mats.is_null() && !mats.is_array()) bad("/materials", "expected an array");
  const size_t count = mats.is_array() ? mats.size() : 0;
  bool any_default = false, any_named = false;
  for (const Instance& inst : instances_)
    for (const Primitive& p : meshes_[inst.mesh]) {
      if (p.material >= static_cast<int64_t>(count))
        bad("/meshes/" + std::to_string(inst.mesh), "material " + std::to_string(p.material) + " does not exist");
      (p.material < 0 ? any_default : any_named) = true;
    }
  if (!any_named) return;
  auto number = [&](const json& obj, const char* key, const std::string& pointer, double fallback) {
    const json& v = member(obj, key, pointer);
    if (v.is_null()) return fallback;
    if (!v.is_number() || !std::isfinite(v.get<double>())) bad(pointer + "/" + key, "expected a number");
    return std::clamp(v.get<double>(), 0.0, 1.0);
  };
  for (size_t i = 0; i < count; ++i) {
    const std::string mp = "/materials/" + std::to_string(i);
    const json& m = mats[i];
    if (!m.is_object()) bad(mp, "expected an object");
    core::Material out;
    out.metallic = 1;  // the glTF defaults
    out.double_sided = false;
    const json& name = member(m, "name", mp);
    if (name.is_string()) out.name = name.get<std::string>();
    const json& pbr = member(m, "pbrMetallicRoughness", mp);
    if (pbr.is_object()) {
      const json& c = member(pbr, "baseColorFactor", mp + "/pbrMetallicRoughness");
      if (!c.is_null()) {
        if (!c.is_array() || c.size() != 4) bad(mp + "/pbrMetallicRoughness/baseColorFactor", "expected 4 numbers");
        for (size_t k = 0; k < 4; ++k) {
          if (!c[k].is_number() || !std::isfinite(c[k].get<double>()))
            bad(mp + "/pbrMetallicRoughness/baseColorFactor", "expected 4 numbers");
          out.base_color[k] = static_cast<float>(std::clamp(c[k].get<double>(), 0.0, 1.0));
        }
      }
      float texel[4];
      if (base_color_texture(pbr, texel))
        for (int k = 0; k < 4; ++k) out.base_color[k] *= texel[k];
      out.metallic = static_cast<float>(number(pbr, "metallicFactor", mp + "/pbrMetallicRoughness", 1));
      out.roughness = static_cast<float>(number(pbr, "roughnessFactor", mp + "/pbrMetallicRoughness", 1));
    }
    const json& mode = member(m, "alphaMode", mp);
    if (mode.is_string()) {
      const std::string s = mode.get<std::string>();
      out.alpha = s == "MASK" ? core::Material::Alpha::mask : s == "BLEND" ? core::Material::Alpha::blend : core::Material::Alpha::opaque;
    }
    const json& cutoff = member(m, "alphaCutoff", mp);
    if (cutoff.is_number() && std::isfinite(cutoff.get<double>()) && cutoff.get<double>() >= 0)
      out.alpha_cutoff = static_cast<float>(cutoff.get<double>());
    const json& two = member(m, "doubleSided", mp);
    if (two.is_boolean()) out.double_sided = two.get<bool>();
    materials_.push_back(std::move(out));
  }
  default_material_ = static_cast<uint32_t>(materials_.size());
  if (any_default) {
    core::Material d;
    d.metallic = 1;
    d.double_sided = false;
    materials_.push_back(d);
  }
}

bool GltfReader::next_chunk(uint64_t target_bytes, Chunk* chunk) {
  while (at_instance_ < instances_.size()) {
    const std::vector<Primitive>& prims = meshes_[instances_[at_instance_].mesh];
    if (at_primitive_ >= prims.size()) {
      ++at_instance_;
      at_primitive_ = 0;
      at_kind_ = 0;
      at_element_ = 0;
      continue;
    }
    const Primitive& p = prims[at_primitive_];
    const uint64_t total = at_kind_ == 0 ? p.vertices : p.elements;
    // Every primitive has one vertex chunk even with no vertices: it sets the primitive's base in resolve().
    if (at_element_ >= total && !(at_kind_ == 0 && at_element_ == 0)) {
      if (at_kind_ == 0) {
        at_kind_ = 1;
      } else {
        ++at_primitive_;
        at_kind_ = 0;
      }
      at_element_ = 0;
      continue;
    }
    // About target_bytes of parsed output: 24 bytes per vertex (x, y, z as doubles), 8 per reference (plus
    // the scratch copy of the indices the elements read).
    const uint64_t arity = p.mode == kPoints ? 1 : p.mode <= kLineStrip ? 2 : 3;
    const uint64_t max_elements = std::max<uint64_t>(1, target_bytes / (at_kind_ == 0 ? 24 : 16 * arity));
    const uint64_t n = std::min(max_elements, total - at_element_);
    chunk->section = at_kind_ | (at_primitive_ << 1);
    chunk->first_line = at_instance_;
    chunk->first_record = at_element_;
    chunk->record_count = n;
    work_done_ += n;
    const uint64_t progress = work_total_ ? static_cast<uint64_t>(static_cast<double>(file_.size()) *
                                                                  static_cast<double>(work_done_) / static_cast<double>(work_total_))
                                          : file_.size();
    chunk->bytes = file_.map(progress, progress);
    at_element_ += n;
    if (n == 0) at_element_ = 1;  // the empty vertex chunk is done
    return true;
  }
  return false;
}

bool GltfReader::base_color_texture(const json& pbr, float rgba[4]) const {
  auto index = [](const json& obj, const char* key, int64_t* out) {
    if (!obj.is_object() || !obj.contains(key) || !obj[key].is_number_unsigned()) return false;
    *out = obj[key].get<int64_t>();
    return true;
  };
  auto element = [&](const char* key, int64_t i) -> const json* {
    if (!doc_.contains(key) || !doc_[key].is_array() || i < 0 || static_cast<size_t>(i) >= doc_[key].size()) return nullptr;
    return &doc_[key][static_cast<size_t>(i)];
  };
  int64_t t = 0, source = 0, view = 0;
  if (!pbr.contains("baseColorTexture") || !index(pbr["baseColorTexture"], "index", &t)) return false;
  const json* texture = element("textures", t);
  if (!texture || !index(*texture, "source", &source)) return false;
  const json* image = element("images", source);
  if (!image || !image->is_object()) return false;
  std::string error;
  if (index(*image, "bufferView", &view)) {
    if (static_cast<size_t>(view) >= views_.size()) return false;
    const View& v = views_[static_cast<size_t>(view)];
    const Bytes b = bytes(v, 0, v.length);
    return texture_mean_color(std::span<const uint8_t>(b.p, v.length), rgba, &error);
  }
  if (!image->contains("uri") || !(*image)["uri"].is_string()) return false;
  const std::string u = (*image)["uri"].get<std::string>();
  if (u.rfind("data:", 0) == 0) {
    const size_t comma = u.find(',');
    std::vector<uint8_t> data;
    if (comma == std::string::npos || u.substr(0, comma).find(";base64") == std::string::npos ||
        !base64_decode(std::string_view(u).substr(comma + 1), &data))
      return false;
    return texture_mean_color(data, rgba, &error);
  }
  const std::string rel = text::percent_decode(u);
  if (rel.empty() || rel[0] == '/' || rel.find("://") != std::string::npos) return false;
  return texture_file_mean_color((std::filesystem::path(file_.path()).parent_path() / rel).string(), rgba, &error);
}

Bytes GltfReader::bytes(const View& v, uint64_t begin, uint64_t end) const {
  const Buffer& b = buffers_[v.buffer];
  Bytes out;
  if (b.kind == Buffer::memory) {
    out.p = b.data.data() + v.offset + begin;
    return out;
  }
  const MappedFile& f = b.kind == Buffer::glb ? file_ : *b.file;
  const uint64_t base = (b.kind == Buffer::glb ? b.glb_offset : 0) + v.offset;
  out.window = f.map(base + begin, base + end);
  out.p = reinterpret_cast<const uint8_t*>(out.window.data());
  return out;
}

template <class T>
T load(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

double component(const uint8_t* p, uint32_t type, bool normalized) {
  switch (type) {
    case 5120: { const double c = static_cast<int8_t>(p[0]); return normalized ? std::max(c / 127.0, -1.0) : c; }
    case 5121: { const double c = p[0]; return normalized ? c / 255.0 : c; }
    case 5122: { const double c = load<int16_t>(p); return normalized ? std::max(c / 32767.0, -1.0) : c; }
    case 5123: { const double c = load<uint16_t>(p); return normalized ? c / 65535.0 : c; }
    case 5125: return load<uint32_t>(p);
    default: return load<float>(p);
  }
}

void GltfReader::read(const Accessor& a, uint64_t first, uint64_t n, double* out) const {
  const uint32_t comps = a.components;
  if (n == 0) return;
  if (a.view >= 0) {
    const Bytes span = bytes(views_[static_cast<size_t>(a.view)], a.offset + first * a.stride,
                             a.offset + (first + n - 1) * a.stride + uint64_t{comps} * a.component_bytes);
    // Float and uint32 (POSITION and indices, nearly always) without the per-component type switch.
    if (a.component == 5126) {
      for (uint64_t i = 0; i < n; ++i)
        for (uint32_t c = 0; c < comps; ++c) out[i * comps + c] = load<float>(span.p + i * a.stride + 4 * c);
    } else if (a.component == 5125) {
      for (uint64_t i = 0; i < n; ++i)
        for (uint32_t c = 0; c < comps; ++c) out[i * comps + c] = load<uint32_t>(span.p + i * a.stride + 4 * c);
    } else {
      for (uint64_t i = 0; i < n; ++i)
        for (uint32_t c = 0; c < comps; ++c)
          out[i * comps + c] = component(span.p + i * a.stride + c * a.component_bytes, a.component, a.normalized);
    }
  } else {
    std::fill(out, out + n * comps, 0.0);
  }
  if (a.sparse_count) {
    const View& iv = views_[a.sparse_index_view];
    const Bytes idx = bytes(iv, a.sparse_index_offset, a.sparse_index_offset + a.sparse_count * a.sparse_index_bytes);
    auto index_at = [&](uint64_t k) {
      const uint8_t* p = idx.p + k * a.sparse_index_bytes;
      return a.sparse_index_bytes == 1 ? uint64_t{p[0]} : a.sparse_index_bytes == 2 ? uint64_t{load<uint16_t>(p)} : uint64_t{load<uint32_t>(p)};
    };
    uint64_t lo = 0, hi = a.sparse_count;  // first sparse entry with index >= first
    while (lo < hi) {
      const uint64_t mid = lo + (hi - lo) / 2;
      if (index_at(mid) < first) lo = mid + 1;
      else hi = mid;
    }
    uint64_t end = lo;
    while (end < a.sparse_count && index_at(end) < first + n) ++end;
    if (end > lo) {
      const uint64_t elem = uint64_t{comps} * a.component_bytes;
      const Bytes vals = bytes(views_[a.sparse_value_view], a.sparse_value_offset + lo * elem, a.sparse_value_offset + end * elem);
      for (uint64_t k = lo; k < end; ++k) {
        const uint64_t i = index_at(k) - first;
        for (uint32_t c = 0; c < comps; ++c)
          out[i * comps + c] = component(vals.p + (k - lo) * elem + c * a.component_bytes, a.component, a.normalized);
      }
    }
  }
}

void GltfReader::parse(const Chunk& chunk, ParsedChunk* out) const {
  const Instance& inst = instances_[chunk.first_line];
  const uint32_t prim_index = chunk.section >> 1;
  const Primitive& p = meshes_[inst.mesh][prim_index];
  const uint64_t first = chunk.first_record, n = chunk.record_count;
  const uint32_t object = static_cast<uint32_t>(chunk.first_line);
  auto error = [&](std::string message) {
    out->error.set = true;
    out->error.message = std::move(message);
  };

  if ((chunk.section & 1) == 0) {
    out->reader_state = first == 0 ? 1 : 0;
    if (n == 0) return;
    out->positions.resize(3 * n);
    double* v = out->positions.data();
    read(accessors_[p.position], first, n, v);
    const double* m = inst.m;
    for (uint64_t i = 0; i < n; ++i, v += 3) {
      const double x = v[0], y = v[1], z = v[2];
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
        return error("/accessors/" + std::to_string(p.position) + ": non-finite POSITION at element " + std::to_string(first + i));
      v[0] = m[0] * x + m[1] * y + m[2] * z + m[3];
      v[1] = m[4] * x + m[5] * y + m[6] * z + m[7];
      v[2] = m[8] * x + m[9] * y + m[10] * z + m[11];
      if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
        return error("/nodes/" + std::to_string(inst.node) + ": POSITION element " + std::to_string(first + i) +
                     " of accessor " + std::to_string(p.position) + " overflows under the node's transform");
    }
    if (colors_) {
      // COLOR_0 values as they are (linear, as glTF defines them and the GLB writer writes them back),
      // clamped to [0, 1] and rounded to bytes; VEC3 is opaque; no COLOR_0 is white (a factor of 1).
      out->colors.assign(4 * n, 255);
      if (p.color >= 0) {
        const Accessor& a = accessors_[static_cast<size_t>(p.color)];
        std::vector<double> c(n * a.components);
        read(a, first, n, c.data());
        for (uint64_t i = 0; i < n; ++i)
          for (uint32_t k = 0; k < a.components; ++k) {
            const double x = c[i * a.components + k];
            if (!std::isfinite(x))
              return error("/accessors/" + std::to_string(p.color) + ": non-finite COLOR_0 at element " + std::to_string(first + i));
            out->colors[4 * i + k] = static_cast<uint8_t>(std::lround(std::clamp(x, 0.0, 1.0) * 255));
          }
      }
    }
    return;
  }

  // The references elements [first, first + n) read: [lo, hi), plus reference 0 for fans and loops.
  uint64_t lo = 0, hi = 0;
  int arity = 3;
  switch (p.mode) {
    case kTriangles: lo = 3 * first, hi = 3 * (first + n); break;
    case kStrip: case kFan: lo = first, hi = first + n + 2; break;
    case kLines: lo = 2 * first, hi = 2 * (first + n), arity = 2; break;
    case kLineStrip: lo = first, hi = first + n + 1, arity = 2; break;
    case kLineLoop: lo = first, hi = std::min(first + n + 1, p.refs), arity = 2; break;
    default: lo = first, hi = first + n, arity = 1; break;
  }
  std::vector<double> refs(hi - lo + 1);
  double* r = refs.data() + 1;  // r[k - lo]; refs[0] holds reference 0
  if (p.indices >= 0) {
    const Accessor& ia = accessors_[static_cast<size_t>(p.indices)];
    read(ia, 0, 1, refs.data());
    read(ia, lo, hi - lo, r);
    const bool need_zero = p.mode == kFan || (p.mode == kLineLoop && first + n == p.elements);
    if (need_zero && refs[0] >= static_cast<double>(p.vertices))
      return error("/accessors/" + std::to_string(p.indices) + ": index 0 is " + std::to_string(static_cast<uint64_t>(refs[0])) +
                   ", past the " + std::to_string(p.vertices) + " vertices of POSITION accessor " + std::to_string(p.position));
    for (uint64_t k = lo; k < hi; ++k)
      if (r[k - lo] >= static_cast<double>(p.vertices))
        return error("/accessors/" + std::to_string(p.indices) + ": index " + std::to_string(k) + " is " +
                     std::to_string(static_cast<uint64_t>(r[k - lo])) + ", past the " + std::to_string(p.vertices) +
                     " vertices of POSITION accessor " + std::to_string(p.position));
  } else {
    refs[0] = 0;
    for (uint64_t k = lo; k < hi; ++k) r[k - lo] = static_cast<double>(k);
  }
  auto at = [&](uint64_t k) { return static_cast<int64_t>(r[k - lo]); };
  const int64_t zero = static_cast<int64_t>(refs[0]);
  std::vector<int64_t>& dst = arity == 3 ? out->triangles : arity == 2 ? out->lines : out->points;
  dst.reserve(n * static_cast<uint64_t>(arity));
  for (uint64_t e = first; e < first + n; ++e) {
    switch (p.mode) {
      case kTriangles: dst.insert(dst.end(), {at(3 * e), at(3 * e + 1), at(3 * e + 2)}); break;
      case kStrip:
        if (e % 2 == 0) dst.insert(dst.end(), {at(e), at(e + 1), at(e + 2)});
        else dst.insert(dst.end(), {at(e), at(e + 2), at(e + 1)});
        break;
      case kFan: dst.insert(dst.end(), {at(e + 1), at(e + 2), zero}); break;
      case kLines: dst.insert(dst.end(), {at(2 * e), at(2 * e + 1)}); break;
      case kLineStrip: dst.insert(dst.end(), {at(e), at(e + 1)}); break;
      case kLineLoop: dst.insert(dst.end(), {at(e), e + 1 < p.refs ? at(e + 1) : zero}); break;
      default: dst.push_back(at(e)); break;
    }
  }
  std::vector<uint32_t>& objects = arity == 3 ? out->triangle_objects : arity == 2 ? out->line_objects : out->point_objects;
  objects.assign(n, object);
  if (!materials_.empty()) {
    std::vector<uint32_t>& materials = arity == 3 ? out->triangle_materials : arity == 2 ? out->line_materials : out->point_materials;
    materials.assign(n, p.material >= 0 ? static_cast<uint32_t>(p.material) : default_material_);
  }
  if (arity == 3) out->polygons = n;
}

void GltfReader::resolve(ParsedChunk* chunk) {
  if (chunk->error.set) fail(Status::bad_data, file_.path() + ": " + chunk->error.message);
  if (chunk->reader_state == 1) primitive_base_ = vertices_;
  vertices_ += chunk->positions.size() / 3;
  const auto base = static_cast<int64_t>(primitive_base_);
  for (auto* refs : {&chunk->triangles, &chunk->lines, &chunk->points})
    for (int64_t& r : *refs) r += base;
}

}  // namespace

std::unique_ptr<Reader> make_gltf_reader(const MappedFile& file, bool glb) {
  return std::make_unique<GltfReader>(file, glb);
}

}  // namespace lodstream::io
