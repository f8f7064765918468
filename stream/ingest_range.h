// Ingest by byte ranges (README "Running on a cluster"): task I of N parses only the I-th byte range of
// the input and writes what it parsed to WORK/ingest-ranges/range-I-of-N.seg; the join (ingest() given
// the segments, stream/ingest.cpp) then builds the scene store from them, the same bytes as a one-machine
// ingest of the whole file.
//
// The cut rule (stream/ingest_range.cpp): every task and the join run the reader's own splitter
// (io::Reader::next_chunk) over the whole file with the same chunk size, range_chunk_bytes(file bytes, N),
// a function of the file and N alone. The splitter cuts at record starts only (OBJ: a line start; PLY: a
// record of the element it is in, variable-size face records found by hopping over their list counts,
// ascii PLY at a line; binary STL: a 50-byte record; ascii STL: after an `endfacet` line), so its chunks
// are a deterministic sequence of whole-record byte ranges. Task I takes the chunks that begin in
// [I, I + 1) · file bytes / N: the N tasks take every chunk exactly once. A task parses only the chunks
// it takes (the splitter skips the others without parsing them; where it must walk records to find the
// next cut, PLY's variable-size and ascii records, it reads their bytes but parses none).
//
// Why the joined store is the whole-file store: io::Reader::parse depends only on a chunk's bytes and the
// splitter's description of it (io/reader.h), so a task's parsed chunk is the one a one-machine ingest
// would parse from the same chunk; the join runs the same splitter again (for the reader state finish()
// checks), takes each chunk's parse from the segment that holds it instead of parsing, and feeds it to
// resolve(), which runs in file order over the whole sequence exactly as one machine's does (global and
// relative OBJ indices, objects, materials, face colours, line numbers of errors). The store does not
// depend on the chunk size (its contract: the same bytes for any --chunk-bytes), so the only difference
// from one machine's run, the chunk size, changes nothing. Parse errors are recorded in the parsed chunk
// and raised by the join's resolve(), with the file and line or byte offset one machine reports.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "io/reader.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

// The splitter's chunk size for a file of `file_bytes` cut into `count` ranges: about 16 chunks a range,
// at most 1 MiB, the largest chunk a memory plan gives (at least 1: one record a chunk).
uint64_t range_chunk_bytes(uint64_t file_bytes, unsigned count);
// Chunks in flight for a range task or the join: the plan's tokens, fewer when the range chunks are larger
// than the plan's, so that they hold about the bytes the plan gives (at least 2).
unsigned range_tokens(const MemoryPlan& plan, uint64_t chunk_bytes);
// Range `index` of `count`: the chunks beginning in [first, second) are its.
std::pair<uint64_t, uint64_t> range_bytes(uint64_t file_bytes, unsigned index, unsigned count);

// Where the segments of the work directory's store go: WORK/ingest-ranges; a report's further originals
// (its store-G, G > 0) WORK/ingest-ranges-G.
std::string ingest_ranges_dir(const WorkDir& work, size_t original = 0);
std::string segment_path(const std::string& dir, unsigned index, unsigned count);

// What a range task did.
struct RangeStats {
  uint64_t range_begin = 0, range_end = 0;  // its byte range
  uint64_t parsed_begin = 0, parsed_end = 0;  // the bytes of the chunks it parsed (begin == end: none)
  uint64_t chunks = 0;
  uint64_t skipped_chunks = 0;  // cut by the splitter before the range, not parsed
  double skip_seconds = 0;      // the splitter's time on them
};

// Task `index` of `count`: parses its chunks of `input` and writes its segment (under a .partial name,
// renamed when complete). Throws Failure as ingest does (header errors; the source's identity).
RangeStats ingest_range(const std::string& input, const WorkDir& work, unsigned index, unsigned count,
                        const MemoryPlan& plan, Progress& progress, size_t original = 0);

// The segments of one range ingest, read by the join in chunk order.
class Segments {
 public:
  // Opens the complete set of segments in `dir` made from `source` (its bytes and mtime; any count N).
  // Returns false when `dir` holds no segment of this source (the join is then not asked for). Throws
  // Failure(no_input) with one line naming the missing ranges when a set is incomplete.
  bool open(const std::string& dir, const SourceId& source);
  unsigned count() const { return count_; }
  uint64_t chunk_bytes() const { return chunk_bytes_; }
  // The parse of `chunk` (as the join's splitter cut it) into `out`, from the segment of the range it
  // begins in. Failure(io_error) when the segment does not hold it (a segment of another cut).
  void load(const io::Chunk& chunk, io::ParsedChunk* out);
  // Removes the segment files (after the store is complete).
  void remove();

  Segments();
  ~Segments();
  Segments(const Segments&) = delete;
  Segments& operator=(const Segments&) = delete;

 private:
  struct Reader;
  std::string dir_;
  unsigned count_ = 0;
  uint64_t chunk_bytes_ = 0, file_bytes_ = 0;
  std::vector<std::unique_ptr<Reader>> readers_;
};

// The segment file format (stream/ingest_segment.cpp): a header, then one record per chunk.
struct SegmentHeader {
  uint32_t index = 0, count = 0;
  uint64_t source_bytes = 0;
  int64_t source_mtime_ns = 0;
  uint64_t chunk_bytes = 0;
};
void write_segment_header(io::FileWriter& out, const SegmentHeader& h);
void write_parsed_chunk(io::FileWriter& out, const io::Chunk& chunk, const io::ParsedChunk& c);
void write_segment_end(io::FileWriter& out);

}  // namespace lodstream::stream
