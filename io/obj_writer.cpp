// Wavefront OBJ writer for one level of detail (see io/obj_writer.h for the statements written).
// Follows the OBJ format (Wavefront Advanced Visualizer manual, Appendix B1); numbers are written with
// std::to_chars in the shortest form that reads back as the same float.
#include "io/obj_writer.h"

#include <charconv>
#include <cstdint>
#include <cstdio>
#include <filesystem>

#include "core/status.h"
#include "io/file_writer.h"

namespace lodstream::io {

namespace {

// One output line at a time, built in a fixed buffer (the longest line, `f` with normals, is well under
// 128 bytes: 6 indices of at most 10 digits).
class Line {
 public:
  void text(std::string_view s) {
    for (char c : s) *end_++ = c;
  }
  void number(float x) { end_ = std::to_chars(end_, buf_ + sizeof buf_, x).ptr; }
  void number(uint64_t x) { end_ = std::to_chars(end_, buf_ + sizeof buf_, x).ptr; }
  void finish(FileWriter& out) {
    *end_++ = '\n';
    out.write(buf_, static_cast<size_t>(end_ - buf_));
    end_ = buf_;
  }

 private:
  char buf_[160];
  char* end_ = buf_;
};

// A material's name in the MTL file: unique (its id first) and one token (blanks and controls become '_').
std::string mtl_name(size_t i, const core::Material& m) {
  std::string name = "m" + std::to_string(i);
  if (!m.name.empty()) name += '_';
  for (char c : m.name) name += static_cast<unsigned char>(c) <= 0x20 || c == 0x7f || c == '#' ? '_' : c;
  return name;
}

std::string mtl_text(const std::vector<core::Material>& materials) {
  std::string text = "# materials of the level of detail next to this file (Kd base colour, d opacity, Pm/Pr PBR)\n";
  for (size_t i = 0; i < materials.size(); ++i) {
    const core::Material& m = materials[i];
    char line[200];
    std::snprintf(line, sizeof line, "Kd %.9g %.9g %.9g\nd %.9g\nPm %.9g\nPr %.9g\n", m.base_color[0], m.base_color[1],
                  m.base_color[2], m.base_color[3], m.metallic, m.roughness);
    text += "newmtl " + mtl_name(i, m) + "\n" + line;
  }
  return text;
}

}  // namespace

std::string mtl_path(const std::string& obj_path) {
  const std::filesystem::path p(obj_path);
  return (p.parent_path() / p.stem()).string() + ".mtl";
}

struct ObjStream::State {
  FileWriter out;
  Line line;
  std::vector<core::Material> materials;
  uint32_t current = UINT32_MAX;  // the material of the last `usemtl`
};

ObjStream::ObjStream(const std::string& path, const std::vector<std::string>& comments,
                     const std::vector<core::Material>& materials)
    : state_(std::make_unique<State>()) {
  // The library first, so that an OBJ under its final name always has its MTL.
  if (!materials.empty()) write_file_atomic(mtl_path(path), mtl_text(materials), Sync::durable);
  state_->materials = materials;
  state_->out.open(path, 1 << 20, Sync::durable);
  for (const std::string& c : comments) {
    std::string line = "# ";
    for (char ch : c) line += static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f ? ' ' : ch;
    line += '\n';
    state_->out.write(line);
  }
  if (!materials.empty()) state_->out.write("mtllib " + std::filesystem::path(mtl_path(path)).filename().string() + "\n");
}

void ObjStream::vertex(const float* xyz, const uint8_t* rgba) {
  Line& line = state_->line;
  // The common `v x y z r g b` extension (colours 0..1); alpha has no place in it.
  line.text("v");
  for (int c = 0; c < 3; ++c) line.text(" "), line.number(xyz[c]);
  for (int c = 0; c < 3; ++c) line.text(" "), line.number(static_cast<float>(rgba[c]) / 255.0f);
  line.finish(state_->out);
}

void ObjStream::use(uint32_t material) {
  if (material == state_->current) return;
  if (material >= state_->materials.size()) fail(Status::internal, "OBJ: material " + std::to_string(material) + " out of range");
  state_->out.write("usemtl " + mtl_name(material, state_->materials[material]) + "\n");
  state_->current = material;
}

ObjStream::~ObjStream() = default;

void ObjStream::vec3(const char* tag, const float* xyz) {
  Line& line = state_->line;
  line.text(tag);
  for (int c = 0; c < 3; ++c) {
    line.text(" ");
    line.number(xyz[c]);
  }
  line.finish(state_->out);
}

void ObjStream::face(const uint64_t* ids, bool normals) {
  Line& line = state_->line;
  line.text("f");
  for (int c = 0; c < 3; ++c) {
    line.text(" ");
    line.number(ids[c] + 1);
    if (normals) {
      line.text("//");
      line.number(ids[c] + 1);
    }
  }
  line.finish(state_->out);
}

void ObjStream::line(uint64_t a, uint64_t b) {
  Line& line = state_->line;
  line.text("l ");
  line.number(a + 1);
  line.text(" ");
  line.number(b + 1);
  line.finish(state_->out);
}

void ObjStream::point(uint64_t p) {
  Line& line = state_->line;
  line.text("p ");
  line.number(p + 1);
  line.finish(state_->out);
}

void ObjStream::commit() { state_->out.commit(); }

void write_obj(const std::string& path, const core::LodMesh& mesh, const std::vector<std::string>& comments) {
  if (const std::string v = core::convention_violation(mesh); !v.empty())
    fail(Status::internal, path + ": cannot write level: " + v);
  const bool normals = !mesh.normals.empty(), materials = !mesh.materials.empty(), colors = !mesh.colors.empty();
  ObjStream out(path, comments, mesh.materials);
  for (uint64_t v = 0; v < mesh.vertex_count(); ++v) {
    if (colors) out.vertex(&mesh.positions[3 * v], &mesh.colors[4 * v]);
    else out.vec3("v", &mesh.positions[3 * v]);
  }
  if (normals)
    for (uint64_t v = 0; v < mesh.vertex_count(); ++v) out.vec3("vn", &mesh.normals[3 * v]);
  for (uint64_t t = 0; t < mesh.triangle_count(); ++t) {
    if (materials) out.use(mesh.triangle_materials[t]);
    const uint64_t ids[3] = {mesh.triangles[3 * t], mesh.triangles[3 * t + 1], mesh.triangles[3 * t + 2]};
    out.face(ids, normals);
  }
  for (uint64_t e = 0; e < mesh.edge_count(); ++e) {
    if (materials) out.use(mesh.edge_materials[e]);
    out.line(mesh.edges[2 * e], mesh.edges[2 * e + 1]);
  }
  for (uint64_t i = 0; i < mesh.point_count(); ++i) {
    if (materials) out.use(mesh.point_materials[i]);
    out.point(mesh.points[i]);
  }
  out.commit();
}

}  // namespace lodstream::io
