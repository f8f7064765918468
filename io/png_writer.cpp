// PNG encoding with libpng into a std::vector.
//
// libpng reports errors by longjmp to the setjmp in write_png, which therefore holds only trivially
// destructible locals (a longjmp skips destructors). The output vector lives in the caller, and the write
// callback turns std::bad_alloc into png_error outside its catch block, so no C++ exception crosses libpng's
// C frames and no longjmp leaves a handler. encode_png throws Failure after libpng's state is released.
#include "io/png_writer.h"

#include <png.h>

#include <cstdio>
#include <new>
#include <string>

#include "core/status.h"
#include "io/png_common.h"

namespace lodstream::io {
namespace {

struct Sink {
  std::vector<uint8_t>* bytes = nullptr;
  PngErrorText error;
};

void on_write(png_structp png, png_bytep data, size_t length) {
  Sink* sink = static_cast<Sink*>(png_get_io_ptr(png));
  bool grown = true;
  try {
    sink->bytes->insert(sink->bytes->end(), data, data + length);
  } catch (const std::bad_alloc&) {
    grown = false;
  }
  if (!grown) png_error(png, "out of memory");
}

void on_flush(png_structp) {}

// Returns false with sink.error.message set when libpng fails.
bool write_png(const uint8_t* pixels, png_uint_32 width, png_uint_32 height, int color_type, size_t stride,
               Sink& sink) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &sink.error, png_on_error, png_on_warning);
  if (png == nullptr) {
    std::snprintf(sink.error.message, sizeof sink.error.message, "cannot create the encoder");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_write_struct(&png, nullptr);
    std::snprintf(sink.error.message, sizeof sink.error.message, "cannot create the encoder");
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, &sink, on_write, on_flush);
  png_set_compression_level(png, 6);
  png_set_IHDR(png, info, width, height, 8, color_type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (png_uint_32 y = 0; y < height; ++y) png_write_row(png, pixels + y * stride);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

std::vector<uint8_t> encode_png(std::span<const uint8_t> pixels, int width, int height, int channels) {
  int color_type = 0;
  switch (channels) {
    case 1: color_type = PNG_COLOR_TYPE_GRAY; break;
    case 3: color_type = PNG_COLOR_TYPE_RGB; break;
    case 4: color_type = PNG_COLOR_TYPE_RGB_ALPHA; break;
    default: fail(Status::internal, "encode_png: " + std::to_string(channels) + " channels (1, 3 or 4)");
  }
  if (width < 1 || height < 1 || width > 1000000 || height > 1000000) {
    fail(Status::internal, "encode_png: image size " + std::to_string(width) + " x " + std::to_string(height) +
                               " out of range");
  }
  const size_t stride = static_cast<size_t>(width) * static_cast<size_t>(channels);
  if (pixels.size() != stride * static_cast<size_t>(height)) {
    fail(Status::internal, "encode_png: pixel buffer size is not width x height x channels");
  }
  std::vector<uint8_t> bytes;
  Sink sink;
  sink.bytes = &bytes;
  if (!write_png(pixels.data(), static_cast<png_uint_32>(width), static_cast<png_uint_32>(height), color_type,
                 stride, sink)) {
    fail(Status::internal, std::string("encode_png: libpng: ") + sink.error.message);
  }
  return bytes;
}

}  // namespace lodstream::io
