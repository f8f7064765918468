// Past one machine for `report` (README "Running on a cluster"). Two ways to share the work among N tasks:
//
// By primitive ranges (sort-last; every level has its switching distance, as a simplify output's have):
// task I traces the I-th N-th of every original's primitives (in store order: triangles, lines, points)
// and of every level's (triangles, edges, points), cut into chunks that fit its budget, for EVERY view of
// every level, and lowers EVERY Hausdorff sample of both directions to its distance to those primitives.
// So a task builds ray-casting scenes of an N-th of the original, not of all of it. It keeps its images
// of the original and of the level (their covered pixels: ViewHitsWriter) and its distances. The merge
// composites the tasks' images in task order (core::composite_view: the image of the primitives in their
// order, cast_view's own) and takes each sample's least distance, then compares and forms the figures
// with one machine's code. The original's samples and view targets are drawn once, as units that the
// tasks take up (stream/report_samples.h), not by every task.
//
// By views (a level without a switching distance: its camera needs the whole Hausdorff max first): task I
// measures the I-th N-th of every level's views and of its Hausdorff samples in each direction
// (consecutive ranges: views [I·K/N, (I+1)·K/N), samples likewise) against the whole original, and keeps
// the raw values every figure is formed from rather than the figures: its share of each direction's
// distances in sample order, its views' silhouette counts, their depth and normal errors in view and
// pixel order, their CSV rows and rendered views.
//
// Either way the merge (merge_report, stream/report.cpp) reads the tasks in order, so every array is one
// machine's, and forms the figures with the same code: distances are per-sample minima, counts are
// integers, and every sum runs over the same values in the same order, so report.json, the CSVs and
// report.html are one machine's bytes.
//
// Files: OUTDIR/shards/report/task-I.levels (the shares, level by level, written under a .partial name),
// with ranges also task-I-run-R-level-L.original-views and .level-views (the images), and then
// OUTDIR/shards/report/task-I.json (last: its presence means the task is complete) with the key of what it
// measured (options, task count, how the work was shared), what it saw of every run and level, its
// counters and stages.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "core/silhouette_error.h"
#include "core/view_cast.h"
#include "io/file_writer.h"
#include "io/report_html.h"
#include "stream/shard.h"

namespace lodstream::stream {

// One level's share of a task.
struct ReportLevelShare {
  uint64_t original_faces = 0, lod_faces = 0;           // face samples of each direction (all tasks')
  // Distances of the task's samples, in sample order; by ranges: of every sample, to the task's primitives.
  std::vector<float> original_to_lod, lod_to_original;
  std::vector<float> targets;                           // by ranges: the original's view targets (xyz)
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
// task-I-run-R-level-L.original-views (`level` false) or .level-views: a task's images by ranges.
std::string report_views_path(const std::string& output_dir, unsigned index, size_t run, size_t level, bool of_level);

// A task's images of one level's views, each as its covered pixels (a pixel the task's primitives did not
// cover cannot change a composite: core::later_hit_wins), written view by view.
class ViewHitsWriter {
 public:
  explicit ViewHitsWriter(const std::string& path);
  void add(const core::ViewImage& image);
  void commit() { out_.commit(); }

 private:
  io::FileWriter out_;
  std::vector<char> record_;
};

// Reads the views of a ViewHitsWriter's file in order, each composited into an image (core::composite_pixel)
// as the image of primitives that come after every one already in it.
class ViewHitsReader : TaskFileReader {
 public:
  explicit ViewHitsReader(const std::string& path);
  // Composites the next view into `into` (cleared to the view's resolution when it has another).
  void composite_next(core::ViewImage* into);

 private:
  std::vector<char> block_;
};


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
