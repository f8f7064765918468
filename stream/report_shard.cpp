// A report task's shares and the file that hands them to the merge (see stream/report_shard.h).
#include "stream/report_shard.h"

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

#include "core/status.h"

namespace lodstream::stream {

namespace {

constexpr char kMagic[8] = {'L', 'O', 'D', 'R', 'E', 'P', 'T', '2'};
constexpr char kViewsMagic[8] = {'L', 'O', 'D', 'V', 'H', 'I', 'T', '1'};

// A covered pixel's record: pixel, depth, normal, kind, centre, and RGB when the view has colours.
constexpr size_t kHitBytes = 4 + 4 + 12 + 1 + 1;
size_t hit_bytes(bool colored) { return kHitBytes + (colored ? 3 : 0); }

}  // namespace

std::string report_shards_dir(const std::string& output_dir) { return output_dir + "/shards/report"; }
std::string report_task_path(const std::string& output_dir, unsigned index) {
  return fmt::format("{}/task-{}.json", report_shards_dir(output_dir), index);
}
std::string report_levels_path(const std::string& output_dir, unsigned index) {
  return fmt::format("{}/task-{}.levels", report_shards_dir(output_dir), index);
}

std::string report_views_path(const std::string& output_dir, unsigned index, size_t run, size_t level, bool of_level) {
  return fmt::format("{}/task-{}-run-{}-level-{}.{}-views", report_shards_dir(output_dir), index, run, level,
                     of_level ? "level" : "original");
}

ViewHitsWriter::ViewHitsWriter(const std::string& path) : out_(path) { out_.write(kViewsMagic, sizeof kViewsMagic); }

void ViewHitsWriter::add(const core::ViewImage& v) {
  const bool colored = !v.color.empty();
  uint64_t covered = 0;
  for (uint8_t k : v.kind) covered += k != 0;
  put(out_, uint32_t{v.resolution}), put(out_, uint8_t{colored}), put(out_, covered);
  const size_t bytes = hit_bytes(colored);
  record_.resize(bytes);
  for (uint64_t p = 0; p < v.kind.size(); ++p) {
    if (v.kind[p] == 0) continue;
    char* r = record_.data();
    const uint32_t pixel = static_cast<uint32_t>(p);
    std::memcpy(r, &pixel, 4), std::memcpy(r + 4, &v.depth[p], 4), std::memcpy(r + 8, &v.normal[3 * p], 12);
    r[20] = static_cast<char>(v.kind[p]), r[21] = static_cast<char>(v.centre[p]);
    if (colored) std::memcpy(r + 22, &v.color[3 * p], 3);
    out_.write(r, bytes);
  }
}

ViewHitsReader::ViewHitsReader(const std::string& path) : TaskFileReader(path, kViewsMagic, "a report task's views") {}

void ViewHitsReader::composite_next(core::ViewImage* into) {
  uint32_t resolution;
  uint8_t colored;
  uint64_t covered;
  read(&resolution, 4), read(&colored, 1), read(&covered, 8);
  const uint64_t pixels = uint64_t{resolution} * resolution;
  if (colored > 1 || covered > pixels || resolution > (1u << 16))
    fail(Status::io_error, path_ + ": a report task's views are damaged");
  if (resolution == 0) return;  // the task cast nothing into this view
  core::begin_composite(into, resolution, colored != 0);
  const size_t bytes = hit_bytes(colored != 0);
  constexpr uint64_t kBlockRecords = 1 << 16;
  block_.resize(bytes * kBlockRecords);
  for (uint64_t done = 0; done < covered;) {
    const uint64_t n = std::min(kBlockRecords, covered - done);
    read(block_.data(), n * bytes);
    for (uint64_t i = 0; i < n; ++i) {
      const char* r = block_.data() + i * bytes;
      uint32_t pixel;
      float depth, normal[3];
      std::memcpy(&pixel, r, 4), std::memcpy(&depth, r + 4, 4), std::memcpy(normal, r + 8, 12);
      const uint8_t kind = static_cast<uint8_t>(r[20]), centre = static_cast<uint8_t>(r[21]);
      if (pixel >= pixels || kind == 0 || kind > 3 || centre > 1) fail(Status::io_error, path_ + ": a report task's views are damaged");
      core::composite_pixel(into, pixel, depth, normal, kind, centre != 0,
                            colored ? reinterpret_cast<const uint8_t*>(r + 22) : nullptr);
    }
    done += n;
  }
}

ReportShareWriter::ReportShareWriter(const std::string& path) : out_(path) { out_.write(kMagic, sizeof kMagic); }

void ReportShareWriter::add(const ReportLevelShare& l) {
  put(out_, l.original_faces), put(out_, l.lod_faces);
  put_array(out_, l.original_to_lod), put_array(out_, l.lod_to_original), put_array(out_, l.targets);
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
  array(l.original_to_lod), array(l.lod_to_original), array(l.targets);
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
