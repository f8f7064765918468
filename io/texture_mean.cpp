// Mean colour of a PNG or JPEG texture (see texture_mean.h). Sources: libpng 1.6 simplified API
// (png_image_begin_read_from_memory / png_image_finish_read), libjpeg 6b API with jpeg_mem_src
// (libjpeg-turbo), sRGB transfer function of IEC 61966-2-1.
#include "io/texture_mean.h"

#include <csetjmp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include <jpeglib.h>
#include <png.h>

namespace lodstream::io {
namespace {

constexpr uint64_t kMaxTexels = uint64_t{1} << 28;
constexpr uint64_t kMaxFileBytes = uint64_t{256} << 20;

double srgb_to_linear(int c) {
  const double v = c / 255.0;
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

// Sums channels of `n` texels of `channels` bytes (3: RGB, 4: RGBA) into rgba (means on return).
void mean(const uint8_t* px, uint64_t n, int channels, float rgba[4]) {
  double lut[256];
  for (int i = 0; i < 256; ++i) lut[i] = srgb_to_linear(i);
  double s[4] = {0, 0, 0, 0};
  for (uint64_t i = 0; i < n; ++i, px += channels) {
    for (int k = 0; k < 3; ++k) s[k] += lut[px[k]];
    s[3] += channels == 4 ? px[3] / 255.0 : 1.0;
  }
  for (int k = 0; k < 4; ++k) rgba[k] = n ? static_cast<float>(s[k] / static_cast<double>(n)) : 1.0f;
}

bool png_mean(std::span<const uint8_t> bytes, float rgba[4], std::string* error) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, bytes.data(), bytes.size())) {
    *error = std::string("PNG: ") + image.message;
    return false;
  }
  if (uint64_t{image.width} * image.height > kMaxTexels) {
    png_image_free(&image);
    *error = "PNG: image too large";
    return false;
  }
  image.format = PNG_FORMAT_RGBA;
  std::vector<uint8_t> px(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, px.data(), 0, nullptr)) {
    *error = std::string("PNG: ") + image.message;
    png_image_free(&image);
    return false;
  }
  mean(px.data(), uint64_t{image.width} * image.height, 4, rgba);
  return true;
}

struct JpegError {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

void jpeg_exit(j_common_ptr info) {
  auto* e = reinterpret_cast<JpegError*>(info->err);
  info->err->format_message(info, e->message);
  std::longjmp(e->jump, 1);
}

// No C++ object with a destructor lives across setjmp/longjmp here: the row buffer is plain malloc'd
// memory owned by libjpeg's pool.
bool jpeg_mean(std::span<const uint8_t> bytes, float rgba[4], std::string* error) {
  jpeg_decompress_struct info;
  JpegError err;
  info.err = jpeg_std_error(&err.mgr);
  err.mgr.error_exit = jpeg_exit;
  err.mgr.output_message = [](j_common_ptr) {};
  double s[3] = {0, 0, 0};
  uint64_t n = 0;
  double lut[256];
  for (int i = 0; i < 256; ++i) lut[i] = srgb_to_linear(i);
  if (setjmp(err.jump)) {
    jpeg_destroy_decompress(&info);
    *error = std::string("JPEG: ") + err.message;
    return false;
  }
  jpeg_create_decompress(&info);
  jpeg_mem_src(&info, bytes.data(), static_cast<unsigned long>(bytes.size()));
  jpeg_read_header(&info, TRUE);
  info.out_color_space = JCS_RGB;
  if (uint64_t{info.image_width} * info.image_height > kMaxTexels) {
    jpeg_destroy_decompress(&info);
    *error = "JPEG: image too large";
    return false;
  }
  jpeg_start_decompress(&info);
  JSAMPARRAY row = (*info.mem->alloc_sarray)(reinterpret_cast<j_common_ptr>(&info), JPOOL_IMAGE,
                                             info.output_width * info.output_components, 1);
  while (info.output_scanline < info.output_height) {
    jpeg_read_scanlines(&info, row, 1);
    const uint8_t* px = row[0];
    for (JDIMENSION x = 0; x < info.output_width; ++x, px += info.output_components)
      for (int k = 0; k < 3; ++k) s[k] += lut[px[k]];
    n += info.output_width;
  }
  jpeg_finish_decompress(&info);
  jpeg_destroy_decompress(&info);
  for (int k = 0; k < 3; ++k) rgba[k] = n ? static_cast<float>(s[k] / static_cast<double>(n)) : 1.0f;
  rgba[3] = 1;
  return true;
}

}  // namespace

bool texture_mean_color(std::span<const uint8_t> bytes, float rgba[4], std::string* error) {
  static const uint8_t png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (bytes.size() >= 8 && std::memcmp(bytes.data(), png_sig, 8) == 0) return png_mean(bytes, rgba, error);
  if (bytes.size() >= 3 && bytes[0] == 0xff && bytes[1] == 0xd8 && bytes[2] == 0xff) return jpeg_mean(bytes, rgba, error);
  *error = "neither PNG nor JPEG";
  return false;
}

bool texture_file_mean_color(const std::string& path, float rgba[4], std::string* error) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec || !std::filesystem::is_regular_file(path, ec) || size > kMaxFileBytes) {
    *error = path + ": cannot be read";
    return false;
  }
  std::ifstream f(path, std::ios::binary);
  std::vector<uint8_t> bytes(size);
  if (!f.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size))) {
    *error = path + ": cannot be read";
    return false;
  }
  return texture_mean_color(bytes, rgba, error);
}

}  // namespace lodstream::io
