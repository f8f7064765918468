// Past one machine for `report` (README "Running on a cluster"): task I of N measures the I-th N-th of
// every level's views and of its Hausdorff samples in each direction (consecutive ranges: views
// [I·K/N, (I+1)·K/N), samples likewise), and keeps the raw values every figure is formed from rather than
// the figures: its share of each direction's distances in sample order, its views' silhouette counts,
// their depth and normal errors in view and pixel order, their CSV rows and rendered views. The merge
// (merge_report, stream/report.cpp) reads the tasks in order, so every array is one machine's, and forms
// the figures with the same code: distances are per-sample minima, counts are integers, and every sum runs
// over the same values in the same order, so report.json, the CSVs and report.html are one machine's bytes.
//
// Files: OUTDIR/shards/report/task-I.levels (the shares, level by level, written under a .partial name)
// and then OUTDIR/shards/report/task-I.json (last: its presence means the task is complete) with the
// key of what it measured (options, task count), what it saw of every run and level, its counters and
// stages.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "core/silhouette_error.h"
#include "io/file_writer.h"
#include "io/report_html.h"
#include "stream/shard.h"

namespace lodstream::stream {

// One level's share of a task.
struct ReportLevelShare {
  uint64_t original_faces = 0, lod_faces = 0;           // face samples of each direction (all tasks')
  std::vector<float> original_to_lod, lod_to_original;  // distances of the task's samples, in sample order
  core::SilhouetteCounts silhouette;                    // over the task's views
  std::vector<float> depth_err, normal_err;             // the task's views', in view and pixel order
  std::vector<std::string> csv_rows;                    // one per view of the task, in view order
  std::vector<io::HtmlView> views;                      // the task's rendered views
};

// [I·n/N, (I+1)·n/N): task I's consecutive share of n items (all of them when count is 0).
inline std::pair<uint64_t, uint64_t> share_of(uint64_t n, unsigned index, unsigned count) {
  if (count == 0) return {0, n};
  return {n * index / count, n * (index + 1) / count};
}

std::string report_shards_dir(const std::string& output_dir);
std::string report_task_path(const std::string& output_dir, unsigned index);    // task-I.json
std::string report_levels_path(const std::string& output_dir, unsigned index);  // task-I.levels

class ReportShareWriter {
 public:
  explicit ReportShareWriter(const std::string& path);
  void add(const ReportLevelShare& level);
  void commit() { out_.commit(); }

 private:
  io::FileWriter out_;
};

// Reads a task's levels in the order they were added. Failure(io_error) naming the file when it is
// missing, cut short or damaged.
class ReportShareReader : TaskFileReader {
 public:
  explicit ReportShareReader(const std::string& path);
  void next(ReportLevelShare* out);

 private:
  template <class T>
  void array(std::vector<T>& v);
};

}  // namespace lodstream::stream
