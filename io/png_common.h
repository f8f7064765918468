// What the libpng reader (io/grid_reader.cpp) and writer (io/png_writer.cpp) share: the error and warning
// callbacks. libpng calls png_on_error with the error pointer given at png_create_*_struct, which must be a
// PngErrorText: the message is kept there and control returns by longjmp to the caller's setjmp (no C++
// exception crosses libpng's C frames). Warnings are ignored.
#pragma once

#include <png.h>

#include <cstdio>

namespace lodstream::io {

struct PngErrorText {
  char message[256] = {};
};

inline void png_on_error(png_structp png, png_const_charp message) {
  PngErrorText* e = static_cast<PngErrorText*>(png_get_error_ptr(png));
  std::snprintf(e->message, sizeof e->message, "%s", message);
  png_longjmp(png, 1);
}

inline void png_on_warning(png_structp, png_const_charp) {}

}  // namespace lodstream::io
