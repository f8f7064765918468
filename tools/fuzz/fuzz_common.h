// Shared body of the reader fuzz targets (fuzz_obj.cpp, fuzz_ply.cpp, fuzz_stl.cpp, fuzz_glb.cpp).
//
// Each input is written to one file per process, named with the format's extension, and read the way
// tests/reader_harness.h reads it (next_chunk, parse, resolve, finish) at three chunk sizes. The reader
// contract requires, for every input:
//   - success, or lodstream::Failure with status bad_data (usage: unrecognised format), whose message is
//     one line starting with the file path; any other exception or status is a bug;
//   - the same outcome at every chunk size: the same vectors and counts, or the same message;
//   - on success: every vertex reference in [0, vertex count) (non-soup readers), finite positions,
//     one object id per primitive and every object id naming an object.
// Anything else aborts, so libFuzzer records the input.
#pragma once

#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <new>
#include <optional>
#include <string>

#include "core/status.h"
#include "tests/reader_harness.h"

namespace lodstream::fuzz {

struct Outcome {
  std::optional<test::ReadAll> result;
  Status status = Status::ok;
  std::string message;
};

[[noreturn]] inline void bug(const std::string& what) {
  std::fprintf(stderr, "\nFUZZ CONTRACT VIOLATION: %s\n", what.c_str());
  std::fflush(stderr);
  std::abort();
}

// One path per process: $TMPDIR (or /dev/shm when it exists, else /tmp) / lodstream-fuzz-PID.EXT, removed
// at a normal exit.
inline const std::string& input_path(const char* ext) {
  static const std::string path = [ext] {
    const char* dir = std::getenv("TMPDIR");
    std::string d = dir && *dir ? dir : (access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp");
    return d + "/lodstream-fuzz-" + std::to_string(getpid()) + "." + ext;
  }();
  static const bool cleanup = std::atexit([] { unlink(path.c_str()); }) == 0;
  (void)cleanup;
  return path;
}

inline void write_input(const std::string& path, const uint8_t* data, size_t size) {
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) bug("cannot write " + path);
  if (size && std::fwrite(data, 1, size, f) != size) bug("cannot write " + path);
  std::fclose(f);
}

inline void check_success(const test::ReadAll& r) {
  for (double v : r.positions)
    if (!std::isfinite(v)) bug("non-finite coordinate accepted");
  if (r.positions.size() % 3 != 0) bug("positions not a multiple of 3");
  const size_t objects = r.object_names.size();
  if (objects == 0) bug("no object names");
  auto ids_ok = [&](const std::vector<uint32_t>& ids, size_t expect, const char* what) {
    if (ids.size() != expect) bug(std::string("wrong number of object ids for ") + what);
    for (uint32_t id : ids)
      if (id >= objects) bug(std::string("object id out of range for ") + what);
  };
  if (r.soup) {
    if (!r.triangles.empty() || !r.lines.empty() || !r.points.empty()) bug("soup reader emitted references");
    if (r.positions.size() % 9 != 0) bug("soup positions not whole triangles");
    ids_ok(r.triangle_objects, r.positions.size() / 9, "soup triangles");
    return;
  }
  const int64_t n = static_cast<int64_t>(r.vertex_count());
  for (const auto* refs : {&r.triangles, &r.lines, &r.points})
    for (int64_t v : *refs)
      if (v < 0 || v >= n) bug("vertex reference " + std::to_string(v) + " outside [0, " + std::to_string(n) + ")");
  if (r.triangles.size() % 3 != 0 || r.lines.size() % 2 != 0) bug("partial primitive");
  ids_ok(r.triangle_objects, r.triangles.size() / 3, "triangles");
  ids_ok(r.line_objects, r.lines.size() / 2, "lines");
  ids_ok(r.point_objects, r.points.size(), "points");
}

// After the path: ":LINE: ", ": byte OFFSET: " or (glTF) ": /JSON/POINTER: ".
inline bool has_location(const std::string& rest) {
  if (rest.rfind(": /", 0) == 0) return rest.find(": ", 3) != std::string::npos;
  size_t i = 0;
  if (rest.rfind(": byte ", 0) == 0) i = 7;
  else if (rest.rfind(":", 0) == 0) i = 1;
  else return false;
  const size_t digits = i;
  while (i < rest.size() && rest[i] >= '0' && rest[i] <= '9') ++i;
  return i > digits && rest.compare(i, 2, ": ") == 0;
}

inline Outcome run(const std::string& path, uint64_t chunk_bytes) {
  Outcome o;
  try {
    o.result = test::read_all(path, chunk_bytes);
    check_success(*o.result);
  } catch (const Failure& f) {
    o.status = f.status();
    o.message = f.what();
    if (o.status != Status::bad_data && o.status != Status::usage)
      bug(std::string("status ") + status_name(o.status) + ": " + o.message);
    if (o.message.rfind(path, 0) != 0) bug("message does not start with the path: " + o.message);
    for (char c : o.message)
      if (static_cast<unsigned char>(c) < 0x20) bug("message is not one printable line: " + o.message);
    if (o.status == Status::bad_data && !has_location(o.message.substr(path.size())))
      bug("message names no line or byte offset: " + o.message);
  } catch (const std::bad_alloc&) {
    bug("std::bad_alloc (an allocation from an untrusted count?)");
  } catch (const std::exception& e) {
    bug(std::string("unexpected exception: ") + e.what());
  }
  return o;
}

inline bool same(const test::ReadAll& a, const test::ReadAll& b) {
  return a.format == b.format && a.soup == b.soup && a.positions.size() == b.positions.size() &&
         std::equal(a.positions.begin(), a.positions.end(), b.positions.begin(),
                    [](double x, double y) { return x == y || (std::isnan(x) && std::isnan(y)); }) &&
         a.triangles == b.triangles && a.lines == b.lines && a.points == b.points &&
         a.triangle_objects == b.triangle_objects && a.line_objects == b.line_objects &&
         a.point_objects == b.point_objects && a.object_names == b.object_names && a.polygons == b.polygons &&
         a.skipped == b.skipped;
}

inline std::string describe(const Outcome& o) {
  if (!o.result) return std::string(status_name(o.status)) + ": " + o.message;
  const test::ReadAll& r = *o.result;
  return "ok " + r.format + ": " + std::to_string(r.positions.size() / 3) + " positions, " +
         std::to_string(r.triangles.size() / 3) + " triangles, " + std::to_string(r.lines.size() / 2) +
         " lines, " + std::to_string(r.points.size()) + " points, " + std::to_string(r.polygons) + " polygons, " +
         std::to_string(r.skipped) + " skipped, " + std::to_string(r.object_names.size()) + " objects";
}

inline int fuzz_one(const char* ext, const uint8_t* data, size_t size) {
  const std::string& path = input_path(ext);
  write_input(path, data, size);
  const uint64_t sizes[] = {1, 1 + size / 3, uint64_t(1) << 20};
  const Outcome first = run(path, sizes[0]);
  for (size_t k = 1; k < sizeof sizes / sizeof sizes[0]; ++k) {
    const Outcome other = run(path, sizes[k]);
    const bool agree = first.result ? (other.result && same(*first.result, *other.result))
                                    : (!other.result && other.status == first.status && other.message == first.message);
    if (!agree) {
      bug("chunk sizes disagree:\n  chunk " + std::to_string(sizes[0]) + ": " + describe(first) + "\n  chunk " +
          std::to_string(sizes[k]) + ": " + describe(other));
    }
  }
  return 0;
}

}  // namespace lodstream::fuzz
