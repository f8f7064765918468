// Runs one format reader the way stream/ingest.cpp does (next_chunk, parse, resolve in file order, then
// finish), serially, and concatenates the resolved chunks. For exact per-reader tests.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "io/reader.h"

namespace lodstream::test {

struct ReadAll {
  std::string format;
  bool soup = false;
  std::vector<double> positions;
  std::vector<int64_t> triangles, lines, points;
  std::vector<uint32_t> triangle_objects, line_objects, point_objects;
  std::vector<std::string> object_names;
  uint64_t polygons = 0, skipped = 0, chunks = 0;
  uint64_t vertex_count() const { return soup ? 0 : positions.size() / 3; }
};

// Throws lodstream::Failure as the pipeline would.
inline ReadAll read_all(const std::string& path, uint64_t target_bytes) {
  io::MappedFile file(path);
  auto reader = io::open_reader(file);
  reader->open();
  ReadAll r;
  r.format = reader->format();
  r.soup = reader->soup();
  io::Chunk chunk;
  io::ParsedChunk parsed;
  uint64_t seq = 0;
  while (true) {
    chunk = io::Chunk{};
    chunk.seq = seq;
    if (!reader->next_chunk(target_bytes, &chunk)) break;
    parsed.clear();
    parsed.seq = seq++;
    reader->parse(chunk, &parsed);
    reader->resolve(&parsed);
    auto append = [](auto& to, const auto& from) { to.insert(to.end(), from.begin(), from.end()); };
    append(r.positions, parsed.positions);
    append(r.triangles, parsed.triangles);
    append(r.lines, parsed.lines);
    append(r.points, parsed.points);
    append(r.triangle_objects, parsed.triangle_objects);
    append(r.line_objects, parsed.line_objects);
    append(r.point_objects, parsed.point_objects);
    r.polygons += parsed.polygons;
    r.skipped += parsed.skipped;
  }
  r.chunks = seq;
  reader->finish(r.soup ? 0 : r.positions.size() / 3);
  r.object_names = reader->object_names();
  return r;
}

}  // namespace lodstream::test
