// Wavefront OBJ writer for one level of detail (core::LodMesh), following the OBJ format of Wavefront's
// Advanced Visualizer manual (Appendix B1, "Object Files (.obj)"): `v`, `vn`, `f`, `l`, `p`, 1-based indices.
//
//   v x y z            one per vertex; every number is the shortest decimal that reads back as the same
//                      float (std::to_chars), so coordinates round-trip exactly
//   vn x y z           one per vertex when the mesh has normals (indices stay aligned with `v`; vertices used
//                      only by edges or points carry (0, 0, 0), see core/mesh.h)
//   f a//a b//b c//c   per triangle (`f a b c` without normals)
//   l a b              per edge (OBJ has no place for the thickness; the PLY and GLB files keep it)
//   p a                per point
// With a material table (core/mesh.h): `mtllib <stem>.mtl` at the top, the library written next to the OBJ
// (before it: newmtl m<id>[_<name>], Kd, d, Pm, Pr per material), and `usemtl` before each primitive whose
// material differs from the previous one's. With vertex colours: `v x y z r g b` (0..1; alpha is dropped).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace lodstream::io {

// Writes `mesh` to `path` (through `<path>.partial`, renamed when complete). Each comment becomes a
// `# ...` line at the top; line breaks and other control characters in it are replaced by spaces.
// Throws Failure(io_error) when the file cannot be written, Failure(internal) when the mesh breaks the
// conventions of core/mesh.h (array sizes, indices out of range).
void write_obj(const std::string& path, const core::LodMesh& mesh, const std::vector<std::string>& comments);
// The MTL file that goes with the OBJ file `obj_path`: the same path with the extension .mtl.
std::string mtl_path(const std::string& obj_path);

// The statements write_obj writes, one at a time, for a level written element by element elsewhere
// (stream/level_files.cpp): all `v` first, then all `vn`, then `f`, `l`, `p`; ids are 0-based here.
// With `materials`, the MTL file is written first and `mtllib` follows the
// comments; use(m) before each primitive writes `usemtl` when m differs from the previous one.
class ObjStream {
 public:
  ObjStream(const std::string& path, const std::vector<std::string>& comments,
            const std::vector<core::Material>& materials = {});
  ~ObjStream();  // discards the file unless committed
  void vec3(const char* tag, const float* xyz);  // "v" or "vn"
  void vertex(const float* xyz, const uint8_t* rgba);  // "v x y z r g b" (0..1)
  void use(uint32_t material);
  void face(const uint64_t* ids, bool normals);
  void line(uint64_t a, uint64_t b);
  void point(uint64_t p);
  void commit();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace lodstream::io
