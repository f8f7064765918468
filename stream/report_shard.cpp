// A report task's shares and the file that hands them to the merge (see stream/report_shard.h).
#include "stream/report_shard.h"

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

#include "core/status.h"

namespace lodstream::stream {

namespace {

constexpr char kMagic[8] = {'L', 'O', 'D', 'R', 'E', 'P', 'T', '1'};

}  // namespace

std::string report_shards_dir(const std::string& output_dir) { return output_dir + "/shards/report"; }
std::string report_task_path(const std::string& output_dir, unsigned index) {
  return fmt::format("{}/task-{}.json", report_shards_dir(output_dir), index);
}
std::string report_levels_path(const std::string& output_dir, unsigned index) {
  return fmt::format("{}/task-{}.levels", report_shards_dir(output_dir), index);
}

ReportShareWriter::ReportShareWriter(const std::string& path) : out_(path) { out_.write(kMagic, sizeof kMagic); }

void ReportShareWriter::add(const ReportLevelShare& l) {
  put(out_, l.original_faces), put(out_, l.lod_faces);
  put_array(out_, l.original_to_lod), put_array(out_, l.lod_to_original);
  const core::SilhouetteCounts& s = l.silhouette;
  put(out_, s.mismatched), put(out_, s.covered_either), put(out_, s.covered_both), put(out_, s.thin), put(out_, s.thin_kept);
  put(out_, uint64_t{s.histogram.size()});
  for (const core::SquaredDistanceCount& b : s.histogram) put(out_, b.squared), put(out_, b.count);
  put_array(out_, l.depth_err), put_array(out_, l.normal_err);
  put(out_, uint64_t{l.csv_rows.size()});
  for (const std::string& row : l.csv_rows) put_string(out_, row);
  put(out_, uint64_t{l.views.size()});
  for (const io::HtmlView& v : l.views) {
    put(out_, v.view), put(out_, v.resolution);
    put_array(out_, v.original_rgb), put_array(out_, v.lod_rgb), put_array(out_, v.heat_rgb);
  }
}

ReportShareReader::ReportShareReader(const std::string& path) : TaskFileReader(path, kMagic, "a report task's shares") {}

template <class T>
void ReportShareReader::array(std::vector<T>& v) {
  uint64_t n;
  read(&n, 8);
  if (n > (uint64_t{1} << 40)) fail(Status::io_error, path_ + ": a report task's shares are damaged");
  v.resize(n);
  read(v.data(), n * sizeof(T));
}

void ReportShareReader::next(ReportLevelShare* out) {
  ReportLevelShare& l = *out;
  read(&l.original_faces, 8), read(&l.lod_faces, 8);
  array(l.original_to_lod), array(l.lod_to_original);
  core::SilhouetteCounts& s = l.silhouette;
  read(&s.mismatched, 8), read(&s.covered_either, 8), read(&s.covered_both, 8), read(&s.thin, 8), read(&s.thin_kept, 8);
  uint64_t n;
  read(&n, 8);
  if (n > (uint64_t{1} << 32)) fail(Status::io_error, path_ + ": a report task's shares are damaged");
  s.histogram.resize(n);
  for (core::SquaredDistanceCount& b : s.histogram) read(&b.squared, 4), read(&b.count, 8);
  array(l.depth_err), array(l.normal_err);
  read(&n, 8);
  if (n > (uint64_t{1} << 32)) fail(Status::io_error, path_ + ": a report task's shares are damaged");
  l.csv_rows.resize(n);
  for (std::string& row : l.csv_rows) {
    uint64_t bytes;
    read(&bytes, 8);
    if (bytes > (uint64_t{1} << 20)) fail(Status::io_error, path_ + ": a report task's shares are damaged");
    row.resize(bytes);
    read(row.data(), bytes);
  }
  read(&n, 8);
  if (n > (uint64_t{1} << 20)) fail(Status::io_error, path_ + ": a report task's shares are damaged");
  l.views.resize(n);
  for (io::HtmlView& v : l.views) {
    read(&v.view, 4), read(&v.resolution, 4);
    array(v.original_rgb), array(v.lod_rgb), array(v.heat_rgb);
  }
}

}  // namespace lodstream::stream
