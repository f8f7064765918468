// Height grids for `lodstream grid` (adaptive subdivision of gridded samples, DeHaemer 1989): a regular
// lattice of heights read whole into memory from one of three formats, recognised by content:
//
//   terrain-rgb-png  Mapbox Terrain-RGB: an 8-bit RGB or RGBA PNG (libpng), height in metres =
//                    -10000 + (R·65536 + G·256 + B) / 10. A pixel with alpha 0 is NODATA. z_scale is
//                    not applied: the encoding is metres by definition.
//   pgm8, pgm16      Netpbm PGM, binary "P5" (maxval <= 255: one byte per sample; <= 65535: two bytes,
//                    big-endian) or plain "P2" (decimal); named by maxval. Height = value · z_scale.
//   esri-ascii       ESRI ASCII grid (.asc): header keys ncols, nrows, xllcorner|xllcenter,
//                    yllcorner|yllcenter, cellsize (or equal dx and dy), optional NODATA_value, in any
//                    order and any case; then nrows × ncols numbers, north row first, in any line layout.
//                    Cells equal to NODATA_value are NODATA. z_scale is not applied (heights in file units).
//
// Errors (lodstream::Failure, core/status.h), every message starting with the path:
//   Status::no_input  missing, unreadable or a directory ("PATH: cannot open: ...")
//   Status::bad_data  malformed content, with "PATH:LINE: ..." for text or "PATH: byte N: ..." for binary:
//                     empty or truncated files, non-numbers, wrong sample counts, width or height 0 or
//                     above 65536, samples above maxval, non-finite heights, a PNG that is not 8-bit RGB(A)
//   Status::usage     a format that is none of the three
// Nothing is allocated from a header's counts before the file is known to be large enough to hold them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace lodstream::io {

// Largest width and height accepted, in samples.
inline constexpr uint32_t kMaxGridSide = 65536;

struct HeightGrid {
  uint32_t width = 0, height = 0;     // samples per row, rows
  double spacing = 1;                 // distance between neighbouring samples (x and y)
  double origin_x = 0, origin_y = 0;  // position of sample (0, height-1) i.e. the lower-left sample
  std::vector<float> z;               // width*height heights, row-major, row 0 = top (north) row of the file
  std::vector<uint8_t> valid;         // empty = every sample valid; else 1 = sample present, 0 = NODATA
  std::string format;                 // "terrain-rgb-png", "pgm8", "pgm16", "esri-ascii"
  double x(uint32_t i) const { return origin_x + i * spacing; }
  double y(uint32_t j) const { return origin_y + double(height - 1 - j) * spacing; }
};

struct GridReadOptions {
  double z_scale = 1;  // PGM only: height = sample value · z_scale
  double spacing = 0;  // > 0 overrides the file's sample distance; 0 = from the file (ASC cellsize) or 1
};

// Reads a whole grid. NODATA samples have z = 0 and valid = 0; `valid` stays empty when there are none.
// The origin is the lower-left sample's centre: ASC xllcenter/yllcenter, or xllcorner/yllcorner plus half
// the file's cellsize; (0, 0) for PNG and PGM. Options must be finite, spacing >= 0 (else Status::usage).
HeightGrid read_height_grid(const std::string& path, const GridReadOptions& options);

}  // namespace lodstream::io
