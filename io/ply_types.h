// PLY property types as Greg Turk's format names them ("The PLY Polygon File Format", 1994), with the
// sized aliases (int8 ... float64) most writers use today: shared by the ingest reader (io/ply_reader.cpp)
// and the LOD reader (io/lod_reader.cpp).
#pragma once

#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string_view>
#include <type_traits>

namespace lodstream::io::ply {

enum class Type : uint8_t { none, i8, u8, i16, u16, i32, u32, f32, f64 };

inline Type type_from_name(std::string_view s) {
  if (s == "char" || s == "int8") return Type::i8;
  if (s == "uchar" || s == "uint8") return Type::u8;
  if (s == "short" || s == "int16") return Type::i16;
  if (s == "ushort" || s == "uint16") return Type::u16;
  if (s == "int" || s == "int32") return Type::i32;
  if (s == "uint" || s == "uint32") return Type::u32;
  if (s == "float" || s == "float32") return Type::f32;
  if (s == "double" || s == "float64") return Type::f64;
  return Type::none;
}

inline const char* type_name(Type t) {
  switch (t) {
    case Type::i8: return "char";
    case Type::u8: return "uchar";
    case Type::i16: return "short";
    case Type::u16: return "ushort";
    case Type::i32: return "int";
    case Type::u32: return "uint";
    case Type::f32: return "float";
    case Type::f64: return "double";
    default: return "?";
  }
}

inline unsigned type_size(Type t) {
  switch (t) {
    case Type::i8:
    case Type::u8: return 1;
    case Type::i16:
    case Type::u16: return 2;
    case Type::i32:
    case Type::u32:
    case Type::f32: return 4;
    case Type::f64: return 8;
    default: return 0;
  }
}

inline bool is_integer(Type t) { return t != Type::none && t != Type::f32 && t != Type::f64; }

inline int64_t type_min(Type t) {
  switch (t) {
    case Type::i8: return std::numeric_limits<int8_t>::min();
    case Type::i16: return std::numeric_limits<int16_t>::min();
    case Type::i32: return std::numeric_limits<int32_t>::min();
    default: return 0;
  }
}

inline int64_t type_max(Type t) {
  switch (t) {
    case Type::i8: return std::numeric_limits<int8_t>::max();
    case Type::u8: return std::numeric_limits<uint8_t>::max();
    case Type::i16: return std::numeric_limits<int16_t>::max();
    case Type::u16: return std::numeric_limits<uint16_t>::max();
    case Type::i32: return std::numeric_limits<int32_t>::max();
    case Type::u32: return std::numeric_limits<uint32_t>::max();
    default: return 0;
  }
}

// A value of type T stored at p (unaligned), byte-swapped when the file's byte order differs from ours.
template <typename T, bool Swap>
inline T load(const char* p) {
  using U = std::conditional_t<sizeof(T) == 1, uint8_t,
                               std::conditional_t<sizeof(T) == 2, uint16_t,
                                                  std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>>;
  U u;
  std::memcpy(&u, p, sizeof u);
  if constexpr (Swap && sizeof(T) == 2) u = __builtin_bswap16(u);
  if constexpr (Swap && sizeof(T) == 4) u = __builtin_bswap32(u);
  if constexpr (Swap && sizeof(T) == 8) u = __builtin_bswap64(u);
  return std::bit_cast<T>(u);
}

template <bool Swap>
inline int64_t load_int(const char* p, Type t) {
  switch (t) {
    case Type::i8: return load<int8_t, Swap>(p);
    case Type::u8: return load<uint8_t, Swap>(p);
    case Type::i16: return load<int16_t, Swap>(p);
    case Type::u16: return load<uint16_t, Swap>(p);
    case Type::i32: return load<int32_t, Swap>(p);
    case Type::u32: return load<uint32_t, Swap>(p);
    default: return 0;  // the header allows only integer types where integers are loaded
  }
}

// Every PLY type converts to double exactly.
template <bool Swap>
inline double load_double(const char* p, Type t) {
  switch (t) {
    case Type::f32: return load<float, Swap>(p);
    case Type::f64: return load<double, Swap>(p);
    default: return static_cast<double>(load_int<Swap>(p, t));
  }
}

}  // namespace lodstream::io::ply
