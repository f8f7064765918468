// A task's share of simplify's emit stage, and the parts files it hands to the merge (see stream/shard.h).
#include "stream/shard.h"
#include "stream/wide_units.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <set>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>

#include <fmt/format.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "stream/kill_point.h"
#include "stream/tiles.h"

namespace lodstream::stream {

namespace {

constexpr char kPartsMagic[8] = {'L', 'O', 'D', 'P', 'A', 'R', 'T', '3'};

}  // namespace

ShardLock::ShardLock(const std::string& work_dir, const std::string& name, bool wait) {
  std::error_code ec;
  std::filesystem::create_directories(work_dir, ec);
  const std::string path = work_dir + "/" + name;
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) fail(Status::io_error, path + ": cannot open the work directory's lock: " + std::strerror(errno));
  int r;
  while ((r = ::flock(fd_, wait ? LOCK_EX : LOCK_EX | LOCK_NB)) != 0 && errno == EINTR) {
  }
  if (r != 0) {
    const int e = errno;
    ::close(fd_);
    fd_ = -1;
    if (!wait && e == EWOULDBLOCK) return;
    fail(Status::io_error, path + ": cannot lock the work directory: " + std::strerror(e));
  }
}

void ShardLock::release() {
  if (fd_ < 0) return;
  ::flock(fd_, LOCK_UN);
  ::close(fd_);
  fd_ = -1;
}

std::pair<uint32_t, uint32_t> shard_regions(const LevelCut& cut, unsigned index, unsigned count) {
  uint64_t total = 0;
  for (uint64_t c : cut.cells) total += c;
  // A region belongs to the task whose share holds the cells before it: task t owns [t, t + 1) · total / count
  // (cells < 2^40 and count <= 100000: the product fits in 64 bits).
  auto owner = [&](uint64_t before) {
    return total == 0 ? 0u : static_cast<unsigned>(before * count / total);
  };
  const uint32_t n = static_cast<uint32_t>(cut.regions.size());
  uint32_t first = n, end = n;
  uint64_t before = 0;
  for (uint32_t r = 0; r < n; ++r) {
    const unsigned t = std::min(owner(before), count - 1);
    if (t >= index && first == n) first = r;
    if (t > index) {
      end = r;
      break;
    }
    before += cut.cells[r];
  }
  if (first > end) first = end;
  return {first, end};
}

std::vector<uint64_t> shard_bounds(const LevelCut& finest, unsigned count) {
  std::vector<uint64_t> bounds(count + 1, UINT64_MAX);
  bounds[0] = 0;
  const uint32_t n = static_cast<uint32_t>(finest.regions.size());
  for (unsigned t = 1; t < count; ++t) {
    const uint32_t first = shard_regions(finest, t, count).first;
    if (first < n) bounds[t] = core::region_code(finest.regions[first]);
  }
  // Invariant: non-decreasing, since a cut's regions are disjoint nodes in region order (their codes
  // strictly increase) and the first region of task t's run does not decrease with t.
  return bounds;
}

std::pair<uint32_t, uint32_t> shard_regions_in(const LevelCut& cut, const std::vector<uint64_t>& bounds, unsigned index) {
  auto below = [&](uint64_t code) {
    return static_cast<uint32_t>(std::partition_point(cut.regions.begin(), cut.regions.end(),
                                                      [&](const core::RegionKey& k) { return core::region_code(k) < code; }) -
                                 cut.regions.begin());
  };
  const uint32_t first = index == 0 ? 0 : below(bounds[index]);
  const uint32_t end = index + 2 >= bounds.size() ? static_cast<uint32_t>(cut.regions.size()) : below(bounds[index + 1]);
  return {first, std::max(first, end)};
}

std::vector<std::pair<uint32_t, uint32_t>> shard_runs(const std::vector<LevelCut>& cuts, unsigned index, unsigned count) {
  const size_t n = cuts.size();
  std::vector<std::pair<uint32_t, uint32_t>> runs(n);
  if (n == 0) return runs;
  const std::vector<int> wide = wide_tasks(cuts, count);
  const unsigned first = wide_task_count(cuts, count);  // the runs of codes go to tasks first to count - 1
  const bool has_codes = index >= first;
  const std::vector<uint64_t> bounds = shard_bounds(cuts[0], count - first);
  for (size_t l = 0; l < n; ++l) {
    const uint32_t regions = static_cast<uint32_t>(cuts[l].regions.size());
    const std::pair<uint32_t, uint32_t> all{0, regions}, none{regions, regions};
    if (wide[l] >= 0) runs[l] = wide[l] == static_cast<int>(index) ? all : none;
    else runs[l] = has_codes ? shard_regions_in(cuts[l], bounds, index - first) : none;
  }
  return runs;
}

namespace {
std::vector<size_t> wide_levels(const std::vector<LevelCut>& cuts, unsigned count) {
  std::vector<size_t> wide;
  for (size_t l = 0; l < cuts.size(); ++l)
    if (wide_level(cuts, l, count)) wide.push_back(l);
  return wide;
}
unsigned wide_task_count_of(size_t wide, unsigned count) {
  return count >= 3 ? static_cast<unsigned>(std::min<size_t>(wide, count - 2)) : 0;
}
}  // namespace

unsigned wide_task_count(const std::vector<LevelCut>& cuts, unsigned count) {
  return wide_task_count_of(wide_levels(cuts, count).size(), count);
}

std::vector<int> wide_tasks(const std::vector<LevelCut>& cuts, unsigned count) {
  const std::vector<size_t> wide = wide_levels(cuts, count);
  const unsigned k = std::max(1u, wide_task_count_of(wide.size(), count));
  std::vector<int> task(cuts.size(), -1);
  for (size_t j = 0; j < wide.size(); ++j) task[wide[j]] = static_cast<int>(j * k / wide.size());
  return task;
}

bool wide_level(const std::vector<LevelCut>& cuts, size_t level, unsigned count) {
  return level > 0 && cuts[level].regions.size() < count;
}

std::string shards_dir(const std::string& output_dir) { return output_dir + "/shards"; }
std::string shard_parts_path(const std::string& output_dir, unsigned index, size_t level) {
  return fmt::format("{}/task-{}-lod{}.parts", shards_dir(output_dir), index, level);
}
std::string shard_task_path(const std::string& output_dir, unsigned index) {
  return fmt::format("{}/task-{}.json", shards_dir(output_dir), index);
}

PartsWriter::PartsWriter(const std::string& path) : out_(path) { out_.write(kPartsMagic, sizeof kPartsMagic); }

void PartsWriter::add(const RegionInfo& info, const RegionPart& part) {
  put(out_, uint64_t{info.level});
  put(out_, info.key.depth);
  put(out_, info.key.x), put(out_, info.key.y), put(out_, info.key.z);
  put(out_, info.cell_size);
  put(out_, info.cells);
  for (int k = 0; k < 3; ++k) put(out_, info.box_min[k]);
  for (int k = 0; k < 3; ++k) put(out_, info.box_max[k]);
  put(out_, part.region);
  const core::LodMesh& m = part.mesh;
  put_array(out_, m.positions), put_array(out_, m.normals), put_array(out_, m.triangles);
  put_array(out_, m.edges), put_array(out_, m.thickness), put_array(out_, m.points);
  put_array(out_, part.vertex_key), put_array(out_, part.owned_key);
  put_array(out_, part.owned_positions), put_array(out_, part.owned_normals);
  // Materials and colours (empty without them); the material table itself is the task summary's.
  put_array(out_, m.triangle_materials), put_array(out_, m.edge_materials), put_array(out_, m.point_materials);
  put_array(out_, m.colors), put_array(out_, part.owned_colors);
  put_array(out_, m.point_size);  // empty when the level has no point sizes
  ++parts_;
}

void PartsWriter::commit() { out_.commit(); }

PartsReader::PartsReader(const std::string& path) : TaskFileReader(path, kPartsMagic, "a task's parts") {}

bool PartsReader::next(StoredPart* out) {
  uint64_t level;
  if (std::fread(&level, 1, sizeof level, f_) != sizeof level) {
    if (std::feof(f_)) return false;
    fail(Status::io_error, path_ + ": cannot read a task's parts");
  }
  RegionInfo& info = out->info;
  info.level = level;
  read(&info.key.depth, 1);
  read(&info.key.x, 4), read(&info.key.y, 4), read(&info.key.z, 4);
  read(&info.cell_size, 8);
  read(&info.cells, 8);
  read(info.box_min, 24), read(info.box_max, 24);
  RegionPart& part = out->part;
  read(&part.region, 4);
  auto array = [&](auto& v) {
    uint64_t n;
    read(&n, 8);
    if (n > (uint64_t{1} << 40)) fail(Status::io_error, path_ + ": a task's parts file is damaged");
    v.resize(n);
    read(v.data(), n * sizeof(v[0]));
  };
  core::LodMesh& m = part.mesh;
  array(m.positions), array(m.normals), array(m.triangles), array(m.edges), array(m.thickness), array(m.points);
  array(part.vertex_key), array(part.owned_key), array(part.owned_positions), array(part.owned_normals);
  array(m.triangle_materials), array(m.edge_materials), array(m.point_materials), array(m.colors), array(part.owned_colors);
  array(m.point_size);
  return true;
}

std::vector<LevelCut> shard_cuts(const ShardEmitInput& in) {
  const core::SceneCube cube = scene_cube_of(*in.meta);
  const std::vector<core::SideBound> sides = in.tiles ? tile_side_bounds(in.sizes, in.cells, cube.side) : std::vector<core::SideBound>();
  return cut_levels(in.prefix, in.cells, cube, in.tile_triangles / 2, in.options.representative, in.meta->single_precision, sides);
}

std::vector<EmitCounts> emit_shard(const ShardEmitInput& in, unsigned index, unsigned count, const std::string& output_dir,
                                   Progress& progress, EmitScratch& scratch, uint64_t* primitives_read,
                                   std::vector<std::array<uint32_t, 3>>* runs_out) {
  const StoreMeta& meta = *in.meta;
  const size_t n = in.sizes.size();
  // This task's older summary no longer vouches for its parts; tasks of a run with more tasks are stale.
  std::error_code ec;
  std::filesystem::create_directories(shards_dir(output_dir), ec);
  if (ec) fail(Status::io_error, shards_dir(output_dir) + ": cannot create: " + ec.message());
  std::filesystem::remove(shard_task_path(output_dir, index), ec);
  for (const auto& e : std::filesystem::directory_iterator(shards_dir(output_dir), ec)) {
    unsigned i;
    if (std::sscanf(e.path().filename().c_str(), "task-%u", &i) == 1 && i >= count) std::filesystem::remove(e.path(), ec);
  }
  const core::SceneCube cube = scene_cube_of(meta);
  const std::vector<LevelCut> cuts = in.cuts.empty() ? shard_cuts(in) : in.cuts;
  const std::vector<std::pair<uint32_t, uint32_t>> runs = shard_runs(cuts, index, count);
  if (runs_out) {
    runs_out->clear();
    for (size_t l = 0; l < n; ++l) runs_out->push_back({runs[l].first, runs[l].second, static_cast<uint32_t>(cuts[l].regions.size())});
  }
  std::vector<uint64_t> share(n, 0), largest(n, 0);
  for (size_t l = 0; l < n; ++l) {
    for (uint32_t r = runs[l].first; r < runs[l].second; ++r)
      share[l] += cuts[l].cells[r], largest[l] = std::max(largest[l], cuts[l].cells[r]);
  }
  // Memory of a batched level (as plan_emit_level counts it): pass A's tables for the batch's cells and its
  // halo (half as many again), with their quadrics (the task sums its cells' own), the quadrics of the ring
  // beyond the halo (pass Q: half as many again), their slots and regions by rank (kBatchCellBytes), and its
  // share of the blocks in flight; per cell of the whole level only bits: the batch's (kBatchBitsPer64Cells)
  // and those of the task's regions (CellRegions); a bit a primitive of the blocks it visits (the collapsed
  // bits: counted as twice its share of the cells' share of the input, for the blocks its halo reaches);
  // and the group's packed cluster map, paged from the vertex-cells files (stream/paged_vertex_map.h: at
  // most an eighth of the budget of pages, its page table).
  const bool quadrics = in.options.representative == Representative::quadric;
  const uint64_t per_cell =
      (emit_level_bytes(1, 0, in.options) + kBatchCellBytes) * 3 / 2 + (quadrics ? sizeof(core::Quadric) / 2 : 0);
  const uint64_t in_flight = emit_level_bytes(0, meta.primitives(), in.options) + emit_corner_bytes(in.budget);
  auto level_bytes = [&](size_t l, uint64_t batch) {
    const double part = in.cells[l] ? 2.0 * static_cast<double>(share[l]) / static_cast<double>(in.cells[l]) : 1.0;
    const uint64_t collapsed = static_cast<uint64_t>(static_cast<double>(meta.primitives()) * std::min(1.0, part)) / 8 + (64 << 10);
    return (in.cells[l] + 63) / 64 * kBatchBitsPer64Cells + cell_regions_bytes(in.cells[l], share[l]) + collapsed + in_flight +
           per_cell * batch;
  };
  EmitOptions emit = in.options;  // its thickness passes hold what in_flight counts for them
  emit.corner_bytes = emit_corner_bytes(in.budget);
  emit.own_representatives = true;
  const BlockBounds bounds = read_block_bounds(block_bounds_path(in.prefix), meta);
  std::atomic<uint64_t> read{0};
  emit.block_bounds = &bounds, emit.primitives_read = &read, emit.vertex_cells = true;
  emit.paged_map_capacity = paged_map_capacity(in.budget, in.options.chunk_bytes);
  auto map_bytes = [&](unsigned bits) { return paged_map_bytes(meta.vertices, bits, emit.paged_map_capacity); };

  // The wide levels whose pass A ran as units (wide_units.h).
  std::set<size_t> classified_levels;
  if (in.wide_units)
    for (const std::vector<size_t>& g : plan_wide_units(in, cuts, count).groups) classified_levels.insert(g.begin(), g.end());

  std::vector<EmitCounts> counts(n);
  std::vector<std::unique_ptr<PartsWriter>> writers(n);
  for (size_t l = 0; l < n; ++l) writers[l] = std::make_unique<PartsWriter>(shard_parts_path(output_dir, index, l));
  auto info = [&](size_t l, uint32_t r) {
    RegionInfo i;
    i.level = l, i.key = cuts[l].regions[r], i.cell_size = in.sizes[l], i.cells = cuts[l].cells[r];
    core::region_box(cube, i.key, i.box_min, i.box_max);
    return i;
  };
  auto add = [&](size_t l, const EmitCounts& c) {
    counts[l].triangles += c.triangles, counts[l].edges += c.edges, counts[l].points += c.points;
    counts[l].edges_on_triangles += c.edges_on_triangles, counts[l].points_covered += c.points_covered;
  };
  // Emits `group` (levels whose shares fit one batch together) in one pass, or its one level in batches of
  // consecutive regions while they fit.
  auto emit_group = [&](const std::vector<size_t>& group, unsigned bits, uint64_t bytes) {
    const size_t first = group[0];
    // The regions of the task's own cells (a bit and a half a cell of the level beside them).
    std::vector<CellRegions> regions;
    for (size_t l : group)
      regions.push_back(load_cell_regions(in.prefix, l, in.cells[l], cube, cuts[l], in.options.representative, meta.single_precision,
                                          runs[l].first, runs[l].second));
    if (group.size() > 1 || map_bytes(bits) + bytes <= in.budget) {
      // Wide levels whose pass A ran as units (wide_units.h): read from the units' files.
      std::vector<std::vector<std::string>> classified;
      if (std::all_of(group.begin(), group.end(), [&](size_t l) { return classified_levels.count(l) > 0; })) {
        for (size_t l : group) {
          classified.emplace_back();
          for (unsigned u = 0; u < count; ++u) classified.back().push_back(wide_unit_path(in.prefix, u, l));
        }
        emit.classified = &classified;
      }
      std::vector<EmitLevel> levels;
      for (size_t i = 0; i < group.size(); ++i) {
        const size_t l = group[i];
        levels.push_back({l, in.cells[l], in.sizes[l], &cuts[l], &regions[i], runs[l].first, runs[l].second, true});
      }
      const std::vector<EmitCounts> c = emit_levels(in.store_dir, meta, in.canonical, in.prefix, levels, in.records, in.cluster,
                                                    emit, progress, scratch, [&](size_t i, RegionPart& part) {
                                                      const size_t l = group[i];
                                                      writers[l]->add(info(l, part.region), part);
                                                    });
      emit.classified = nullptr;
      for (size_t i = 0; i < group.size(); ++i) add(group[i], c[i]);
      return;
    }
    const uint64_t room = in.budget - map_bytes(bits) - level_bytes(first, 0);
    const uint64_t batch_cells = std::max<uint64_t>(1, room / per_cell);
    for (uint32_t r = runs[first].first; r < runs[first].second;) {
      uint64_t held = cuts[first].cells[r];
      uint32_t e = r + 1;
      while (e < runs[first].second && held + cuts[first].cells[e] <= batch_cells) held += cuts[first].cells[e++];
      const EmitLevel level{first, in.cells[first], in.sizes[first], &cuts[first], &regions[0], r, e, true};
      const std::vector<EmitCounts> c = emit_levels(in.store_dir, meta, in.canonical, in.prefix, std::span<const EmitLevel>(&level, 1),
                                                    in.records, in.cluster, emit, progress, scratch,
                                                    [&](size_t, RegionPart& part) { writers[first]->add(info(first, part.region), part); });
      add(first, c[0]);
      r = e;
    }
  };
  // The task's levels in groups that share a pass over the input, as far as the memory plan allows (as one
  // machine's groups do): first its runs of codes, then apart from them its wide levels (shard_runs), whose
  // regions read about the whole input whatever they are grouped with, so that they take one pass between
  // them rather than a share level's bits taking their room. Neither the groups nor the batches change a byte.
  for (const bool wide : {false, true}) {
    std::vector<size_t> levels;  // the task's levels of this kind with regions, in level order
    for (size_t l = 0; l < n; ++l)
      if (runs[l].first < runs[l].second && wide_level(cuts, l, count) == wide) levels.push_back(l);
    for (size_t i = 0; i < levels.size();) {
      const size_t first = levels[i];
      const uint64_t alone = map_bytes(emit_bits(in.cells[first])) + level_bytes(first, largest[first]);
      if (alone > in.budget)
        fail(Status::usage, fmt::format("task {} of {}: emitting level {} ({} cells) region by region needs about {} MiB, "
                                        "more than --memory allows ({} MiB for the stage): raise --memory",
                                        index, count, first, in.cells[first], alone >> 20, in.budget >> 20));
      std::vector<size_t> group{first};
      unsigned bits = emit_bits(in.cells[first]);
      uint64_t bytes = level_bytes(first, share[first]);
      size_t j = i + 1;
      if (map_bytes(bits) + bytes <= in.budget)
        for (; j < levels.size(); ++j) {
          const size_t l = levels[j];
          const unsigned b = bits + emit_bits(in.cells[l]);
          const uint64_t w = bytes + level_bytes(l, share[l]);
          if (b > 64 || map_bytes(b) + w > in.budget) break;
          group.push_back(l), bits = b, bytes = w;
        }
      emit_group(group, bits, bytes);
      i = j;
    }
  }
  for (auto& w : writers) w->commit();
  if (primitives_read) *primitives_read += read.load();
  return counts;
}

nlohmann::ordered_json tiles_options_json(const TilesOptions& o) {
  return {{"levels", o.levels},
          {"thick", o.thick},
          {"pixels_per_cell", o.pixels_per_cell},
          {"scene_magnitude", o.scene_magnitude},
          {"cube_min", {o.cube_min[0], o.cube_min[1], o.cube_min[2]}},
          {"cube_side", o.cube_side},
          {"transform", o.transform},
          {"generator", o.generator}};
}

TilesOptions tiles_options_from_json(const nlohmann::ordered_json& j) {
  TilesOptions o;
  o.levels = j.at("levels");
  o.thick = j.at("thick");
  o.pixels_per_cell = j.at("pixels_per_cell");
  o.scene_magnitude = j.at("scene_magnitude");
  for (int k = 0; k < 3; ++k) o.cube_min[k] = j.at("cube_min").at(k);
  o.cube_side = j.at("cube_side");
  o.transform = j.at("transform").get<std::vector<double>>();
  o.generator = j.at("generator");
  return o;
}

void write_shard_task(const std::string& output_dir, unsigned index, const nlohmann::ordered_json& key,
                      const nlohmann::ordered_json& manifest) {
  const nlohmann::ordered_json task{{"index", index}, {"key", key}, {"manifest", manifest}};
  kill_point(fmt::format("task-{}.json", index));
  io::write_file_atomic(shard_task_path(output_dir, index), task.dump(1) + "\n", io::Sync::durable);
}

std::vector<nlohmann::ordered_json> read_task_summaries(const std::string& dir, const TaskNames& n) {
  using nlohmann::ordered_json;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec))
    fail(Status::no_input, dir + ": no " + n.parts + " to merge (run `lodstream " + n.command + " ... --shard I/N --work DIR` for every task first)");
  std::map<unsigned, ordered_json> tasks;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    unsigned i;
    char tail[8] = {0};
    if (std::sscanf(name.c_str(), "task-%u.%5s", &i, tail) != 2 || std::string(tail) != "json") continue;
    try {
      tasks[i] = ordered_json::parse(io::read_small_file(e.path().string()));
    } catch (const std::exception&) {
      fail(Status::io_error, e.path().string() + ": cannot read a " + n.task + "'s summary");
    }
  }
  if (tasks.empty())
    fail(Status::no_input, dir + ": no " + n.task + " has finished (no task-I.json): run every task (`lodstream " + n.command +
                               " ... --shard I/N`) first");
  // The count of the job: the one most tasks name (a task of an older job with another count is stale).
  std::map<unsigned, unsigned> votes;
  for (const auto& [i, t] : tasks) ++votes[t.at("key").at("count").get<unsigned>()];
  const unsigned count = std::max_element(votes.begin(), votes.end(), [](auto& a, auto& b) { return a.second < b.second; })->first;
  std::vector<unsigned> missing, stale;
  const ordered_json* key = nullptr;
  for (unsigned i = 0; i < count; ++i) {
    const auto it = tasks.find(i);
    if (it == tasks.end()) {
      missing.push_back(i);
      continue;
    }
    const ordered_json& k = it->second.at("key");
    if (k.at("count") != count || (key && k != *key)) stale.push_back(i);
    else if (!key) key = &k;
  }
  if (!missing.empty() || !stale.empty()) {
    std::string what;
    if (!missing.empty())
      what = fmt::format("{}{} {} of {} ha{} not finished (no {}/task-I.json)", n.task, missing.size() == 1 ? "" : "s",
                         fmt::join(missing, ", "), count, missing.size() == 1 ? "s" : "ve", dir);
    if (!stale.empty())
      what += fmt::format("{}{}{} {} of {} belong{} to another {} ({})", what.empty() ? "" : "; ", n.task, stale.size() == 1 ? "" : "s",
                          fmt::join(stale, ", "), count, stale.size() == 1 ? "s" : "", n.job, n.other);
    fail(Status::no_input, "merge: " + what + ": rerun " + (missing.size() + stale.size() == 1 ? "it" : "them") + " (`lodstream " +
                               n.command + " ... --shard I/" + std::to_string(count) + "` on the same work directory)");
  }
  std::vector<ordered_json> out;
  for (unsigned i = 0; i < count; ++i) out.push_back(std::move(tasks[i]));
  return out;
}

}  // namespace lodstream::stream

namespace lodstream {

bool shard_from_env(unsigned* index, unsigned* count, std::string* error) {
  auto number = [](const char* name, unsigned* out) {
    const char* v = std::getenv(name);
    if (!v || !*v) return false;
    char* end = nullptr;
    errno = 0;
    const unsigned long n = std::strtoul(v, &end, 10);
    if (*end || errno || n > 1u << 30) return false;
    *out = static_cast<unsigned>(n);
    return true;
  };
  const bool given_count = number("LODSTREAM_SHARD_COUNT", count);
  if (number("SLURM_ARRAY_TASK_ID", index)) {
    if (!given_count && !number("SLURM_ARRAY_TASK_COUNT", count)) {
      *error = "--shard-from-env: SLURM_ARRAY_TASK_ID is set but neither SLURM_ARRAY_TASK_COUNT nor LODSTREAM_SHARD_COUNT";
      return false;
    }
  } else if (number("JOB_COMPLETION_INDEX", index) || number("AWS_BATCH_JOB_ARRAY_INDEX", index)) {
    if (!given_count) {
      *error = "--shard-from-env: JOB_COMPLETION_INDEX or AWS_BATCH_JOB_ARRAY_INDEX is set: give the task count in LODSTREAM_SHARD_COUNT";
      return false;
    }
  } else {
    *error = "--shard-from-env: none of SLURM_ARRAY_TASK_ID, JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX is set (a number)";
    return false;
  }
  if (*count == 0 || *index >= *count) {
    *error = fmt::format("--shard-from-env: task index {} is not below the count {}", *index, *count);
    return false;
  }
  return true;
}

}  // namespace lodstream
