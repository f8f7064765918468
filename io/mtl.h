// Wavefront MTL material libraries, as an OBJ file's mtllib statements name them (Wavefront, "MTL material
// format", Lightwave-era specification), reduced to what core::Material carries:
//   newmtl name     starts a material (the rest of the line, trimmed)
//   Kd r g b        base colour (a single value means grey)
//   d a / Tr t      opacity a, or transparency t = 1 - a; below 1 the alpha mode is blend
//   Pm m / Pr r     metallic and roughness (the PBR extension of the format), else 0 and 1
//   map_Kd file     a texture (PNG or JPEG, relative to the library; options before the name skipped): the
//                   levels carry no texture coordinates, so its mean colour (io/texture_mean.h) multiplies
//                   Kd; its alpha is not used (d gives the opacity). One that cannot be read counts as white.
// Every other statement is ignored. A library that cannot be read (missing, unreadable, not a regular file,
// over 64 MiB) is skipped: the
// materials it would define keep core::Material's defaults (white, opaque), and the OBJ still reads.
// When two libraries define one name, the first one read wins.
#pragma once

#include <string>
#include <string_view>
#include <unordered_map>

#include "core/mesh.h"

namespace lodstream::io {

class MtlLibraries {
 public:
  // Reads the libraries named by one mtllib statement (`names`, blank-separated), relative to the
  // directory of `obj_path`. Each file is read once.
  void read(const std::string& obj_path, const std::string& names);
  // Fills `out`'s colour and factors from the material named out->name, if a library defines it.
  bool find(const std::string& name, core::Material* out) const;
  // Parses one library's text (exposed for tests); map_Kd files are read relative to `dir`, and not at
  // all when it is empty.
  void parse(std::string_view text, const std::string& dir = {});

 private:
  std::unordered_map<std::string, core::Material> materials_;
  std::unordered_map<std::string, bool> read_;
};

}  // namespace lodstream::io
