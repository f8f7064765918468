// Small, allocation-free helpers for parsing text records in place. Every function takes [p, end) and
// never reads past end; none of them needs a terminating NUL.
#pragma once

#include <locale.h>

#include <cctype>
#include <charconv>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

namespace lodstream::io::text {

inline bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// Bytes that may appear in a text model file: printable ASCII, tabs, line breaks and UTF-8 (>= 0x80).
inline bool is_text_byte(unsigned char c) { return c >= 0x20 || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

inline const char* skip_blanks(const char* p, const char* end) {
  while (p < end && is_blank(*p)) ++p;
  return p;
}

// End of the current line (pointer to its '\n', or end).
inline const char* line_end(const char* p, const char* end) {
  const void* nl = std::memchr(p, '\n', static_cast<size_t>(end - p));
  return nl ? static_cast<const char*>(nl) : end;
}

// The next blank-separated token of [p, end); advances p past it. Empty at end.
inline std::string_view next_token(const char*& p, const char* end) {
  p = skip_blanks(p, end);
  const char* b = p;
  while (p < end && !is_blank(*p) && *p != '\n') ++p;
  return {b, static_cast<size_t>(p - b)};
}

// The correctly rounded value of a number std::from_chars found out of range: 0 or a denormal for an
// underflow, infinity for an overflow (strtod in the C locale; the whole token, however long).
inline double out_of_range_value(const char* b, const char* e) {
  static const locale_t c_locale = newlocale(LC_ALL_MASK, "C", static_cast<locale_t>(nullptr));
  const std::string token(b, e);
  return strtod_l(token.c_str(), nullptr, c_locale);
}

// Parses a decimal or scientific number at p (after blanks); accepts a leading '+'. Advances p. Returns
// false if no number starts there or it is followed by something other than a blank or line end.
// Infinite or NaN spellings ("inf", "nan") and overflowing numbers ("1e999") parse as infinity or NaN,
// so the caller reports them by value; an underflowing number ("1e-400") is its rounded value, 0.
inline bool parse_double(const char*& p, const char* end, double* out) {
  p = skip_blanks(p, end);
  if (p < end && *p == '+') ++p;
  auto [q, ec] = std::from_chars(p, end, *out, std::chars_format::general);
  if (ec != std::errc() && ec != std::errc::result_out_of_range) return false;
  if (q < end && !is_blank(*q) && *q != '\n') return false;
  if (ec == std::errc::result_out_of_range) *out = out_of_range_value(p, q);
  p = q;
  return true;
}

// Parses a signed decimal integer at p (after blanks); stops at a non-digit, which the caller checks.
inline bool parse_int64(const char*& p, const char* end, int64_t* out) {
  p = skip_blanks(p, end);
  if (p < end && *p == '+') ++p;
  auto [q, ec] = std::from_chars(p, end, *out);
  if (ec != std::errc()) return false;
  p = q;
  return true;
}

inline uint64_t count_newlines(const char* p, const char* end) {
  uint64_t n = 0;
  while (p < end) {
    const void* nl = std::memchr(p, '\n', static_cast<size_t>(end - p));
    if (!nl) break;
    ++n;
    p = static_cast<const char*>(nl) + 1;
  }
  return n;
}

inline bool finite3(const double* v) {
  // x - x is 0 for finite x and NaN for NaN or infinity.
  return (v[0] - v[0]) == 0 && (v[1] - v[1]) == 0 && (v[2] - v[2]) == 0;
}

// "%20" and friends decoded (URIs, cookies); a '%' not followed by two hex digits is kept as it is.
inline std::string percent_decode(std::string_view s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out += static_cast<char>(std::stoi(std::string(s.substr(i + 1, 2)), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

}  // namespace lodstream::io::text
