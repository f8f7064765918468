// Wavefront OBJ writer for one level of detail (see io/obj_writer.h for the statements written).
// Follows the OBJ format (Wavefront Advanced Visualizer manual, Appendix B1); numbers are written with
// std::to_chars in the shortest form that reads back as the same float.
#include "io/obj_writer.h"

#include <charconv>
#include <cstdint>

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

}  // namespace

void write_obj(const std::string& path, const core::LodMesh& mesh, const std::vector<std::string>& comments) {
  if (const std::string v = core::convention_violation(mesh); !v.empty())
    fail(Status::internal, path + ": cannot write level: " + v);
  const bool normals = !mesh.normals.empty();

  FileWriter out(path, 1 << 20, Sync::durable);
  for (const std::string& c : comments) {
    std::string line = "# ";
    for (char ch : c) line += static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f ? ' ' : ch;
    line += '\n';
    out.write(line);
  }

  Line line;
  auto xyz = [&](const char* tag, const std::vector<float>& a, uint64_t v) {
    line.text(tag);
    for (int c = 0; c < 3; ++c) {
      line.text(" ");
      line.number(a[3 * v + c]);
    }
    line.finish(out);
  };
  for (uint64_t v = 0; v < mesh.vertex_count(); ++v) xyz("v", mesh.positions, v);
  if (normals)
    for (uint64_t v = 0; v < mesh.vertex_count(); ++v) xyz("vn", mesh.normals, v);

  for (uint64_t t = 0; t < mesh.triangle_count(); ++t) {
    line.text("f");
    for (int c = 0; c < 3; ++c) {
      const uint64_t id = uint64_t{mesh.triangles[3 * t + c]} + 1;
      line.text(" ");
      line.number(id);
      if (normals) {
        line.text("//");
        line.number(id);
      }
    }
    line.finish(out);
  }
  for (uint64_t e = 0; e < mesh.edge_count(); ++e) {
    line.text("l ");
    line.number(uint64_t{mesh.edges[2 * e]} + 1);
    line.text(" ");
    line.number(uint64_t{mesh.edges[2 * e + 1]} + 1);
    line.finish(out);
  }
  for (uint32_t p : mesh.points) {
    line.text("p ");
    line.number(uint64_t{p} + 1);
    line.finish(out);
  }
  out.commit();
}

struct ObjStream::State {
  FileWriter out;
  Line line;
};

ObjStream::ObjStream(const std::string& path, const std::vector<std::string>& comments) : state_(std::make_unique<State>()) {
  state_->out.open(path, 1 << 20, Sync::durable);
  for (const std::string& c : comments) {
    std::string line = "# ";
    for (char ch : c) line += static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f ? ' ' : ch;
    line += '\n';
    state_->out.write(line);
  }
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

}  // namespace lodstream::io
