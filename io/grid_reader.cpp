// Height-grid readers: Terrain-RGB PNG, PGM (P5, P2), ESRI ASCII grid.
//
// Formats: Mapbox, "Terrain-RGB" (docs.mapbox.com, raster tiles: height = -10000 + (R·65536 + G·256 + B)
// · 0.1 m); Netpbm pgm(5) (P5/P2, maxval < 65536, two-byte samples most significant byte first); ESRI
// ASCII raster format (ArcGIS "Esri ASCII raster format": six header lines, rows north to south).
//
// The whole file is mapped once: a grid is read into memory anyway. PNG decoding uses libpng's classic API
// so that the IHDR can be checked before any pixel is decoded; libpng reports errors by longjmp to the
// setjmp in decode_png, whose locals are therefore trivially destructible, and every C++ object it fills
// lives in the caller (a longjmp must not skip a destructor). Allocation follows the bytes the file holds:
// PNG rows are appended as libpng produces them, PGM and ASC check the file size before reserving.
#include "io/grid_reader.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstring>
#include <new>
#include <string_view>

#include "core/status.h"
#include "io/mapped_file.h"
#include "io/png_common.h"
#include "io/reader.h"
#include "io/text.h"

namespace lodstream::io {
namespace {

const char kUnsupported[] = "unsupported grid format (expected Terrain-RGB PNG, PGM or ESRI ASCII .asc)";

double sample_spacing(const GridReadOptions& options, double from_file) {
  return options.spacing > 0 ? options.spacing : from_file;
}

// ---- Terrain-RGB PNG

// deflate cannot expand data by more than 1032:1 (RFC 1951: a 258-byte match costs at least 2 bits), so
// a PNG of S bytes decodes to at most ~1032·S bytes; an interlaced image is only buffered below that.
constexpr uint64_t kMaxDeflateRatio = 1032;

struct PngDecode {
  const uint8_t* data = nullptr;
  size_t size = 0;
  size_t pos = 0;  // bytes handed to libpng so far: the offset reported with its errors
  PngErrorText error;
  enum class Outcome { ok, png_error, not_rgb8, bad_size, too_large, out_of_memory } outcome = Outcome::ok;
  png_uint_32 width = 0, height = 0;
  int bit_depth = 0, color_type = 0, interlace = 0;
  std::vector<uint8_t>* pixels = nullptr;  // row buffer, or the whole image when interlaced
  std::vector<float>* z = nullptr;
  std::vector<uint8_t>* valid = nullptr;  // RGBA only: one flag per sample (alpha != 0)
};

void png_on_read(png_structp png, png_bytep out, size_t length) {
  PngDecode* d = static_cast<PngDecode*>(png_get_io_ptr(png));
  if (length > d->size - d->pos) {
    d->pos = d->size;
    png_error(png, "unexpected end of file");
  }
  std::memcpy(out, d->data + d->pos, length);
  d->pos += length;
}

// Appends one decoded row of `channels` bytes per pixel as heights. False when out of memory.
bool append_terrain_row(const uint8_t* row, png_uint_32 width, int channels, PngDecode* d) {
  try {
    for (png_uint_32 i = 0; i < width; ++i) {
      const uint8_t* px = row + size_t(i) * channels;
      const uint32_t code = uint32_t(px[0]) << 16 | uint32_t(px[1]) << 8 | px[2];
      const bool present = channels == 3 || px[3] != 0;
      d->z->push_back(present ? float(-10000.0 + code / 10.0) : 0.0f);
      if (channels == 4) d->valid->push_back(present ? 1 : 0);
    }
  } catch (const std::bad_alloc&) {
    return false;
  }
  return true;
}

bool resize_buffer(std::vector<uint8_t>* buffer, size_t bytes) {
  try {
    buffer->resize(bytes);
  } catch (const std::bad_alloc&) {
    return false;
  }
  return true;
}

// Decodes into d->z / d->valid. Returns with d->outcome set; never throws, never leaks libpng's state.
void decode_png(PngDecode* d) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &d->error, png_on_error, png_on_warning);
  if (png == nullptr) {
    d->outcome = PngDecode::Outcome::out_of_memory;
    return;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    d->outcome = PngDecode::Outcome::out_of_memory;
    return;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    d->outcome = PngDecode::Outcome::png_error;
    return;
  }
  png_set_read_fn(png, d, png_on_read);
  png_read_info(png, info);
  png_get_IHDR(png, info, &d->width, &d->height, &d->bit_depth, &d->color_type, &d->interlace, nullptr,
               nullptr);
  if (d->bit_depth != 8 ||
      (d->color_type != PNG_COLOR_TYPE_RGB && d->color_type != PNG_COLOR_TYPE_RGB_ALPHA)) {
    png_destroy_read_struct(&png, &info, nullptr);
    d->outcome = PngDecode::Outcome::not_rgb8;
    return;
  }
  if (d->width == 0 || d->height == 0 || d->width > kMaxGridSide || d->height > kMaxGridSide) {
    png_destroy_read_struct(&png, &info, nullptr);
    d->outcome = PngDecode::Outcome::bad_size;
    return;
  }
  const int channels = d->color_type == PNG_COLOR_TYPE_RGB ? 3 : 4;
  const size_t row_bytes = size_t(d->width) * channels;
  bool ok = true;
  if (d->interlace == PNG_INTERLACE_NONE) {
    ok = resize_buffer(d->pixels, row_bytes);
    for (png_uint_32 y = 0; ok && y < d->height; ++y) {
      png_read_row(png, d->pixels->data(), nullptr);
      ok = append_terrain_row(d->pixels->data(), d->width, channels, d);
    }
  } else {
    const uint64_t image_bytes = uint64_t(row_bytes + 1) * d->height;
    if (image_bytes > kMaxDeflateRatio * d->size) {
      png_destroy_read_struct(&png, &info, nullptr);
      d->outcome = PngDecode::Outcome::too_large;
      return;
    }
    ok = resize_buffer(d->pixels, size_t(image_bytes));
    if (ok) {
      const int passes = png_set_interlace_handling(png);
      png_read_update_info(png, info);
      for (int pass = 0; pass < passes; ++pass) {
        for (png_uint_32 y = 0; y < d->height; ++y)
          png_read_row(png, d->pixels->data() + y * row_bytes, nullptr);
      }
      for (png_uint_32 y = 0; ok && y < d->height; ++y) {
        ok = append_terrain_row(d->pixels->data() + y * row_bytes, d->width, channels, d);
      }
    }
  }
  if (ok) png_read_end(png, nullptr);  // checks the chunks after the image data, up to IEND
  png_destroy_read_struct(&png, &info, nullptr);
  d->outcome = ok ? PngDecode::Outcome::ok : PngDecode::Outcome::out_of_memory;
}

HeightGrid read_terrain_png(const MappedFile& file, const Window& bytes, const GridReadOptions& options) {
  HeightGrid grid;
  std::vector<uint8_t> pixels;
  PngDecode d;
  d.data = reinterpret_cast<const uint8_t*>(bytes.data());
  d.size = size_t(bytes.size());
  d.pixels = &pixels;
  d.z = &grid.z;
  d.valid = &grid.valid;
  decode_png(&d);
  switch (d.outcome) {
    case PngDecode::Outcome::ok:
      break;
    case PngDecode::Outcome::png_error:
      fail_at_offset(file, d.pos, std::string("PNG: ") + d.error.message);
    case PngDecode::Outcome::not_rgb8: {
      const char* type = d.color_type == PNG_COLOR_TYPE_GRAY         ? "gray"
                         : d.color_type == PNG_COLOR_TYPE_GRAY_ALPHA ? "gray+alpha"
                         : d.color_type == PNG_COLOR_TYPE_PALETTE    ? "palette"
                         : d.color_type == PNG_COLOR_TYPE_RGB        ? "RGB"
                                                                     : "RGBA";
      // Offset 24: the IHDR's bit depth, followed by the colour type.
      fail_at_offset(
          file, 24,
          "not an 8-bit RGB(A) Terrain-RGB PNG (" + std::to_string(d.bit_depth) + "-bit " + type + ")");
    }
    case PngDecode::Outcome::bad_size:
      fail_at_offset(file, 16,
                     "image size " + std::to_string(d.width) + "x" + std::to_string(d.height) +
                         " outside 1.." + std::to_string(kMaxGridSide));
    case PngDecode::Outcome::too_large:
      fail_at_offset(file, 16,
                     "interlaced image of " + std::to_string(d.width) + "x" + std::to_string(d.height) +
                         " cannot be held by a file of " + std::to_string(d.size) + " bytes");
    case PngDecode::Outcome::out_of_memory:
      fail(Status::internal, file.path() + ": out of memory decoding the PNG");
  }
  grid.width = d.width;
  grid.height = d.height;
  grid.spacing = sample_spacing(options, 1);
  grid.format = "terrain-rgb-png";
  if (std::find(grid.valid.begin(), grid.valid.end(), uint8_t{0}) == grid.valid.end())
    std::vector<uint8_t>().swap(grid.valid);
  return grid;
}

// ---- Text scanning shared by PGM headers, P2 and ASC

inline bool is_space(char c) { return c == '\n' || text::is_blank(c); }

// A cursor over [p, end) that counts lines as it passes '\n'.
struct TextCursor {
  const char* p;
  const char* end;
  uint64_t line = 1;

  // Skips white space, and '#' comments to the end of their line when `comments`.
  void skip_space(bool comments) {
    while (p < end) {
      if (*p == '\n') {
        ++line;
        ++p;
      } else if (is_space(*p)) {
        ++p;
      } else if (comments && *p == '#') {
        p = text::line_end(p, end);
      } else {
        break;
      }
    }
  }
  // The next run of non-space bytes (after skip_space); empty at end.
  std::string_view token() {
    const char* b = p;
    while (p < end && !is_space(*p)) ++p;
    return {b, size_t(p - b)};
  }
};

std::string quoted(std::string_view token) {
  constexpr size_t kMax = 40;
  std::string s(token.substr(0, kMax));
  for (char& c : s) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return "'" + s + (token.size() > kMax ? "...'" : "'");
}

// A decimal integer token of digits only, in [lo, hi].
bool parse_count(std::string_view token, uint64_t lo, uint64_t hi, uint64_t* out) {
  if (token.empty() || token.size() > 12) return false;
  uint64_t v = 0;
  for (char c : token) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + uint64_t(c - '0');
  }
  if (v < lo || v > hi) return false;
  *out = v;
  return true;
}

// A whole token as a double (decimal or scientific, optional sign); overflow gives infinity.
bool parse_number(std::string_view token, double* out) {
  if (token.empty()) return false;
  const char* p = token.data();
  return text::parse_double(p, token.data() + token.size(), out) && p == token.data() + token.size();
}

std::string size_text(uint64_t width, uint64_t height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

// ---- PGM

HeightGrid read_pgm(const MappedFile& file, const Window& bytes, const GridReadOptions& options) {
  const char* begin = bytes.data();
  TextCursor c{begin, begin + bytes.size()};
  const bool binary = c.token() == "P5";
  uint64_t values[3] = {};
  const char* names[3] = {"width", "height", "maxval"};
  const uint64_t limits[3] = {kMaxGridSide, kMaxGridSide, 65535};
  for (int k = 0; k < 3; ++k) {
    c.skip_space(true);
    const uint64_t line = c.line;
    const std::string_view token = c.token();
    if (token.empty()) fail_at_line(file, line, std::string("truncated header: no ") + names[k]);
    if (!parse_count(token, 1, limits[k], &values[k])) {
      fail_at_line(file, line,
                   std::string("bad ") + names[k] + " " + quoted(token) + " (expected an integer in 1.." +
                       std::to_string(limits[k]) + ")");
    }
  }
  const uint64_t width = values[0], height = values[1], maxval = values[2];
  const uint64_t count = width * height;
  if (!std::isfinite(double(maxval) * options.z_scale) ||
      !std::isfinite(float(double(maxval) * options.z_scale))) {
    fail(Status::usage, file.path() + ": --z-scale " + std::to_string(options.z_scale) + " makes maxval " +
                            std::to_string(maxval) + " overflow a 32-bit float");
  }

  HeightGrid grid;
  grid.width = uint32_t(width);
  grid.height = uint32_t(height);
  grid.spacing = sample_spacing(options, 1);
  grid.format = maxval <= 255 ? "pgm8" : "pgm16";

  if (binary) {
    // Exactly one white-space byte separates maxval from the samples.
    if (c.p == c.end) fail_at_line(file, c.line, "truncated header: no sample data after maxval");
    const uint64_t start = uint64_t(c.p + 1 - begin);
    const uint64_t sample_bytes = maxval <= 255 ? 1 : 2;
    const uint64_t need = count * sample_bytes;
    const uint64_t have = bytes.size() - start;
    if (have < need) {
      fail_at_offset(file, bytes.size(),
                     "truncated: the header says " + size_text(width, height) + " samples of " +
                         std::to_string(sample_bytes) + " byte(s), " + std::to_string(need) + " bytes, but " +
                         std::to_string(have) + " follow it");
    }
    if (have > need) {
      fail_at_offset(file, start + need,
                     std::to_string(have - need) + " bytes after the last of the " +
                         size_text(width, height) + " samples the header announces");
    }
    grid.z.resize(count);
    const auto* s = reinterpret_cast<const uint8_t*>(begin + start);
    for (uint64_t i = 0; i < count; ++i) {
      const uint32_t v = sample_bytes == 1 ? s[i] : uint32_t(s[2 * i]) << 8 | s[2 * i + 1];
      if (v > maxval) {
        fail_at_offset(file, start + i * sample_bytes,
                       "sample " + std::to_string(v) + " exceeds maxval " + std::to_string(maxval));
      }
      grid.z[i] = float(v * options.z_scale);
    }
    return grid;
  }

  // P2: at least one digit and one separator per sample but the last, so the reservation is safe.
  grid.z.reserve(size_t(std::min<uint64_t>(count, (uint64_t(c.end - c.p) + 1) / 2)));
  for (;;) {
    c.skip_space(true);
    if (c.p == c.end) break;
    const uint64_t line = c.line;
    const std::string_view token = c.token();
    if (grid.z.size() == count) {
      fail_at_line(file, line, "more samples than the " + size_text(width, height) + " the header announces");
    }
    uint64_t v = 0;
    if (!parse_count(token, 0, UINT64_MAX / 16, &v))
      fail_at_line(file, line, "not a sample value: " + quoted(token));
    if (v > maxval)
      fail_at_line(file, line, "sample " + std::string(token) + " exceeds maxval " + std::to_string(maxval));
    grid.z.push_back(float(double(v) * options.z_scale));
  }
  if (grid.z.size() < count) {
    fail_at_line(file, c.line,
                 "truncated: " + std::to_string(grid.z.size()) + " of the " + std::to_string(count) +
                     " samples (" + size_text(width, height) + ") the header announces");
  }
  return grid;
}

// ---- ESRI ASCII grid

bool is_number_start(char ch) {
  return (ch >= '0' && ch <= '9') || ch == '-' || ch == '+' || ch == '.';
}

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& ch : out) {
    if (ch >= 'A' && ch <= 'Z') ch = char(ch - 'A' + 'a');
  }
  return out;
}

HeightGrid read_esri_ascii(const MappedFile& file, const Window& bytes, const GridReadOptions& options) {
  const char* keys[] = {"ncols",     "nrows",    "xllcorner", "xllcenter", "yllcorner",
                        "yllcenter", "cellsize", "dx",        "dy",        "nodata_value"};
  constexpr int kKeys = sizeof keys / sizeof keys[0];
  double value[kKeys] = {};
  uint64_t seen_line[kKeys] = {};  // 0 = absent
  auto index = [&](std::string_view key) {
    for (int k = 0; k < kKeys; ++k) {
      if (key == keys[k]) return k;
    }
    return -1;
  };

  TextCursor c{bytes.data(), bytes.data() + bytes.size()};
  for (;;) {
    c.skip_space(false);
    if (c.p == c.end || is_number_start(*c.p)) break;
    const uint64_t line = c.line;
    const std::string_view key_token = c.token();
    const int k = index(lower(key_token));
    if (k < 0) fail_at_line(file, line, "unknown header key " + quoted(key_token));
    if (seen_line[k]) {
      fail_at_line(file, line,
                   "header key " + std::string(keys[k]) + " repeated (first on line " +
                       std::to_string(seen_line[k]) + ")");
    }
    c.p = text::skip_blanks(c.p, c.end);
    const std::string_view token = c.token();
    if (!parse_number(token, &value[k]) || !std::isfinite(value[k])) {
      fail_at_line(file, line, "bad value " + quoted(token) + " for " + std::string(keys[k]));
    }
    seen_line[k] = line;
    c.p = text::skip_blanks(c.p, c.end);
    if (c.p < c.end && *c.p != '\n')
      fail_at_line(file, line, "unexpected text after the value of " + std::string(keys[k]));
  }
  const uint64_t data_line = c.line;
  enum { kCols, kRows, kXCorner, kXCenter, kYCorner, kYCenter, kCell, kDx, kDy, kNodata };
  auto require = [&](int k) {
    if (!seen_line[k]) fail_at_line(file, data_line, std::string("missing header key ") + keys[k]);
  };
  auto dimension = [&](int k) {
    require(k);
    const double v = value[k];
    if (!(v >= 1 && v <= kMaxGridSide && v == std::floor(v))) {
      fail_at_line(file, seen_line[k],
                   std::string(keys[k]) + " must be an integer in 1.." + std::to_string(kMaxGridSide));
    }
    return uint64_t(v);
  };
  const uint64_t width = dimension(kCols), height = dimension(kRows);
  auto one_of = [&](int a, int b) {
    if (seen_line[a] && seen_line[b]) {
      fail_at_line(file, seen_line[b], std::string("both ") + keys[a] + " and " + keys[b] + " given");
    }
    if (!seen_line[a] && !seen_line[b]) {
      fail_at_line(file, data_line, std::string("missing header key ") + keys[a] + " or " + keys[b]);
    }
  };
  one_of(kXCorner, kXCenter);
  one_of(kYCorner, kYCenter);
  double cell = 0;
  if (seen_line[kCell]) {
    if (seen_line[kDx] || seen_line[kDy])
      fail_at_line(file, seen_line[kCell], "both cellsize and dx/dy given");
    cell = value[kCell];
  } else if (seen_line[kDx] || seen_line[kDy]) {
    require(kDx);
    require(kDy);
    if (value[kDx] != value[kDy]) {
      fail(Status::usage, file.path() + ":" + std::to_string(seen_line[kDy]) +
                              ": non-square cells (dx != dy) are not supported");
    }
    cell = value[kDx];
  } else {
    require(kCell);
  }
  const int cell_key = seen_line[kCell] ? kCell : kDx;
  if (!(cell > 0)) fail_at_line(file, seen_line[cell_key], std::string(keys[cell_key]) + " must be positive");

  HeightGrid grid;
  grid.width = uint32_t(width);
  grid.height = uint32_t(height);
  grid.spacing = sample_spacing(options, cell);
  grid.origin_x = seen_line[kXCenter] ? value[kXCenter] : value[kXCorner] + cell / 2;
  grid.origin_y = seen_line[kYCenter] ? value[kYCenter] : value[kYCorner] + cell / 2;
  grid.format = "esri-ascii";

  const uint64_t count = width * height;
  const bool has_nodata = seen_line[kNodata] != 0;
  const double nodata = value[kNodata];
  // At least one digit and one separator per value but the last, so the reservation is safe.
  const size_t reserve = size_t(std::min<uint64_t>(count, (uint64_t(c.end - c.p) + 1) / 2));
  grid.z.reserve(reserve);
  if (has_nodata) grid.valid.reserve(reserve);
  uint64_t missing = 0;
  for (;;) {
    c.skip_space(false);
    if (c.p == c.end) break;
    const uint64_t line = c.line;
    const std::string_view token = c.token();
    if (grid.z.size() == count) {
      fail_at_line(file, line, "more values than the " + size_text(width, height) + " the header announces");
    }
    double v = 0;
    if (!parse_number(token, &v)) fail_at_line(file, line, "not a number: " + quoted(token));
    if (has_nodata && v == nodata) {
      grid.z.push_back(0);
      grid.valid.push_back(0);
      ++missing;
      continue;
    }
    if (!std::isfinite(v) || !std::isfinite(float(v))) {
      fail_at_line(file, line, "height " + quoted(token) + " is not a finite 32-bit float");
    }
    grid.z.push_back(float(v));
    if (has_nodata) grid.valid.push_back(1);
  }
  if (grid.z.size() < count) {
    fail_at_line(file, c.line,
                 "truncated: " + std::to_string(grid.z.size()) + " of the " + std::to_string(count) +
                     " values (" + size_text(width, height) + ") the header announces");
  }
  if (missing == 0) std::vector<uint8_t>().swap(grid.valid);
  return grid;
}

bool looks_like_esri_ascii(std::string_view head) {
  size_t i = 0;
  while (i < head.size() && is_space(head[i])) ++i;
  size_t j = i;
  while (j < head.size() && !is_space(head[j])) ++j;
  const std::string key = lower(head.substr(i, j - i));
  return key == "ncols" || key == "nrows" || key == "xllcorner" || key == "xllcenter" || key == "yllcorner" ||
         key == "yllcenter" || key == "cellsize" || key == "nodata_value";
}

}  // namespace

HeightGrid read_height_grid(const std::string& path, const GridReadOptions& options) {
  if (!std::isfinite(options.z_scale)) fail(Status::usage, path + ": --z-scale must be a finite number");
  if (!std::isfinite(options.spacing) || options.spacing < 0) {
    fail(Status::usage, path + ": --spacing must be a positive number");
  }
  const MappedFile file(path);
  if (file.size() == 0) fail_at_offset(file, 0, "empty file");
  const Window bytes = file.map(0, file.size());
  const std::string_view head = bytes.view().substr(0, 64);

  static const char kPngSignature[] = "\x89PNG\r\n\x1a\n";
  if (head.substr(0, 8) == std::string_view(kPngSignature, 8)) return read_terrain_png(file, bytes, options);
  if (head.size() >= 3 && head[0] == 'P' && (head[1] == '5' || head[1] == '2') &&
      (is_space(head[2]) || head[2] == '#')) {
    return read_pgm(file, bytes, options);
  }
  if (looks_like_esri_ascii(head)) return read_esri_ascii(file, bytes, options);
  fail(Status::usage, path + ": " + kUnsupported);
}

}  // namespace lodstream::io
