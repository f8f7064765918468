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

// The statements write_obj writes, one at a time, for a level written element by element elsewhere
// (stream/level_files.cpp): all `v` first, then all `vn`, then `f`, `l`, `p`; ids are 0-based here.
class ObjStream {
 public:
  ObjStream(const std::string& path, const std::vector<std::string>& comments);
  ~ObjStream();  // discards the file unless committed
  void vec3(const char* tag, const float* xyz);  // "v" or "vn"
  void face(const uint64_t* ids, bool normals);
  void line(uint64_t a, uint64_t b);
  void point(uint64_t p);
  void commit();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace lodstream::io
