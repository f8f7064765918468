// One colour per primitive, for renders that draw a primitive in one colour (the error report's images):
// what a material's base colour and the vertex colours of core/mesh.h make of it.
#pragma once

#include <cstdint>

#include "core/mesh.h"

namespace lodstream::core {

// The colour a primitive of `arity` vertices is drawn in where one colour is wanted (the error report's
// renders): its material's base colour (none: white) times the mean of its vertices' RGBA colours (none:
// white), as RGB 0..255.
inline void primitive_rgb(const uint8_t* const* vertex_rgba, int arity, const Material* material, uint8_t* out) {
  for (int k = 0; k < 3; ++k) {
    double c = 255;
    if (vertex_rgba) {
      c = 0;
      for (int j = 0; j < arity; ++j) c += vertex_rgba[j][k];
      c /= arity;
    }
    if (material) c *= material->base_color[k] < 0 ? 0.0 : material->base_color[k] > 1 ? 1.0 : material->base_color[k];
    out[k] = static_cast<uint8_t>(c + 0.5);
  }
}

}  // namespace lodstream::core
