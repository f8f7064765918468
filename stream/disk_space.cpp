#include "stream/disk_space.h"

#include <sys/stat.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <filesystem>
#include <map>
#include <system_error>

#include <fmt/format.h>

#include "core/status.h"
#include "io/mapped_file.h"
#include "io/reader.h"
#include "stream/cluster_stage.h"

namespace lodstream::stream {

namespace fs = std::filesystem;

namespace {

std::string size_text(uint64_t bytes) {
  const double b = static_cast<double>(bytes);
  return b >= 1e9 ? fmt::format("{:.2f} GB", b / 1e9) : fmt::format("{:.1f} MB", b / 1e6);
}

uint64_t entry_bytes(const fs::directory_entry& e) {
  std::error_code ec;
  if (e.is_regular_file(ec)) {
    const uint64_t n = e.file_size(ec);
    return ec ? 0 : n;
  }
  if (e.is_directory(ec)) return directory_bytes(e.path().string());
  return 0;
}

// The nearest existing ancestor of `path` (itself when it exists): where its files will land.
std::string existing_ancestor(const std::string& path) {
  std::error_code ec;
  fs::path p = fs::absolute(path, ec);
  while (!p.empty() && !fs::exists(p, ec) && p != p.root_path()) p = p.parent_path();
  return p.empty() ? std::string(".") : p.string();
}

}  // namespace

uint64_t directory_bytes(const std::string& path) {
  std::error_code ec;
  uint64_t total = 0;
  for (fs::recursive_directory_iterator it(path, fs::directory_options::skip_permission_denied, ec), end;
       !ec && it != end; it.increment(ec)) {
    std::error_code e2;
    if (it->is_regular_file(e2)) {
      const uint64_t n = it->file_size(e2);
      if (!e2) total += n;
    }
  }
  return total;
}

WorkDirUsage work_dir_usage(const std::string& path, uint64_t input_bytes) {
  WorkDirUsage u;
  u.path = path;
  u.input_bytes = input_bytes;
  std::error_code ec;
  for (fs::directory_iterator it(path, ec), end; !ec && it != end; it.increment(ec)) {
    const uint64_t n = entry_bytes(*it);
    u.entries.emplace_back(it->path().filename().string(), n);
    u.bytes += n;
  }
  std::sort(u.entries.begin(), u.entries.end());
  return u;
}

// Bytes per record of each format, for a typical mesh with half as many vertices as triangles (per
// triangle: half a vertex record and one face record). Binary PLY: 12-byte float vertices, 13-byte
// triangle faces; text: about 30 bytes a vertex line and 22 a face line; binary STL: 50 bytes a facet,
// ASCII STL about 250.
SceneCounts guess_counts(uint64_t bytes, const std::string& format) {
  double per_triangle = 0.5 * 12 + 13;
  SceneCounts c;
  if (format == "obj") {
    per_triangle = 0.5 * 30 + 22;
    c.single_precision = false;  // OBJ coordinates are stored as doubles
  } else if (format == "ply-ascii") {
    per_triangle = 0.5 * 30 + 22;
  } else if (format == "stl-binary") {
    per_triangle = 50, c.soup = true;
  } else if (format == "stl-ascii") {
    per_triangle = 250, c.soup = true;
  }
  c.triangles = static_cast<uint64_t>(std::ceil(static_cast<double>(bytes) / per_triangle));
  c.vertices = (c.triangles + 1) / 2;
  return c;
}

namespace {

// The scene store: positions, 3 vertex ids a triangle (object runs are negligible).
uint64_t store_bytes(const SceneCounts& c) { return c.vertices * (c.single_precision ? 12 : 24) + c.triangles * 12; }

// What ingest adds while it runs: for a soup, the corner sort (32-byte records, 3 a triangle), whose runs
// are released as they are merged (external_sort.h) while the corner-id sort (16 bytes a corner) fills,
// and 4 bytes a triangle of object ids.
uint64_t ingest_transient_bytes(const SceneCounts& c) { return c.soup ? c.triangles * (3 * 32 + 4) : 0; }

}  // namespace

uint64_t info_work_bytes(const SceneCounts& c) { return store_bytes(c) + ingest_transient_bytes(c); }

uint64_t report_work_bytes(const SceneCounts& c) { return store_bytes(c) + ingest_transient_bytes(c); }

// Simplify, after ingest, at its largest (every stored vertex counted as a record of the weight index, as
// if none shared a position): the store and the weld map (a bit a stored vertex, and 4 bytes for each one
// welded to another: taken as 3 in 10, as on the city scene) throughout, and then the larger of
// - the grade stage's sort: 12-byte runs a record, released as they are merged into the order (4 bytes a
//   record) and, for the mean representative, the grades (8), and, in a run that grades in shares, the
//   records' positions in weight order (12 or 24 bytes a record: stream/position_gather.h; one machine does
//   not write them, keeping its work directory within 1.5x the input); the weld's pairs (8 bytes a welded vertex:
//   its sort's runs, or, as units, their runs kept through the grading shares) fit in that count, which
//   takes every stored vertex as a record where only the distinct positions are (12 · distinct + 8 ·
//   welded <= 12 · vertices);
// - the end of the cluster stage: the order (and grades, and positions), one bit-packed cell map per level (at most
//   bit_width(records) bits a record; 22 bits or less on the city scene's levels) and the cell info by
//   representative (12 to 48 bytes a cell, about 12 cells per 100 vertices over all levels on the city),
//   and during emit a level emitted in batches' representatives (24 bytes a cell of the finest level,
//   taken as half the cells); a sharded run's add every level's cells by vertex (at most 4 bytes a stored vertex,
//   packed to the level's bits, stream/vertex_cells.h) and, until those are written, the clustering merge's pairs by
//   vertex range (at most 8 bytes a record a split level, packed, stream/cluster_merge.h; every level counted;
//   the shares' decisions, 8 bytes a record a split level too, are emptied before the pairs are written), which
//   the tasks remove before the wide levels' units write their outputs (stream/wide_units.h: a bit a
//   triangle and segment a wide level, and each block's deduplicated outputs; 86 MB for the 193 M-triangle
//   city's three wide levels, within the 8 bytes a vertex and level so freed).
// The GLB's binary data and the levels' scratch files are in the output directory (simplify_output_bytes),
// not here.
uint64_t simplify_work_bytes(const SceneCounts& c, size_t levels, Representative representative, bool sharded) {
  const uint64_t v = c.vertices;
  const bool ordered_positions = sharded;
  const uint64_t weld = v / 8 + 4 * v * 3 / 10;
  const uint64_t index = 4 * v + (ordered_positions ? position_bytes(c.single_precision) * v : 0) +
                         (representative == Representative::mean ? 8 * v : 0);
  const uint64_t maps = static_cast<uint64_t>(levels) * ((v * static_cast<uint64_t>(std::bit_width(v)) + 7) / 8);
  const uint64_t info = v * 12 / 100 * cell_info_bytes(cell_info_kind(representative), c.single_precision);
  const uint64_t reps = v * 6 / 100 * 24 + (sharded ? 12 * v * static_cast<uint64_t>(levels) : 0);
  const uint64_t after_ingest = store_bytes(c) + weld + std::max(12 * v, index + maps + info + reps);
  return std::max(store_bytes(c) + ingest_transient_bytes(c), after_ingest);
}

// Per output triangle: PLY about 40 bytes (half a vertex of position and normal, 24 bytes, and a 13-byte
// face), the GLB about as much, twice while its binary data, gathered beside it, is copied in behind its
// JSON; OBJ text about 60. During emit, the levels' scratch files (stream/level_files.h: half a vertex of 24
// bytes and a 24-byte triangle, about 40 bytes) sit beside the GLB's gathered data, before it is copied.
uint64_t simplify_output_bytes(uint64_t output_triangles, const SimplifyOptions& o) {
  const uint64_t glb = o.write_glb ? 40 : 0;
  const uint64_t per = (o.write_ply ? 40 : 0) + std::max(2 * glb, glb + 40) + (o.write_obj ? 60 : 0);
  return output_triangles * per;
}

void check_free_space(std::span<const SpaceNeed> needs) {
  struct Fs {
    std::string dir;
    uint64_t need = 0;
    std::string parts;
  };
  std::map<dev_t, Fs> by_fs;
  for (const SpaceNeed& n : needs) {
    const std::string dir = existing_ancestor(n.path);
    struct stat st {};
    if (::stat(dir.c_str(), &st) != 0) continue;  // creating it will report the error
    Fs& f = by_fs[st.st_dev];
    if (f.dir.empty()) f.dir = dir;
    f.need += n.bytes;
    f.parts += fmt::format("{}{} {}", f.parts.empty() ? "" : ", ", n.what, size_text(n.bytes));
  }
  for (const auto& [dev, f] : by_fs) {
    struct statvfs sv {};
    if (::statvfs(f.dir.c_str(), &sv) != 0) continue;
    const uint64_t free = static_cast<uint64_t>(sv.f_bavail) * sv.f_frsize;
    if (f.need > free)
      fail(Status::io_error, fmt::format("{}: not enough free disk space: the run needs about {} ({}), the file "
                                         "system has {} free (free some, choose another --work or -o, or pass "
                                         "--no-space-check to try anyway)",
                                         f.dir, size_text(f.need), f.parts, size_text(free)));
  }
}

namespace {

SceneCounts guess_input_counts(const std::string& input) {
  const io::MappedFile file(input);
  const std::unique_ptr<io::Reader> reader = io::open_reader(file);
  return guess_counts(file.size(), reader->format());
}

uint64_t beyond(uint64_t estimate, uint64_t present) { return estimate > present ? estimate - present : 0; }

}  // namespace

void check_info_space(const std::string& input, const std::string& work_dir) {
  const SceneCounts c = guess_input_counts(input);
  const SpaceNeed need{work_dir, "work directory", beyond(info_work_bytes(c), directory_bytes(work_dir))};
  check_free_space(std::span(&need, 1));
}

void check_simplify_space(const std::string& input, const SimplifyOptions& o, const std::string& work_dir, bool sharded) {
  const SceneCounts c = guess_input_counts(input);
  const size_t levels = !o.cell_sizes.empty() ? o.cell_sizes.size() : !o.target_triangles.empty() ? o.target_triangles.size() : o.levels;
  // Output triangles: the targets, or the default levels' (counts falling geometrically from the input's
  // to a few thousand, simplify.cpp), which explicit cell sizes are taken to resemble.
  uint64_t out = 0;
  if (!o.target_triangles.empty()) {
    for (uint64_t t : o.target_triangles) out += t;
  } else {
    const double t0 = static_cast<double>(std::max<uint64_t>(c.triangles, 1));
    const double coarsest = std::min(4000.0, t0 / std::pow(2.0, static_cast<double>(levels)));
    const double ratio = std::pow(coarsest / t0, 1.0 / static_cast<double>(levels));
    for (size_t l = 0; l < levels; ++l) out += static_cast<uint64_t>(t0 * std::pow(ratio, static_cast<double>(l + 1)));
  }
  const SpaceNeed needs[2] = {
      {work_dir, "work directory",
       beyond(simplify_work_bytes(c, levels, o.representative, sharded), directory_bytes(work_dir))},
      {o.output_dir, "outputs", simplify_output_bytes(out, o)}};
  check_free_space(needs);
}

void check_report_space(std::span<const std::string> originals, const std::string& work_dir,
                        const std::string& output_dir, uint64_t task_bytes) {
  uint64_t bytes = 0;
  for (const std::string& o : originals) bytes += report_work_bytes(guess_input_counts(o));
  const SpaceNeed needs[2] = {{work_dir, "work directory", beyond(bytes, directory_bytes(work_dir))},
                              {output_dir, "report task's shares", task_bytes}};
  check_free_space(std::span(needs, task_bytes ? 2 : 1));
}

nlohmann::ordered_json work_dir_json(const WorkDirUsage& u) {
  nlohmann::ordered_json entries = nlohmann::ordered_json::object();
  for (const auto& [name, bytes] : u.entries) entries[name] = bytes;
  return {{"path", u.path},
          {"bytes", u.bytes},
          {"input_bytes", u.input_bytes},
          {"ratio", u.input_bytes ? static_cast<double>(u.bytes) / static_cast<double>(u.input_bytes) : 0.0},
          {"entries", entries}};
}

}  // namespace lodstream::stream

std::string lodstream::work_dir_json(const WorkDirUsage& usage) { return stream::work_dir_json(usage).dump(); }
