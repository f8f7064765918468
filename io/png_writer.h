// PNG encoding in memory for the images of report.html (renders of original and LOD, mismatch heat maps),
// which embeds them as data: URIs (io/base64.h), so that the report opens in any browser without a server.
//
// Encoded with libpng (PNG specification, ISO/IEC 15948:2004 / W3C, second edition). The output is
// deterministic: IHDR, IDAT and IEND only (no tIME, no text, no gamma chunk), 8 bits per channel,
// no interlacing, zlib level 6 with libpng's default filter choice, so the same pixels give the same bytes
// with the same libpng and zlib.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace lodstream::io {

// Encodes an image of width × height pixels, rows top to bottom, each row width × channels bytes with no
// padding: channels 1 = gray, 3 = RGB, 4 = RGBA (straight, not premultiplied alpha). 1 <= width, height
// <= 1,000,000 (libpng's limit). Bad arguments or an encoder failure (out of memory): Failure(Status::internal).
std::vector<uint8_t> encode_png(std::span<const uint8_t> pixels, int width, int height, int channels);

}  // namespace lodstream::io
