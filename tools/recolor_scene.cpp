// Benchmark inputs for issue 16.6 from a scene that make-scene.sh wrote (binary little-endian PLY, float
// x y z, faces as `list uchar int`, all triangles):
//   recolor_scene ply IN.ply OUT.ply   the same scene with uchar red green blue per vertex, one colour per
//                                      object;
//   recolor_scene glb IN.ply OUT.glb   the same scene as one glTF mesh (float VEC3 POSITION, uint32
//                                      TRIANGLES indices), with COLOR_0 (normalized ubyte VEC3) when
//                                      --colors is given before IN.ply.
// Objects: the PLY has no object ids, but compose.cpp writes instance after instance, each one's vertices
// after the previous one's, so a face whose smallest vertex is above every earlier face's largest starts
// a new object. The furniture models are made of many parts written one after the other, so this finds
// parts rather than instances (150,872 on make-scene.sh 2 1's 173 instances): more colours than one per
// instance, which costs simplify nothing more (its colour work is per vertex and per cell, not per colour). A vertex takes the
// object of the first face that uses it; the colour is a hash of the object number. Everything else is
// copied byte for byte, so simplify's work differs only by the colours.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

[[noreturn]] void die(const std::string& m) {
  std::fprintf(stderr, "recolor_scene: %s\n", m.c_str());
  std::exit(1);
}

struct Input {
  const uint8_t* data = nullptr;
  size_t size = 0, header = 0;
  uint64_t vertices = 0, faces = 0;
};

Input open_ply(const char* path) {
  Input in;
  const int fd = open(path, O_RDONLY);
  if (fd < 0) die(std::string("cannot open ") + path);
  struct stat st;
  fstat(fd, &st);
  in.size = static_cast<size_t>(st.st_size);
  in.data = static_cast<const uint8_t*>(mmap(nullptr, in.size, PROT_READ, MAP_PRIVATE, fd, 0));
  if (in.data == MAP_FAILED) die("mmap failed");
  close(fd);
  const std::string head(reinterpret_cast<const char*>(in.data), std::min<size_t>(in.size, 4096));
  const size_t end = head.find("end_header\n");
  if (end == std::string::npos) die("no PLY header");
  in.header = end + 11;
  const std::string expect_v = "property float x\nproperty float y\nproperty float z\nelement face ";
  if (head.find("format binary_little_endian 1.0") == std::string::npos || head.find(expect_v) == std::string::npos ||
      head.find("property list uchar int vertex_indices\nend_header") == std::string::npos)
    die("not a make-scene.sh PLY (binary LE, float x y z, list uchar int faces)");
  in.vertices = std::stoull(head.substr(head.find("element vertex ") + 15));
  in.faces = std::stoull(head.substr(head.find("element face ") + 13));
  if (in.size != in.header + 12 * in.vertices + 13 * in.faces) die("faces are not all triangles");
  return in;
}

const uint8_t* face(const Input& in, uint64_t f) { return in.data + in.header + 12 * in.vertices + 13 * f; }

// The object colour of every vertex (RGB), by the rule at the top.
std::vector<uint8_t> vertex_colors(const Input& in) {
  std::vector<uint32_t> object(in.vertices, UINT32_MAX);
  int64_t highest = -1;
  uint32_t current = 0;
  for (uint64_t f = 0; f < in.faces; ++f) {
    int32_t v[3];
    std::memcpy(v, face(in, f) + 1, 12);
    const int32_t lo = std::min(v[0], std::min(v[1], v[2])), hi = std::max(v[0], std::max(v[1], v[2]));
    if (lo < 0 || static_cast<uint64_t>(hi) >= in.vertices) die("face " + std::to_string(f) + ": vertex out of range");
    if (lo > highest && f > 0) ++current;
    highest = std::max<int64_t>(highest, hi);
    for (int32_t x : v)
      if (object[x] == UINT32_MAX) object[x] = current;
  }
  std::fprintf(stderr, "recolor_scene: %u objects\n", current + 1);
  std::vector<uint8_t> rgb(3 * in.vertices);
  for (uint64_t i = 0; i < in.vertices; ++i) {
    uint32_t h = object[i] == UINT32_MAX ? 0 : object[i] * 2654435761u;
    h ^= h >> 15;
    h *= 2246822519u;
    h ^= h >> 13;
    rgb[3 * i] = static_cast<uint8_t>(h), rgb[3 * i + 1] = static_cast<uint8_t>(h >> 8), rgb[3 * i + 2] = static_cast<uint8_t>(h >> 16);
  }
  return rgb;
}

void put(FILE* f, const void* p, size_t n) {
  if (n && std::fwrite(p, 1, n, f) != n) die("write failed");
}

void write_ply(const Input& in, const char* out) {
  const std::vector<uint8_t> rgb = vertex_colors(in);
  FILE* f = std::fopen(out, "wb");
  if (!f) die(std::string("cannot create ") + out);
  const std::string h = "ply\nformat binary_little_endian 1.0\ncomment recolor_scene: one colour per object\nelement vertex " +
                        std::to_string(in.vertices) +
                        "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
                        "property uchar blue\nelement face " +
                        std::to_string(in.faces) + "\nproperty list uchar int vertex_indices\nend_header\n";
  put(f, h.data(), h.size());
  std::vector<uint8_t> buf;
  for (uint64_t v = 0; v < in.vertices; ++v) {
    buf.insert(buf.end(), in.data + in.header + 12 * v, in.data + in.header + 12 * v + 12);
    buf.insert(buf.end(), &rgb[3 * v], &rgb[3 * v] + 3);
    if (buf.size() > (1 << 22)) put(f, buf.data(), buf.size()), buf.clear();
  }
  put(f, buf.data(), buf.size());
  put(f, face(in, 0), 13 * in.faces);
  if (std::fclose(f) != 0) die("write failed");
}

void write_glb(const Input& in, const char* out, bool colors) {
  const uint64_t vbytes = 12 * in.vertices, ibytes = 12 * in.faces, cbytes = colors ? (3 * in.vertices + 3) / 4 * 4 : 0;
  float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
  for (uint64_t v = 0; v < in.vertices; ++v) {
    float p[3];
    std::memcpy(p, in.data + in.header + 12 * v, 12);
    for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], p[k]), hi[k] = std::max(hi[k], p[k]);
  }
  char mm[256];
  std::snprintf(mm, sizeof mm, "\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]", lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
  std::string attrs = "\"POSITION\":0", accessors =
      "{\"bufferView\":0,\"componentType\":5126,\"count\":" + std::to_string(in.vertices) + ",\"type\":\"VEC3\"," + mm +
      "},{\"bufferView\":1,\"componentType\":5125,\"count\":" + std::to_string(3 * in.faces) + ",\"type\":\"SCALAR\"}";
  std::string views = "{\"buffer\":0,\"byteLength\":" + std::to_string(vbytes) + "},{\"buffer\":0,\"byteOffset\":" +
                      std::to_string(vbytes) + ",\"byteLength\":" + std::to_string(ibytes) + "}";
  if (colors) {
    attrs += ",\"COLOR_0\":2";
    accessors += ",{\"bufferView\":2,\"componentType\":5121,\"normalized\":true,\"count\":" + std::to_string(in.vertices) +
                 ",\"type\":\"VEC3\"}";
    views += ",{\"buffer\":0,\"byteOffset\":" + std::to_string(vbytes + ibytes) + ",\"byteLength\":" + std::to_string(3 * in.vertices) + "}";
  }
  std::string json = "{\"asset\":{\"version\":\"2.0\",\"generator\":\"recolor_scene\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],"
                     "\"nodes\":[{\"mesh\":0}],\"meshes\":[{\"primitives\":[{\"attributes\":{" + attrs + "},\"indices\":1}]}],"
                     "\"accessors\":[" + accessors + "],\"bufferViews\":[" + views + "],\"buffers\":[{\"byteLength\":" +
                     std::to_string(vbytes + ibytes + cbytes) + "}]}";
  json.append((4 - json.size() % 4) % 4, ' ');
  const uint64_t bin = vbytes + ibytes + cbytes, total = 12 + 8 + json.size() + 8 + bin;
  if (total >> 32) die("too large for one GLB");
  FILE* f = std::fopen(out, "wb");
  if (!f) die(std::string("cannot create ") + out);
  const uint32_t head[5] = {0x46546C67, 2, static_cast<uint32_t>(total), static_cast<uint32_t>(json.size()), 0x4E4F534A};
  put(f, head, sizeof head);
  put(f, json.data(), json.size());
  const uint32_t bh[2] = {static_cast<uint32_t>(bin), 0x004E4942};
  put(f, bh, sizeof bh);
  put(f, in.data + in.header, vbytes);
  std::vector<uint8_t> buf;
  for (uint64_t t = 0; t < in.faces; ++t) {
    buf.insert(buf.end(), face(in, t) + 1, face(in, t) + 13);
    if (buf.size() > (1 << 22)) put(f, buf.data(), buf.size()), buf.clear();
  }
  put(f, buf.data(), buf.size());
  if (colors) {
    std::vector<uint8_t> rgb = vertex_colors(in);
    rgb.resize(cbytes, 0);
    put(f, rgb.data(), rgb.size());
  }
  if (std::fclose(f) != 0) die("write failed");
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> a(argv + 1, argv + argc);
  bool colors = false;
  if (a.size() == 4 && a[1] == "--colors") colors = true, a.erase(a.begin() + 1);
  if (a.size() != 3 || (a[0] != "ply" && a[0] != "glb")) die("usage: recolor_scene ply|glb [--colors] IN.ply OUT");
  const Input in = open_ply(a[1].c_str());
  if (a[0] == "ply") write_ply(in, a[2].c_str());
  else write_glb(in, a[2].c_str(), colors);
  return 0;
}
