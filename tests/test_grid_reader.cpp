// Height-grid reader (io/grid_reader.h): the Fuji Terrain-RGB tile against an independent decode with
// libpng's simplified API; tiny PNG, PGM (P2, P5; 8 and 16 bit) and ESRI ASCII grids with heights worked out
// by hand; the fixtures in tests/data/grids; every error path with its status and a message naming the file.
#include <gtest/gtest.h>
#include <png.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/status.h"
#include "io/grid_reader.h"
#include "io/png_writer.h"
#include "test_util.h"

namespace lodstream {
namespace {

using io::GridReadOptions;
using io::HeightGrid;
using io::read_height_grid;
using test::TempDir;

std::string fixture(const std::string& name) {
  return test::source_dir() + "/tests/data/grids/" + name;
}

// The Terrain-RGB height of an (R, G, B) pixel, as the format defines it.
float terrain(uint32_t r, uint32_t g, uint32_t b) {
  return float(-10000.0 + (r * 65536 + g * 256 + b) / 10.0);
}

// R, G, B of a Terrain-RGB code (height · 10 + 100000).
std::vector<uint8_t> rgb_of(uint32_t code) {
  return {uint8_t(code >> 16), uint8_t(code >> 8), uint8_t(code)};
}

// Calls read_height_grid and expects a Failure with `status` whose message names `path` and holds `part`.
void expect_failure(const std::string& path, Status status, const std::string& part,
                    const GridReadOptions& options = {}) {
  try {
    read_height_grid(path, options);
    ADD_FAILURE() << path << ": no failure, expected " << status_name(status) << " with '" << part << "'";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), status) << f.what();
    const std::string message = f.what();
    EXPECT_EQ(message.rfind(path, 0), 0u) << "message does not start with the path: " << message;
    EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
  }
}

// Writes a PNG with libpng's classic API in any bit depth, colour type and interlacing (encode_png only
// writes 8-bit non-interlaced images). `rows` holds height rows of packed samples, big-endian for 16 bits.
bool write_png_file(const std::string& path, uint32_t width, uint32_t height, int bit_depth, int color_type,
                    int interlace, const std::vector<uint8_t>& rows) {
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    return false;
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, width, height, bit_depth, color_type, interlace, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_color palette[2] = {{0, 0, 0}, {255, 255, 255}};
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_PLTE(png, info, palette, 2);
  png_write_info(png, info);
  const size_t stride = rows.size() / height;
  const int passes = png_set_interlace_handling(png);
  for (int pass = 0; pass < passes; ++pass) {
    for (uint32_t y = 0; y < height; ++y) png_write_row(png, rows.data() + y * stride);
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return std::fclose(f) == 0;
}

std::string write_bytes(const TempDir& dir, const std::string& name, const std::vector<uint8_t>& bytes) {
  return dir.write(name, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

TEST(GridReader, FujiTileMatchesAnIndependentDecode) {
  LODSTREAM_REQUIRE_SHARED_DATA(data);
  const std::string path = data + "/terrain/fuji-terrain-rgb.png";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "skipped: " << path << " is absent";

  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  ASSERT_TRUE(png_image_begin_read_from_file(&image, path.c_str())) << image.message;
  image.format = PNG_FORMAT_RGB;
  std::vector<uint8_t> rgb(PNG_IMAGE_SIZE(image));
  ASSERT_TRUE(png_image_finish_read(&image, nullptr, rgb.data(), 0, nullptr)) << image.message;

  const HeightGrid grid = read_height_grid(path, {});
  EXPECT_EQ(grid.format, "terrain-rgb-png");
  ASSERT_EQ(grid.width, 512u);
  ASSERT_EQ(grid.height, 512u);
  ASSERT_EQ(grid.z.size(), 512u * 512u);
  EXPECT_TRUE(grid.valid.empty());
  EXPECT_EQ(grid.spacing, 1);
  EXPECT_EQ(grid.origin_x, 0);
  EXPECT_EQ(grid.origin_y, 0);

  auto expected = [&](uint32_t i, uint32_t j) {
    const uint8_t* p = rgb.data() + (size_t(j) * 512 + i) * 3;
    return terrain(p[0], p[1], p[2]);
  };
  // A few pixels spelled out (corners, centre), then all of them.
  for (auto [i, j] : {std::pair{0u, 0u}, {511u, 0u}, {0u, 511u}, {511u, 511u}, {256u, 256u}, {100u, 400u}}) {
    EXPECT_EQ(grid.z[size_t(j) * 512 + i], expected(i, j)) << "pixel " << i << "," << j;
  }
  size_t mismatches = 0;
  float highest = -1e9f;
  for (uint32_t j = 0; j < 512; ++j) {
    for (uint32_t i = 0; i < 512; ++i) {
      mismatches += grid.z[size_t(j) * 512 + i] != expected(i, j);
      highest = std::max(highest, grid.z[size_t(j) * 512 + i]);
    }
  }
  EXPECT_EQ(mismatches, 0u);
  // Mount Fuji's summit is 3776 m; the tile holds it (at the tile's resolution, within a few tens of m).
  EXPECT_GT(highest, 3600.0f);
  EXPECT_LT(highest, 3800.0f);

  GridReadOptions spaced;
  spaced.spacing = 30;
  spaced.z_scale = 7;  // not applied to Terrain-RGB
  const HeightGrid g2 = read_height_grid(path, spaced);
  EXPECT_EQ(g2.spacing, 30);
  EXPECT_EQ(g2.z, grid.z);
  EXPECT_EQ(g2.x(2), 60);
  EXPECT_EQ(g2.y(511), 0);
  EXPECT_EQ(g2.y(0), 511 * 30);
}

TEST(GridReader, TinyTerrainRgbPng) {
  TempDir dir;
  // 3 × 2 pixels: codes for 0 m, 0.1 m, -10000 m (code 0) / 3776.5 m, 1.2 m, 123456.7 m.
  const uint32_t codes[6] = {100000, 100001, 0, 137765, 100012, 1334567};
  std::vector<uint8_t> rgb;
  for (uint32_t code : codes) {
    const auto p = rgb_of(code);
    rgb.insert(rgb.end(), p.begin(), p.end());
  }
  const std::string path = write_bytes(dir, "tiny.png", io::encode_png(rgb, 3, 2, 3));
  const HeightGrid g = read_height_grid(path, {});
  EXPECT_EQ(g.format, "terrain-rgb-png");
  ASSERT_EQ(g.width, 3u);
  ASSERT_EQ(g.height, 2u);
  const std::vector<float> want = {
      0.0f,    float(-10000.0 + 100001 / 10.0), -10000.0f,
      3776.5f, float(-10000.0 + 100012 / 10.0), float(-10000.0 + 1334567 / 10.0)};
  EXPECT_EQ(g.z, want);
  EXPECT_TRUE(g.valid.empty());
  EXPECT_EQ(g.x(0), 0);
  EXPECT_EQ(g.y(0), 1);
  EXPECT_EQ(g.y(1), 0);

  // RGBA: alpha is ignored except 0, which marks NODATA (z 0).
  std::vector<uint8_t> rgba;
  for (int k = 0; k < 6; ++k) {
    rgba.insert(rgba.end(), rgb.begin() + 3 * k, rgb.begin() + 3 * k + 3);
    rgba.push_back(k == 4 ? 0 : k == 1 ? 7 : 255);
  }
  const HeightGrid ga =
      read_height_grid(write_bytes(dir, "tiny-rgba.png", io::encode_png(rgba, 3, 2, 4)), {});
  std::vector<float> want_a = want;
  want_a[4] = 0;
  EXPECT_EQ(ga.z, want_a);
  EXPECT_EQ(ga.valid, (std::vector<uint8_t>{1, 1, 1, 1, 0, 1}));

  // Fully opaque RGBA: no NODATA, so `valid` stays empty.
  for (size_t k = 3; k < rgba.size(); k += 4) rgba[k] = 255;
  const HeightGrid go = read_height_grid(write_bytes(dir, "opaque.png", io::encode_png(rgba, 3, 2, 4)), {});
  EXPECT_EQ(go.z, want);
  EXPECT_TRUE(go.valid.empty());
}

TEST(GridReader, InterlacedTerrainRgbPng) {
  TempDir dir;
  const uint32_t w = 11, h = 9;  // not a multiple of the Adam7 block, so every pass is partial
  std::vector<uint8_t> rgb;
  std::vector<float> want;
  for (uint32_t k = 0; k < w * h; ++k) {
    const uint32_t code = 100000 + k * 977;
    const auto p = rgb_of(code);
    rgb.insert(rgb.end(), p.begin(), p.end());
    want.push_back(float(-10000.0 + code / 10.0));
  }
  const std::string path = dir.file("adam7.png");
  ASSERT_TRUE(write_png_file(path, w, h, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_ADAM7, rgb));
  const HeightGrid g = read_height_grid(path, {});
  EXPECT_EQ(g.width, w);
  EXPECT_EQ(g.height, h);
  EXPECT_EQ(g.z, want);
}

TEST(GridReader, PngErrors) {
  TempDir dir;
  const std::string not_rgb = "not an 8-bit RGB(A) Terrain-RGB PNG";
  expect_failure(write_bytes(dir, "gray.png", io::encode_png(std::vector<uint8_t>(4, 9), 2, 2, 1)),
                 Status::bad_data, not_rgb);
  const std::string rgb16 = dir.file("rgb16.png");
  ASSERT_TRUE(
      write_png_file(rgb16, 2, 1, 16, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, std::vector<uint8_t>(12, 1)));
  expect_failure(rgb16, Status::bad_data, not_rgb + " (16-bit RGB)");
  const std::string palette = dir.file("palette.png");
  ASSERT_TRUE(write_png_file(palette, 2, 1, 8, PNG_COLOR_TYPE_PALETTE, PNG_INTERLACE_NONE, {0, 1}));
  expect_failure(palette, Status::bad_data, not_rgb + " (8-bit palette)");
  const std::string gray16 = dir.file("gray16.png");
  ASSERT_TRUE(write_png_file(gray16, 2, 1, 16, PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE, {0, 1, 2, 3}));
  expect_failure(gray16, Status::bad_data, not_rgb);

  // Wider than 65536 samples.
  const std::string wide = dir.file("wide.png");
  ASSERT_TRUE(write_png_file(wide, 65537, 1, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                             std::vector<uint8_t>(65537 * 3, 0x86)));
  expect_failure(wide, Status::bad_data, "byte 16: image size 65537x1 outside 1..65536");

  // Truncated in the image data, and after it (no IEND): byte offsets of where decoding stopped.
  std::vector<uint8_t> rgb(64 * 64 * 3);
  for (size_t k = 0; k < rgb.size(); ++k) rgb[k] = uint8_t(k * 31 + k / 7);
  const std::vector<uint8_t> good = io::encode_png(rgb, 64, 64, 3);
  ASSERT_NO_THROW(read_height_grid(write_bytes(dir, "good.png", good), {}));
  const std::vector<uint8_t> half(good.begin(), good.begin() + good.size() / 2);
  expect_failure(write_bytes(dir, "half.png", half), Status::bad_data, ": byte ");
  expect_failure(write_bytes(dir, "half.png", half), Status::bad_data, "unexpected end of file");
  const std::vector<uint8_t> no_iend(good.begin(), good.end() - 12);
  expect_failure(write_bytes(dir, "no-iend.png", no_iend), Status::bad_data, "unexpected end of file");
  // Only the signature and part of the IHDR.
  expect_failure(write_bytes(dir, "sig.png", std::vector<uint8_t>(good.begin(), good.begin() + 20)),
                 Status::bad_data, "byte ");
  // A flipped bit in the image data: the chunk's CRC no longer matches.
  std::vector<uint8_t> flipped = good;
  flipped[good.size() / 2] ^= 0x10;
  expect_failure(write_bytes(dir, "crc.png", flipped), Status::bad_data, "PNG: ");

  // A header announcing 65536 × 65536 RGBA pixels followed by almost nothing: an error, not a 16 GiB buffer.
  std::vector<uint8_t> lie = io::encode_png(std::vector<uint8_t>(4, 1), 1, 1, 4);
  // IHDR data starts at byte 16: width, height (big-endian); then recompute the IHDR's CRC by re-encoding
  // is impossible, so the liar gets the correct CRC from libpng's own crc32 (zlib).
  lie[16] = 0, lie[17] = 1, lie[18] = 0, lie[19] = 0;
  lie[20] = 0, lie[21] = 1, lie[22] = 0, lie[23] = 0;
  const uLong crc = crc32(crc32(0, nullptr, 0), lie.data() + 12, 17);
  lie[29] = uint8_t(crc >> 24), lie[30] = uint8_t(crc >> 16), lie[31] = uint8_t(crc >> 8),
  lie[32] = uint8_t(crc);
  expect_failure(write_bytes(dir, "lie.png", lie), Status::bad_data, "PNG: ");
}

TEST(GridReader, Pgm) {
  TempDir dir;
  // P5, 8-bit, a comment in the header: 3 × 2.
  const std::string p5 = dir.write(
      "a.pgm", std::string("P5\n# made by hand\n3 2\n255\n") + std::string("\x00\x01\xff\x10\x20\x30", 6));
  GridReadOptions scaled;
  scaled.z_scale = 0.5;
  HeightGrid g = read_height_grid(p5, scaled);
  EXPECT_EQ(g.format, "pgm8");
  EXPECT_EQ(g.width, 3u);
  EXPECT_EQ(g.height, 2u);
  EXPECT_EQ(g.z, (std::vector<float>{0, 0.5f, 127.5f, 8, 16, 24}));
  EXPECT_TRUE(g.valid.empty());
  EXPECT_EQ(g.spacing, 1);

  // P5, 16-bit big-endian, maxval 1000, spacing from the options.
  const std::string p5w =
      dir.write("b.pgm", std::string("P5 2 2 1000\n") + std::string("\x03\xe8\x00\x01\x01\x00\x00\x00", 8));
  GridReadOptions spaced;
  spaced.spacing = 2.5;
  g = read_height_grid(p5w, spaced);
  EXPECT_EQ(g.format, "pgm16");
  EXPECT_EQ(g.z, (std::vector<float>{1000, 1, 256, 0}));
  EXPECT_EQ(g.spacing, 2.5);
  EXPECT_EQ(g.y(0), 2.5);

  // P2, 8-bit and 16-bit, values spread over lines, comments anywhere.
  g = read_height_grid(dir.write("c.pgm", "P2\n2 3 # w h\n9\n0 1\n2\n3 # row 2\n4 9\n"), scaled);
  EXPECT_EQ(g.format, "pgm8");
  EXPECT_EQ(g.z, (std::vector<float>{0, 0.5f, 1, 1.5f, 2, 4.5f}));
  g = read_height_grid(dir.write("d.pgm", "P2 2 1 65535 65535 300"), {});
  EXPECT_EQ(g.format, "pgm16");
  EXPECT_EQ(g.z, (std::vector<float>{65535, 300}));
}

TEST(GridReader, PgmErrors) {
  TempDir dir;
  auto w = [&](const std::string& name, const std::string& bytes) { return dir.write(name, bytes); };
  expect_failure(w("e1.pgm", "P5\n0 2\n255\n"), Status::bad_data,
                 ":2: bad width '0' (expected an integer in 1..65536)");
  expect_failure(w("e2.pgm", "P5\n65537 2\n255\n"), Status::bad_data, ":2: bad width '65537'");
  expect_failure(w("e3.pgm", "P2\n2 x\n255\n"), Status::bad_data, ":2: bad height 'x'");
  expect_failure(w("e4.pgm", "P5\n2 2\n70000\n"), Status::bad_data, ":3: bad maxval '70000'");
  expect_failure(w("e5.pgm", "P5\n2 2\n0\n"), Status::bad_data, ":3: bad maxval '0'");
  expect_failure(w("e6.pgm", "P5\n2 2\n"), Status::bad_data, ":3: truncated header: no maxval");
  expect_failure(w("e7.pgm", "P5 2 2 255"), Status::bad_data, ":1: truncated header: no sample data");
  // P5 data: too short, too long, above maxval (8 and 16 bit), at their byte offsets.
  expect_failure(w("e8.pgm", "P5 2 2 255\n\x01\x02\x03"), Status::bad_data,
                 ": byte 14: truncated: the header says 2x2 samples of 1 byte(s), 4 bytes, but 3 follow it");
  expect_failure(w("e9.pgm", "P5 2 2 255\n\x01\x02\x03\x04\x05"), Status::bad_data,
                 ": byte 15: 1 bytes after the last of the 2x2 samples");
  expect_failure(w("e10.pgm", "P5 2 2 100\n\x01\x02\x65\x04"), Status::bad_data,
                 ": byte 13: sample 101 exceeds maxval 100");
  expect_failure(w("e11.pgm", std::string("P5 2 1 1000\n\x00\x05\x03\xe9", 16)), Status::bad_data,
                 ": byte 14: sample 1001 exceeds maxval 1000");
  // A header that lies about its size costs nothing: 65536 × 65536 samples announced, 4 present.
  expect_failure(
      w("e12.pgm", "P5 65536 65536 65535\n\x01\x02\x03\x04"), Status::bad_data,
      "truncated: the header says 65536x65536 samples of 2 byte(s), 8589934592 bytes, but 4 follow it");
  // P2 data, at their lines.
  expect_failure(w("e13.pgm", "P2\n2 2\n255\n1 2\n3 x\n"), Status::bad_data, ":5: not a sample value: 'x'");
  expect_failure(w("e14.pgm", "P2\n2 2\n255\n1 2\n3 -4\n"), Status::bad_data, ":5: not a sample value: '-4'");
  expect_failure(w("e15.pgm", "P2\n2 2\n255\n1 2\n3 256\n"), Status::bad_data,
                 ":5: sample 256 exceeds maxval 255");
  expect_failure(w("e16.pgm", "P2\n2 2\n255\n1 2\n3\n\n"), Status::bad_data,
                 ":7: truncated: 3 of the 4 samples (2x2) the header announces");
  expect_failure(w("e17.pgm", "P2\n2 2\n255\n1 2\n3 4\n5\n"), Status::bad_data,
                 ":6: more samples than the 2x2 the header announces");
  expect_failure(w("e18.pgm", "P2 65536 65536 255 1 2 3"), Status::bad_data,
                 "truncated: 3 of the 4294967296 samples");
  // --z-scale that overflows a float.
  GridReadOptions huge;
  huge.z_scale = 1e36;
  expect_failure(w("e19.pgm", "P2 1 1 65535 1"), Status::usage, "overflow a 32-bit float", huge);
}

TEST(GridReader, EsriAscii) {
  TempDir dir;
  // Corner origin: the lower-left sample's centre is half a cell in from the corner. NODATA cells.
  const std::string corner =
      dir.write("corner.asc",
                "ncols 3\r\nnrows 2\r\nxllcorner 100\r\nyllcorner 200\r\ncellsize 10\r\n"
                "NODATA_value -9999\r\n1 2.5 -9999\r\n-9999.0 5 6e1\r\n");
  HeightGrid g = read_height_grid(corner, {});
  EXPECT_EQ(g.format, "esri-ascii");
  EXPECT_EQ(g.width, 3u);
  EXPECT_EQ(g.height, 2u);
  EXPECT_EQ(g.spacing, 10);
  EXPECT_EQ(g.origin_x, 105);
  EXPECT_EQ(g.origin_y, 205);
  EXPECT_EQ(g.x(2), 125);
  EXPECT_EQ(g.y(0), 215);
  EXPECT_EQ(g.z, (std::vector<float>{1, 2.5f, 0, 0, 5, 60}));
  EXPECT_EQ(g.valid, (std::vector<uint8_t>{1, 1, 0, 0, 1, 1}));

  // Center origin, keys in any case and order, values wrapped over lines, no NODATA present: valid empty.
  const std::string center = dir.write("center.asc",
                                       "NCOLS 2\nCellSize 0.5\nNROWS 2\nXLLCENTER -1\nyllCenter 3\n"
                                       "nodata_value -1\n7\n8 9\n10\n");
  g = read_height_grid(center, {});
  EXPECT_EQ(g.origin_x, -1);
  EXPECT_EQ(g.origin_y, 3);
  EXPECT_EQ(g.spacing, 0.5);
  EXPECT_EQ(g.z, (std::vector<float>{7, 8, 9, 10}));
  EXPECT_TRUE(g.valid.empty());

  // dx / dy (as GDAL writes them), equal; --spacing overrides the cell size, not the origin; z_scale unused.
  GridReadOptions options;
  options.spacing = 3;
  options.z_scale = 100;
  g = read_height_grid(
      dir.write("dxdy.asc", "ncols 1\nnrows 2\nxllcorner 0\nyllcorner 0\ndx 2\ndy 2\n4\n5\n"), options);
  EXPECT_EQ(g.spacing, 3);
  EXPECT_EQ(g.origin_x, 1);
  EXPECT_EQ(g.origin_y, 1);
  EXPECT_EQ(g.y(0), 4);
  EXPECT_EQ(g.z, (std::vector<float>{4, 5}));
}

TEST(GridReader, EsriAsciiErrors) {
  TempDir dir;
  const std::string head = "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n";
  auto w = [&](const std::string& name, const std::string& bytes) { return dir.write(name, bytes); };
  expect_failure(w("a1.asc", "ncols 2\nnrows 2\nxllcorner 0\ncellsize 1\n1 2 3 4\n"), Status::bad_data,
                 ":5: missing header key yllcorner or yllcenter");
  expect_failure(w("a2.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\n1 2 3 4\n"), Status::bad_data,
                 ":5: missing header key cellsize");
  expect_failure(w("a3.asc", "ncols 2\nnrows 2\nbands 1\n"), Status::bad_data,
                 ":3: unknown header key 'bands'");
  expect_failure(w("a4.asc", "ncols 2\nNCOLS 3\n"), Status::bad_data,
                 ":2: header key ncols repeated (first on line 1)");
  expect_failure(w("a5.asc", "ncols 0\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n"), Status::bad_data,
                 ":1: ncols must be an integer in 1..65536");
  expect_failure(w("a6.asc", "ncols 2.5\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n"), Status::bad_data,
                 ":1: ncols must be an integer");
  expect_failure(w("a7.asc", "ncols 2\nnrows 70000\nxllcorner 0\nyllcorner 0\ncellsize 1\n"),
                 Status::bad_data, ":2: nrows must be an integer in 1..65536");
  expect_failure(w("a8.asc", "ncols two\n"), Status::bad_data, ":1: bad value 'two' for ncols");
  expect_failure(w("a9.asc", "ncols 2 3\n"), Status::bad_data,
                 ":1: unexpected text after the value of ncols");
  expect_failure(w("a10.asc", "ncols 2\nnrows 2\nxllcorner 0\nxllcenter 0\nyllcorner 0\ncellsize 1\n"),
                 Status::bad_data, ":4: both xllcorner and xllcenter given");
  expect_failure(w("a11.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize -1\n1 2 3 4\n"),
                 Status::bad_data, ":5: cellsize must be positive");
  expect_failure(w("a12.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ndx 1\ndy 2\n1 2 3 4\n"),
                 Status::usage, ":6: non-square cells (dx != dy) are not supported");
  expect_failure(w("a13.asc", head + "1 2\n3 x4\n"), Status::bad_data, ":7: not a number: 'x4'");
  expect_failure(w("a14.asc", head + "1 2\n3\n"), Status::bad_data, ":8: truncated: 3 of the 4 values (2x2)");
  expect_failure(w("a15.asc", head + "1 2\n3 4\n5\n"), Status::bad_data, ":8: more values than the 2x2");
  expect_failure(w("a16.asc", head + "1 2\n3 nan\n"), Status::bad_data,
                 ":7: height 'nan' is not a finite 32-bit float");
  expect_failure(w("a17.asc", head + "1 2\n1e39 4\n"), Status::bad_data, ":7: height '1e39' is not a finite");
  expect_failure(w("a18.asc", head), Status::bad_data, ":6: truncated: 0 of the 4 values");
  // 65536 × 65536 announced, two values present: an error, not a 16 GiB reservation.
  expect_failure(w("a19.asc", "ncols 65536\nnrows 65536\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n"),
                 Status::bad_data, "truncated: 2 of the 4294967296 values");
}

TEST(GridReader, InputAndFormatErrors) {
  TempDir dir;
  expect_failure(dir.file("missing.asc"), Status::no_input, ": cannot open: No such file or directory");
  std::filesystem::create_directories(dir.file("a-directory"));
  expect_failure(dir.file("a-directory"), Status::no_input, ": cannot open: is a directory");
  if (geteuid() != 0) {
    const std::string locked = dir.write("locked.asc", "ncols 1\n");
    chmod(locked.c_str(), 0);
    expect_failure(locked, Status::no_input, ": cannot open: Permission denied");
  }
  expect_failure(dir.write("empty.pgm", ""), Status::bad_data, ": byte 0: empty file");
  const std::string unsupported =
      ": unsupported grid format (expected Terrain-RGB PNG, PGM or ESRI ASCII .asc)";
  expect_failure(dir.write("hello.txt", "hello world\n"), Status::usage, unsupported);
  expect_failure(dir.write("rgb.ppm", "P6\n1 1\n255\n\x01\x02\x03"), Status::usage, unsupported);
  expect_failure(dir.write("jpeg.jpg", "\xff\xd8\xff\xe0"), Status::usage, unsupported);
  expect_failure(dir.write("png-start", "\x89PNG"), Status::usage, unsupported);

  const std::string ok = dir.write("ok.pgm", "P2 1 1 9 1");
  GridReadOptions bad;
  bad.spacing = -1;
  expect_failure(ok, Status::usage, ": --spacing must be a positive number", bad);
  bad.spacing = NAN;
  expect_failure(ok, Status::usage, ": --spacing must be a positive number", bad);
  bad = {};
  bad.z_scale = INFINITY;
  expect_failure(ok, Status::usage, ": --z-scale must be a finite number", bad);
}

TEST(GridReader, Fixtures) {
  // tests/data/grids: small files for the CLI tests and for trying `lodstream grid` by hand.
  HeightGrid g = read_height_grid(fixture("hill.asc"), {});
  EXPECT_EQ(g.format, "esri-ascii");
  EXPECT_EQ(g.width, 5u);
  EXPECT_EQ(g.height, 4u);
  EXPECT_EQ(g.origin_x, 1005);
  EXPECT_EQ(g.origin_y, 2005);
  EXPECT_EQ(g.spacing, 10);
  ASSERT_EQ(g.valid.size(), 20u);
  EXPECT_EQ(std::count(g.valid.begin(), g.valid.end(), 0), 2);
  EXPECT_EQ(g.valid[0], 0);  // north-west corner
  EXPECT_EQ(g.z[2 * 5 + 2], 12);

  g = read_height_grid(fixture("hill-center.asc"), {});
  EXPECT_EQ(g.origin_x, 1005);
  EXPECT_EQ(g.origin_y, 2005);
  EXPECT_TRUE(g.valid.empty());

  GridReadOptions scaled;
  scaled.z_scale = 0.25;
  g = read_height_grid(fixture("hill-p2.pgm"), scaled);
  EXPECT_EQ(g.format, "pgm8");
  EXPECT_EQ(g.width, 5u);
  EXPECT_EQ(g.height, 4u);
  EXPECT_EQ(g.z[2 * 5 + 2], 12 * 0.25f);

  const HeightGrid p5 = read_height_grid(fixture("hill-p5-16.pgm"), scaled);
  EXPECT_EQ(p5.format, "pgm16");
  EXPECT_EQ(p5.z, g.z);

  g = read_height_grid(fixture("hill-terrain-rgb.png"), {});
  EXPECT_EQ(g.format, "terrain-rgb-png");
  EXPECT_EQ(g.width, 5u);
  EXPECT_EQ(g.height, 4u);
  EXPECT_EQ(g.z[2 * 5 + 2], 1012.5f);
  EXPECT_TRUE(g.valid.empty());
}

}  // namespace
}  // namespace lodstream
