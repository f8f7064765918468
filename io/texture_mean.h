// The mean colour of a base colour texture (PNG or JPEG bytes), for materials that carry a texture the
// levels cannot (they have no texture coordinates): the texture is reduced to one colour that multiplies
// the material's base colour factor (glTF 2.0 §3.9.2: baseColor = factor * texture; MTL: Kd * map_Kd).
// Texels are sRGB-encoded (glTF §3.9.2 and every MTL viewer): each channel is decoded to linear light
// (IEC 61966-2-1), averaged over the texels, and kept linear, as the factor is; alpha is linear already.
// Decoding: libpng's simplified API (any PNG to 8-bit RGBA) and libjpeg(-turbo) (JPEG to RGB).
#pragma once

#include <cstdint>
#include <span>
#include <string>

namespace lodstream::io {

// Fills rgba with the texture's mean colour. False when the bytes are not a PNG or JPEG that decodes
// (why in *error); decoding is bounded to images of at most 2^28 texels.
bool texture_mean_color(std::span<const uint8_t> bytes, float rgba[4], std::string* error);

// The same for a file; false when it cannot be read (over 256 MiB included).
bool texture_file_mean_color(const std::string& path, float rgba[4], std::string* error);

}  // namespace lodstream::io
