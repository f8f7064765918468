// Runs one format reader the way stream/ingest.cpp does (next_chunk, parse, resolve in file order, then
// finish), serially, and concatenates the resolved chunks. For exact per-reader tests.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <thread>
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
  std::vector<uint32_t> triangle_materials, line_materials, point_materials;  // empty in a chunk: all 0
  std::vector<core::Material> materials;
  std::vector<uint8_t> colors;
  uint64_t polygons = 0, skipped = 0, chunks = 0;
  uint64_t degenerate = 0, face_segments = 0, planar_faces = 0;
  uint64_t vertex_count() const { return soup ? 0 : positions.size() / 3; }
};

inline void append(ReadAll* r, const io::ParsedChunk& parsed) {
  auto add = [](auto& to, const auto& from) { to.insert(to.end(), from.begin(), from.end()); };
  add(r->positions, parsed.positions);
  add(r->positions, parsed.positions32);  // widened: exact
  add(r->triangles, parsed.triangles);
  add(r->triangles, parsed.triangles32);
  add(r->lines, parsed.lines);
  add(r->points, parsed.points);
  add(r->triangle_objects, parsed.triangle_objects);
  add(r->line_objects, parsed.line_objects);
  add(r->point_objects, parsed.point_objects);
  auto add_materials = [](std::vector<uint32_t>& to, const std::vector<uint32_t>& from, size_t count) {
    if (from.empty()) to.insert(to.end(), count, 0u);
    else to.insert(to.end(), from.begin(), from.end());
  };
  add(r->colors, parsed.colors);
  add_materials(r->triangle_materials, parsed.triangle_materials, parsed.triangle_objects.size());
  add_materials(r->line_materials, parsed.line_materials, parsed.line_objects.size());
  add_materials(r->point_materials, parsed.point_materials, parsed.point_objects.size());
  r->polygons += parsed.polygons;
  r->degenerate += parsed.degenerate;
  r->face_segments += parsed.face_segments;
  r->planar_faces += parsed.planar_faces.size() / 2;
  r->skipped += parsed.skipped;
}

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
    append(&r, parsed);
  }
  r.chunks = seq;
  reader->finish(r.soup ? 0 : r.positions.size() / 3);
  r.object_names = reader->object_names();
  r.materials = reader->materials();
  return r;
}

// Cuts every chunk first, parses them on `threads` threads at once, each taking chunks from the end of
// the file backwards, then resolves in file order: parse() must be thread-safe and order-free.
inline ReadAll read_parallel(const std::string& path, uint64_t target_bytes, int threads) {
  io::MappedFile file(path);
  auto reader = io::open_reader(file);
  reader->open();
  std::vector<io::Chunk> chunks;
  for (;;) {
    io::Chunk c;
    c.seq = chunks.size();
    if (!reader->next_chunk(target_bytes, &c)) break;
    chunks.push_back(std::move(c));
  }
  std::vector<io::ParsedChunk> parsed(chunks.size());
  std::vector<std::thread> workers;
  for (int t = 0; t < threads; ++t) {
    workers.emplace_back([&, t] {
      for (size_t i = chunks.size(); i-- > 0;) {
        if (i % static_cast<size_t>(threads) != static_cast<size_t>(t)) continue;
        parsed[i].seq = i;
        reader->parse(chunks[i], &parsed[i]);
      }
    });
  }
  for (auto& w : workers) w.join();
  ReadAll r;
  r.format = reader->format();
  r.soup = reader->soup();
  r.chunks = chunks.size();
  for (auto& p : parsed) {
    reader->resolve(&p);
    append(&r, p);
  }
  reader->finish(r.soup ? 0 : r.positions.size() / 3);
  r.object_names = reader->object_names();
  r.materials = reader->materials();
  return r;
}

// Every field of two reads is equal.
inline void expect_same(const ReadAll& a, const ReadAll& b, const std::string& context) {
  SCOPED_TRACE(context);
  EXPECT_EQ(a.format, b.format);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.lines, b.lines);
  EXPECT_EQ(a.points, b.points);
  EXPECT_EQ(a.triangle_objects, b.triangle_objects);
  EXPECT_EQ(a.line_objects, b.line_objects);
  EXPECT_EQ(a.point_objects, b.point_objects);
  EXPECT_EQ(a.object_names, b.object_names);
  EXPECT_EQ(a.colors, b.colors);
  EXPECT_EQ(a.triangle_materials, b.triangle_materials);
  EXPECT_EQ(a.line_materials, b.line_materials);
  EXPECT_EQ(a.point_materials, b.point_materials);
  EXPECT_TRUE(a.materials == b.materials);
  EXPECT_EQ(a.polygons, b.polygons);
  EXPECT_EQ(a.degenerate, b.degenerate);
  EXPECT_EQ(a.face_segments, b.face_segments);
  EXPECT_EQ(a.planar_faces, b.planar_faces);
  EXPECT_EQ(a.skipped, b.skipped);
}

}  // namespace lodstream::test
