// The wide levels' pass A as units: see wide_units.h.
#include "stream/wide_units.h"

#include <chrono>
#include <filesystem>

#include <fmt/format.h>

#include "core/status.h"
#include "stream/units.h"

namespace lodstream::stream {

std::string wide_units_dir(const std::string& prefix) { return prefix + "wide-units/"; }
std::string wide_unit_path(const std::string& prefix, unsigned unit, size_t level) {
  return wide_units_dir(prefix) + fmt::format("unit-{}-level-{}.bin", unit, level);
}

WideUnitsPlan plan_wide_units(const ShardEmitInput& in, const std::vector<LevelCut>& cuts, unsigned count) {
  const StoreMeta& meta = *in.meta;
  WideUnitsPlan plan;
  plan.units = count;
  // A level's memory in a unit: its working memory in pass A (its per-cell tables, quadrics, the blocks in
  // flight: emit_level_bytes), its per-cell tables of a batch (kLevelBytesPerCell) and its collapsed bits
  // (a bit an input triangle and segment).
  auto level_bytes = [&](size_t l) {
    return emit_level_bytes(in.cells[l], meta.primitives(), in.options) + kLevelBytesPerCell * in.cells[l] +
           (meta.triangles + meta.lines + 63) / 64 * 8;
  };
  // The group's packed map, paged as the units' emit holds it (stream/paged_vertex_map.h).
  const uint64_t capacity = paged_map_capacity(in.budget, in.options.chunk_bytes);
  auto map_bytes = [&](unsigned bits) { return paged_map_bytes(meta.vertices, bits, capacity); };
  unsigned bits = 0;
  uint64_t bytes = 0;
  for (size_t l = 0; l < cuts.size(); ++l) {
    if (!wide_level(cuts, l, count)) continue;
    const unsigned b = emit_bits(in.cells[l]);
    const uint64_t w = level_bytes(l);
    if (map_bytes(b) + w > in.budget) continue;  // its task classifies it (in batches, if need be)
    if (plan.groups.empty() || bits + b > 64 || map_bytes(bits + b) + bytes + w > in.budget) {
      plan.groups.emplace_back();
      bits = 0, bytes = 0;
    }
    plan.groups.back().push_back(l);
    bits += b, bytes += w;
  }
  return plan;
}

nlohmann::ordered_json run_wide_units(const ShardEmitInput& in, unsigned index, unsigned count, const nlohmann::ordered_json& key,
                                      Progress& progress, EmitScratch& scratch, std::atomic<uint64_t>& read) {
  using nlohmann::ordered_json;
  const StoreMeta& meta = *in.meta;
  const std::vector<LevelCut> cuts = in.cuts.empty() ? shard_cuts(in) : in.cuts;
  const WideUnitsPlan plan = plan_wide_units(in, cuts, count);
  ordered_json figures{{"levels", ordered_json::array()}, {"units", plan.units}};
  for (const auto& g : plan.groups)
    for (size_t l : g) figures["levels"].push_back(l);
  if (plan.groups.empty()) return figures;
  const core::SceneCube cube = scene_cube_of(meta);
  const uint64_t blocks = emit_block_count(meta);
  EmitOptions options = in.options;
  options.own_representatives = true, options.vertex_cells = true, options.primitives_read = &read;
  options.paged_map_capacity = paged_map_capacity(in.budget, in.options.chunk_bytes);
  std::vector<ordered_json> values;
  for (size_t g = 0; g < plan.groups.size(); ++g) {
    const std::vector<size_t>& group = plan.groups[g];
    std::vector<CellRegions> regions_of;
    std::vector<EmitLevel> levels;
    for (size_t l : group)
      regions_of.push_back(load_cell_regions(in.prefix, l, in.cells[l], cube, cuts[l], in.options.representative, meta.single_precision));
    for (size_t i = 0; i < group.size(); ++i) {
      const size_t l = group[i];
      const uint32_t regions = static_cast<uint32_t>(cuts[l].regions.size());
      levels.push_back({l, in.cells[l], in.sizes[l], &cuts[l], &regions_of[i], 0, regions, true});
    }
    const std::string dir = wide_units_dir(in.prefix) + fmt::format("group-{}/", g);
    ordered_json unit_key = key;
    unit_key["wide_levels"] = group;
    unit_key["units"] = plan.units;
    const std::vector<ordered_json> v = take_units(
        dir, plan.units, index % plan.units, [&](unsigned u) { return dir + fmt::format("wide-unit-{}.json", u); }, unit_key,
        [&](unsigned u) {
          const auto t0 = std::chrono::steady_clock::now();
          ClassifyUnit unit{u * blocks / plan.units, (u + 1) * blocks / plan.units, {}};
          for (size_t l : group) unit.paths.push_back(wide_unit_path(in.prefix, u, l));
          options.classify_unit = &unit;
          emit_levels(in.store_dir, meta, in.canonical, in.prefix, levels, in.records, in.cluster, options, progress, scratch,
                      [](size_t, RegionPart&) {});
          options.classify_unit = nullptr;
          ordered_json value{{"seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()},
                             {"by", unit_runner()}};
          return std::pair(unit.paths, std::move(value));
        });
    values.insert(values.end(), v.begin(), v.end());
  }
  const ordered_json f = unit_figures(values);
  figures["seconds"] = f.at("seconds"), figures["by"] = f.at("by");
  return figures;
}

}  // namespace lodstream::stream
