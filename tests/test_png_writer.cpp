// PNG encoding (io/png_writer.h) decoded back with libpng and compared pixel for pixel, its chunk list (only
// IHDR, IDAT, IEND: nothing that varies between runs), determinism, bad arguments; base64 (io/base64.h)
// against the RFC 4648 §10 test vectors and all byte values.
#include <gtest/gtest.h>
#include <png.h>

#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "core/status.h"
#include "io/base64.h"
#include "io/png_writer.h"

namespace lodstream {
namespace {

struct Decoded {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<uint8_t> pixels;
};

// Decodes with libpng's simplified API in the file's own format (no conversion).
Decoded decode(const std::vector<uint8_t>& png) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  Decoded d;
  if (!png_image_begin_read_from_memory(&image, png.data(), png.size())) {
    ADD_FAILURE() << "libpng: " << image.message;
    return d;
  }
  d.width = static_cast<int>(image.width);
  d.height = static_cast<int>(image.height);
  d.channels = static_cast<int>(PNG_IMAGE_PIXEL_CHANNELS(image.format));
  d.pixels.resize(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, d.pixels.data(), 0, nullptr)) {
    ADD_FAILURE() << "libpng: " << image.message;
  }
  png_image_free(&image);
  return d;
}

// Chunk types in file order, after checking the signature and that the chunks exactly fill the file.
std::vector<std::string> chunk_types(const std::vector<uint8_t>& png) {
  static const uint8_t kSignature[8] = {137, 80, 78, 71, 13, 10, 26, 10};
  EXPECT_GE(png.size(), 8u);
  EXPECT_EQ(std::memcmp(png.data(), kSignature, 8), 0);
  std::vector<std::string> types;
  size_t at = 8;
  while (at + 12 <= png.size()) {
    const size_t length = size_t{png[at]} << 24 | size_t{png[at + 1]} << 16 | size_t{png[at + 2]} << 8 | png[at + 3];
    types.emplace_back(reinterpret_cast<const char*>(png.data() + at + 4), 4);
    at += 12 + length;
  }
  EXPECT_EQ(at, png.size());
  return types;
}

std::vector<uint8_t> random_pixels(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<uint8_t> p(n);
  for (uint8_t& b : p) b = static_cast<uint8_t>(rng());
  return p;
}

TEST(PngWriter, RoundTripsEveryFormat) {
  for (const int channels : {1, 3, 4}) {
    for (const auto& [w, h] : {std::pair{1, 1}, std::pair{7, 3}, std::pair{3, 7}, std::pair{64, 33}}) {
      const std::vector<uint8_t> pixels = random_pixels(static_cast<size_t>(w) * h * channels, w * 100 + h);
      const std::vector<uint8_t> png = io::encode_png(pixels, w, h, channels);
      const Decoded d = decode(png);
      EXPECT_EQ(d.width, w);
      EXPECT_EQ(d.height, h);
      EXPECT_EQ(d.channels, channels);
      EXPECT_EQ(d.pixels, pixels) << channels << " channels, " << w << "x" << h;
    }
  }
}

// A 3 × 2 RGB image drawn out: red green blue / white black grey, rows top to bottom.
TEST(PngWriter, KnownImage) {
  const std::vector<uint8_t> pixels = {
      255, 0, 0, 0, 255, 0, 0, 0, 255,  //
      255, 255, 255, 0, 0, 0, 128, 128, 128,
  };
  const std::vector<uint8_t> png = io::encode_png(pixels, 3, 2, 3);
  const Decoded d = decode(png);
  ASSERT_EQ(d.pixels.size(), pixels.size());
  EXPECT_EQ(d.pixels, pixels);
  // IHDR: width 3, height 2, bit depth 8, colour type 2 (RGB), compression 0, filter 0, no interlace.
  const uint8_t ihdr[] = {0, 0, 0, 13, 'I', 'H', 'D', 'R', 0, 0, 0, 3, 0, 0, 0, 2, 8, 2, 0, 0, 0};
  ASSERT_GE(png.size(), 8 + sizeof ihdr);
  EXPECT_EQ(std::memcmp(png.data() + 8, ihdr, sizeof ihdr), 0);
}

TEST(PngWriter, OnlyCriticalChunksAndSameBytesEveryTime) {
  const std::vector<uint8_t> pixels = random_pixels(50 * 40 * 4, 5);
  const std::vector<uint8_t> a = io::encode_png(pixels, 50, 40, 4);
  const std::vector<uint8_t> b = io::encode_png(pixels, 50, 40, 4);
  EXPECT_EQ(a, b);
  const std::vector<std::string> types = chunk_types(a);
  ASSERT_GE(types.size(), 3u);
  EXPECT_EQ(types.front(), "IHDR");
  EXPECT_EQ(types.back(), "IEND");
  for (size_t i = 1; i + 1 < types.size(); ++i) EXPECT_EQ(types[i], "IDAT");
}

TEST(PngWriter, BadArguments) {
  const std::vector<uint8_t> pixels(12, 0);
  EXPECT_THROW(io::encode_png(pixels, 2, 2, 2), Failure);  // 2 channels (gray + alpha) not offered
  EXPECT_THROW(io::encode_png(pixels, 2, 2, 4), Failure);  // 16 bytes needed
  EXPECT_THROW(io::encode_png(pixels, 0, 4, 3), Failure);
  EXPECT_THROW(io::encode_png({}, 0, 0, 1), Failure);
  EXPECT_NO_THROW(io::encode_png(pixels, 2, 2, 3));
  try {
    io::encode_png(pixels, 2, 2, 5);
    FAIL() << "no Failure";
  } catch (const Failure& e) {
    EXPECT_EQ(e.status(), Status::internal);
  }
}

std::string b64(const std::string& s) {
  return io::base64_encode(std::span(reinterpret_cast<const uint8_t*>(s.data()), s.size()));
}

TEST(Base64, Rfc4648Vectors) {
  EXPECT_EQ(b64(""), "");
  EXPECT_EQ(b64("f"), "Zg==");
  EXPECT_EQ(b64("fo"), "Zm8=");
  EXPECT_EQ(b64("foo"), "Zm9v");
  EXPECT_EQ(b64("foob"), "Zm9vYg==");
  EXPECT_EQ(b64("fooba"), "Zm9vYmE=");
  EXPECT_EQ(b64("foobar"), "Zm9vYmFy");
}

// Every 6-bit group value, and the high bytes that would go wrong through a signed char.
TEST(Base64, FullAlphabetAndHighBytes) {
  const std::vector<uint8_t> bytes = {0x00, 0x10, 0x83, 0x10, 0x51, 0x87, 0x20, 0x92, 0x8b, 0x30, 0xd3, 0x8f,
                                      0x41, 0x14, 0x93, 0x51, 0x55, 0x97, 0x61, 0x96, 0x9b, 0x71, 0xd7, 0x9f,
                                      0x82, 0x18, 0xa3, 0x92, 0x59, 0xa7, 0xa2, 0x9a, 0xab, 0xb2, 0xdb, 0xaf,
                                      0xc3, 0x1c, 0xb3, 0xd3, 0x5d, 0xb7, 0xe3, 0x9e, 0xbb, 0xf3, 0xdf, 0xbf};
  EXPECT_EQ(io::base64_encode(bytes), "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/");
  EXPECT_EQ(io::base64_encode(std::vector<uint8_t>{0xff}), "/w==");
  EXPECT_EQ(io::base64_encode(std::vector<uint8_t>{0xff, 0xfe}), "//4=");
  EXPECT_EQ(io::base64_encode(std::vector<uint8_t>{0xfb, 0xff, 0xbf}), "+/+/");
}

}  // namespace
}  // namespace lodstream
