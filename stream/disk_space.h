// Disk space of a job: what its work directory holds, and the free-space check made before it starts.
//
// The check compares an estimate with the free space (statvfs) of each file system the job writes to,
// and stops the job with Failure(io_error) and the figures when the estimate does not fit, before
// anything is written. The estimate comes from the input's size and format (a job cannot know its counts
// before reading the input) and from what each stage writes per vertex and primitive (below); it is an
// estimate, so a disk that fills anyway still ends the job with io_error, leaving the stages done so far
// for a rerun to resume from.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include <nlohmann/json.hpp>

#include "lodstream/lodstream.h"

namespace lodstream::stream {

// Bytes of the regular files under `path`, recursively (sizes, not blocks); 0 when it does not exist.
// Entries that vanish while it walks are skipped.
uint64_t directory_bytes(const std::string& path);

// The work directory's files when the job ends: in all and per top-level entry.
WorkDirUsage work_dir_usage(const std::string& path, uint64_t input_bytes);

// What an estimate is made from: a store's counts, or a guess of them from an input file.
struct SceneCounts {
  uint64_t vertices = 0, triangles = 0;
  bool single_precision = true;  // positions stored as float
  bool soup = false;             // STL: corners welded by external sorts during ingest
};
// Typical counts for a file of `bytes` bytes in `format` (io::Reader::format()): a mesh has about half as
// many vertices as triangles, and each format spends about so many bytes on them.
SceneCounts guess_counts(uint64_t bytes, const std::string& format);

// Most bytes each job has in its work directory at once (see disk_space.cpp for the terms).
uint64_t info_work_bytes(const SceneCounts& c);
uint64_t report_work_bytes(const SceneCounts& c);
// sharded: a sharded run (its records' positions in weight order, its cells by vertex, the clustering merge's plain cells).
uint64_t simplify_work_bytes(const SceneCounts& c, size_t levels, Representative representative, bool sharded);
// Bytes of simplify's outputs for `output_triangles` triangles over all levels.
uint64_t simplify_output_bytes(uint64_t output_triangles, const SimplifyOptions& options);

// The checks each job makes before it writes anything (Options::check_disk_space): the work directory's
// estimate less what it already holds (a rerun resumes from it), and the outputs'. Sniffs each input's
// format, so a missing or unrecognised input fails here as it would in ingest.
void check_info_space(const std::string& input, const std::string& work_dir);
// sharded: a task of a sharded run (its work directory may hold the records' positions in weight order).
void check_simplify_space(const std::string& input, const SimplifyOptions& options, const std::string& work_dir,
                          bool sharded);
// task_bytes: what a report task hands the merge in its output directory (0 for one machine).
void check_report_space(std::span<const std::string> originals, const std::string& work_dir,
                        const std::string& output_dir, uint64_t task_bytes);

// {"path", "bytes", "input_bytes", "ratio", "entries": {name: bytes}}, for the JSON files jobs write.
nlohmann::ordered_json work_dir_json(const WorkDirUsage& usage);

struct SpaceNeed {
  std::string path;  // a directory, possibly not created yet: its nearest existing ancestor is checked
  std::string what;  // "work directory", "outputs"
  uint64_t bytes = 0;
};
// Sums the needs per file system and throws Failure(io_error), one line with the figures, when one
// exceeds the space available there to an unprivileged user.
void check_free_space(std::span<const SpaceNeed> needs);

}  // namespace lodstream::stream
