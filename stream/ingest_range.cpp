// Ingest by byte ranges: the cut rule and a range task (see stream/ingest_range.h for why the chunks a
// task takes are deterministic and why the joined store equals the whole-file store).
//
// A task is a TBB parallel_pipeline of three stages: the reader's splitter in file order (chunks that
// begin before the range are dropped unparsed, the first that begins at or past its end stops it), the
// parse in parallel, and the segment written in file order.
#include "stream/ingest_range.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <mutex>
#include <tuple>

#include <fmt/format.h>
#include <tbb/parallel_pipeline.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "stream/kill_point.h"

namespace lodstream::stream {

uint64_t range_chunk_bytes(uint64_t file_bytes, unsigned count) {
  constexpr uint64_t kMax = 1 << 20, kChunksPerRange = 16;
  return std::clamp<uint64_t>(file_bytes / std::max(1u, count) / kChunksPerRange, 1, kMax);
}

unsigned range_tokens(const MemoryPlan& plan, uint64_t chunk_bytes) {
  if (chunk_bytes <= plan.chunk_bytes) return plan.tokens;
  return static_cast<unsigned>(std::clamp<uint64_t>(plan.tokens * plan.chunk_bytes / chunk_bytes, 2, plan.tokens));
}

std::pair<uint64_t, uint64_t> range_bytes(uint64_t file_bytes, unsigned index, unsigned count) {
  // floor(file_bytes · i / count) without overflow: file_bytes = q · count + r, and r · i < count².
  auto at = [&](unsigned i) { return file_bytes / count * i + file_bytes % count * i / count; };
  return {at(index), index + 1 == count ? UINT64_MAX : at(index + 1)};
}

std::string ingest_ranges_dir(const WorkDir& work, size_t original) {
  return work.file(original == 0 ? std::string("ingest-ranges") : fmt::format("ingest-ranges-{}", original));
}

std::string segment_path(const std::string& dir, unsigned index, unsigned count) {
  return fmt::format("{}/range-{}-of-{}.seg", dir, index, count);
}

RangeStats ingest_range(const std::string& input, const WorkDir& work, unsigned index, unsigned count,
                        const MemoryPlan& plan, Progress& progress, size_t original) {
  if (count == 0 || index >= count)
    fail(Status::usage, fmt::format("--shard-ingest {}/{}: the index must be below the count", index, count));
  io::MappedFile file(input);
  std::unique_ptr<io::Reader> reader = io::open_reader(file);
  reader->open();
  const uint64_t chunk_bytes = range_chunk_bytes(file.size(), count);
  RangeStats stats;
  // The last range's end is open: a chunk may begin at the end of the file (glTF's cut the splitter's
  // progress, not their data's bytes, into chunk windows, and an empty one may sit there).
  uint64_t range_begin = 0, range_end = 0;
  std::tie(range_begin, range_end) = range_bytes(file.size(), index, count);
  stats.range_begin = range_begin;
  stats.range_end = std::min(range_end, file.size());

  const std::string dir = ingest_ranges_dir(work, original);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) fail(Status::io_error, dir + ": cannot create: " + ec.message());
  io::FileWriter out(segment_path(dir, index, count), 1 << 22);
  write_segment_header(out, {index, count, file.size(), file.mtime_ns(), chunk_bytes});

  struct Slot {
    io::Chunk chunk;
    io::ParsedChunk parsed;
  };
  std::vector<std::unique_ptr<Slot>> slots;
  std::vector<Slot*> free_slots;
  std::mutex free_mutex;
  const unsigned tokens = range_tokens(plan, chunk_bytes);
  for (unsigned i = 0; i < tokens; ++i) {
    slots.push_back(std::make_unique<Slot>());
    free_slots.push_back(slots.back().get());
  }
  uint64_t seq = 0;
  bool done = false;
  const double span = static_cast<double>(std::max<uint64_t>(1, stats.range_end - stats.range_begin));
  progress.report("ingest-range", 0);
  tbb::parallel_pipeline(
      tokens,
      tbb::make_filter<void, Slot*>(tbb::filter_mode::serial_in_order,
                                    [&](tbb::flow_control& fc) -> Slot* {
                                      Slot* s = nullptr;
                                      {
                                        std::lock_guard lock(free_mutex);
                                        s = free_slots.back();
                                        free_slots.pop_back();
                                      }
                                      for (;;) {
                                        progress.check();
                                        s->chunk = io::Chunk{};
                                        s->chunk.seq = seq;
                                        const auto t0 = std::chrono::steady_clock::now();
                                        if (done || !reader->next_chunk(chunk_bytes, &s->chunk)) break;
                                        ++seq;
                                        const uint64_t begin = s->chunk.bytes.begin();
                                        if (begin >= range_end) break;
                                        if (begin >= range_begin) return s;
                                        s->chunk.bytes.reset();  // another range's chunk: not parsed
                                        ++stats.skipped_chunks;
                                        stats.skip_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
                                      }
                                      done = true;
                                      s->chunk.bytes.reset();
                                      std::lock_guard lock(free_mutex);
                                      free_slots.push_back(s);
                                      fc.stop();
                                      return nullptr;
                                    }) &
          tbb::make_filter<Slot*, Slot*>(tbb::filter_mode::parallel,
                                         [&](Slot* s) {
                                           s->parsed.clear();
                                           s->parsed.seq = s->chunk.seq;
                                           reader->parse(s->chunk, &s->parsed);
                                           return s;
                                         }) &
          tbb::make_filter<Slot*, void>(tbb::filter_mode::serial_in_order, [&](Slot* s) {
            write_parsed_chunk(out, s->chunk, s->parsed);
            if (stats.chunks++ == 0) stats.parsed_begin = s->chunk.bytes.begin();
            stats.parsed_end = s->chunk.bytes.end();
            s->chunk.bytes.reset();
            progress.report("ingest-range", std::min(1.0, static_cast<double>(stats.parsed_end - stats.range_begin) / span));
            std::lock_guard lock(free_mutex);
            free_slots.push_back(s);
          }));
  write_segment_end(out);
  kill_point(std::filesystem::path(out.path()).filename().string());
  out.commit();
  progress.report("ingest-range", 1);
  return stats;
}

}  // namespace lodstream::stream
