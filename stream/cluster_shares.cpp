// The clustering pass as N shares, and their merge. This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.2
// See cluster_shares.h for the plan, the passes and the invariant.
#include "stream/cluster_shares.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <queue>

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include "core/floating_cell_centers.h"
#include "core/floating_cell_region.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "stream/cell_map_file.h"
#include "stream/cluster_merge.h"
#include "stream/position_gather.h"
#include "stream/ranked_bits.h"
#include "stream/store_access.h"
#include "stream/units.h"
#include "stream/vertex_cells.h"

namespace lodstream::stream {

namespace {

constexpr int kBins = 4096;
constexpr uint64_t kWindowRecords = uint64_t{1} << 22;  // records a window of a column holds
constexpr uint64_t kBlockRecords = uint64_t{1} << 16;   // records' positions in weight order read at once
constexpr double kInf = std::numeric_limits<double>::infinity();

std::string dec_path(const std::string& prefix, unsigned share, size_t level) { return cluster_share_decisions_path(prefix, share, level); }
std::string ctr_path(const std::string& prefix, unsigned share, size_t level) { return cluster_share_centers_path(prefix, share, level); }
// A whole level's map and info, as the share that clustered it leaves them.
std::string whole_map_path(const std::string& prefix, size_t level) { return cluster_shares_dir(prefix) + fmt::format("level-{}.map", level); }
std::string whole_info_path(const std::string& prefix, size_t level) { return cluster_shares_dir(prefix) + fmt::format("level-{}.info", level); }
std::string whole_vertex_cells_path(const std::string& prefix, size_t level) {
  return cluster_shares_dir(prefix) + fmt::format("level-{}.vcells", level);
}

// Positions at the store's precision (floats for a float store: half the bytes; widened to double, exactly,
// when read).
struct Positions {
  bool single = true;
  std::vector<float> f;
  std::vector<double> d;
  void add(const double* p) {
    if (single) f.insert(f.end(), {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])});
    else d.insert(d.end(), p, p + 3);
  }
  void get(size_t k, double* p) const {
    for (int a = 0; a < 3; ++a) p[a] = single ? static_cast<double>(f[3 * k + a]) : d[3 * k + a];
  }
  uint64_t bytes() const { return f.capacity() * sizeof(float) + d.capacity() * sizeof(double); }
};

// Writes a position at the store's precision (floats for a float store: exact, since its positions are floats).
void write_position(io::FileWriter& out, const double* p, bool single_precision) {
  if (single_precision) {
    const float f[3] = {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
    out.write(f, sizeof f);
  } else {
    out.write(p, 24);
  }
}

// Reads a position written so.
void read_position(const char* at, bool single_precision, double* p) {
  if (single_precision) {
    float f[3];
    std::memcpy(f, at, 12);
    p[0] = f[0], p[1] = f[1], p[2] = f[2];
  } else {
    std::memcpy(p, at, 24);
  }
}

// Calls f(id, xyz) for every position of the store's column, in id order (read front to back).
template <class F>
void for_each_position(const WeightIndex& index, Progress& progress, F&& f) {
  const io::MappedFile column(index.positions_path);
  const uint64_t bytes = index.single_precision ? 12 : 24;
  if (column.size() != index.vertices * bytes) fail(Status::io_error, index.positions_path + ": size does not match");
  double p[3];
  for (uint64_t first = 0; first < index.vertices; first += kWindowRecords) {
    progress.check();
    const uint64_t n = std::min(kWindowRecords, index.vertices - first);
    const io::Window w = column.map(first * bytes, (first + n) * bytes);
    for (uint64_t i = 0; i < n; ++i) {
      if (index.single_precision) {
        float q[3];
        std::memcpy(q, w.data() + i * 12, 12);
        p[0] = q[0], p[1] = q[1], p[2] = q[2];
      } else {
        std::memcpy(p, w.data() + i * 24, 24);
      }
      f(first + i, p);
    }
  }
}

// Calls f(record, id) for every record of the weight index, in weight order.
template <class F>
void for_each_record(const WeightIndex& index, Progress& progress, F&& f) {
  if (std::filesystem::file_size(index.order_path) != index.records * 4)
    fail(Status::io_error, index.order_path + ": size does not match");
  for_column_blocks(index.order_path, index.records, 1, kWindowRecords, [&](uint64_t first, std::span<const uint32_t> ids) {
    progress.check();
    for (size_t i = 0; i < ids.size(); ++i) f(first + i, ids[i]);
  });
}

// A set of vertex ids with their positions: the k-th selected id's position is at slot k (its rank).
struct Selection {
  RankedBits ids;
  Positions xyz;
};

// The held records of a share: the records whose vertex is selected and their positions, in weight order
// (gathered once, so that every level and every try reads them front to back).
struct Held {
  std::vector<uint32_t> record;
  Positions xyz;
  uint64_t bytes() const { return record.capacity() * 4 + xyz.bytes(); }
};

// One thread's part of a total that several share (the levels clustered at once, under one budget): set()
// makes the part `now` and returns the total; the part is given back when the object goes, however.
class SharedPart {
 public:
  explicit SharedPart(std::atomic<uint64_t>& total) : total_(total) {}
  SharedPart(const SharedPart&) = delete;
  SharedPart& operator=(const SharedPart&) = delete;
  ~SharedPart() { total_.fetch_sub(part_); }
  uint64_t set(uint64_t now) {
    total_.fetch_add(now - part_);  // wraps correctly when the part shrinks
    part_ = now;
    return total_.load();
  }

 private:
  std::atomic<uint64_t>& total_;
  uint64_t part_ = 0;
};

// What a share holds past its budget: Failure(usage), naming what outgrew it.
void check_share_memory(const ClusterShareInput& in, const std::string& what, uint64_t bytes) {
  if (bytes <= in.memory_bytes) return;
  fail(Status::usage, fmt::format("cluster share: {} take {} MiB, more than --memory allows ({} MiB): raise --memory, or run "
                                  "more shares",
                                  what, bytes >> 20, in.memory_bytes >> 20));
}

// Pass 1 of a share: the vertices with lo <= p[axis] < hi, then their records.
// With the records' positions in weight order (a run that grades in shares, stream/position_gather.h): two
// passes over them, one counting the held records, one gathering them; record r's position is its vertex's,
// so the held records and positions are those of the passes by vertex below. On the 193 M-triangle city a
// slab's selection took 1.4 CPU-s this way where the passes by vertex took 5.3 (two reads of the store's
// column by vertex and two of the order), and it needs no copy of the selected positions beside the held ones.
void select_ordered(const ClusterShareInput& in, int axis, double lo, double hi, Progress& progress, Held& held) {
  const OrderedPositions positions(in.index.ordered_positions_path, in.index.single_precision, in.index.records);
  std::vector<double> xyz(3 * std::min(kBlockRecords, in.index.records));
  auto for_each_held = [&](auto&& f) {
    for (uint64_t first = 0; first < in.index.records; first += kBlockRecords) {
      progress.check();
      const uint64_t n = std::min(kBlockRecords, in.index.records - first);
      positions.read(first, n, xyz.data());
      for (uint64_t i = 0; i < n; ++i)
        if (lo <= xyz[3 * i + axis] && xyz[3 * i + axis] < hi) f(first + i, &xyz[3 * i]);
    }
  };
  uint64_t held_count = 0;
  for_each_held([&](uint64_t, const double*) { ++held_count; });
  held.record.reserve(held_count);
  (held.xyz.single ? held.xyz.f.reserve(3 * held_count) : held.xyz.d.reserve(3 * held_count));
  check_share_memory(in, "its held vertices", held.bytes() + xyz.size() * 8);
  for_each_held([&](uint64_t r, const double* p) {
    held.record.push_back(static_cast<uint32_t>(r));
    held.xyz.add(p);
  });
}

void select(const ClusterShareInput& in, int axis, double lo, double hi, Progress& progress, Held& held) {
  held.xyz.single = in.index.single_precision;
  if (!in.index.ordered_positions_path.empty()) return select_ordered(in, axis, lo, hi, progress, held);
  Selection sel{RankedBits(in.index.vertices), {}};
  sel.xyz.single = held.xyz.single = in.index.single_precision;
  // The ids first, then their positions into arrays of their exact size: grown by doubling, the positions
  // took up to twice their bytes, and three times while a growth copied them (one more read of the column
  // costs less than that headroom, which decided how many slabs fit a budget).
  for_each_position(in.index, progress, [&](uint64_t id, const double* p) {
    if (lo <= p[axis] && p[axis] < hi) sel.ids.set(id);
  });
  sel.ids.count();
  if (sel.xyz.single) sel.xyz.f.reserve(3 * sel.ids.ones());
  else sel.xyz.d.reserve(3 * sel.ids.ones());
  for_each_position(in.index, progress, [&](uint64_t id, const double* p) {
    if (sel.ids.has(id)) sel.xyz.add(p);
  });
  // The held arrays are sized first (a count pass over the index), so that they take no growth headroom.
  uint64_t held_count = 0;
  for_each_record(in.index, progress, [&](uint64_t, uint32_t id) {
    if (id >= in.index.vertices) fail(Status::io_error, in.index.order_path + ": vertex id out of range");
    held_count += sel.ids.has(id);
  });
  held.record.reserve(held_count);
  (held.xyz.single ? held.xyz.f.reserve(3 * held_count) : held.xyz.d.reserve(3 * held_count));
  check_share_memory(in, "its held vertices", sel.ids.bytes() + sel.xyz.bytes() + held.bytes());
  double p[3];
  for_each_record(in.index, progress, [&](uint64_t r, uint32_t id) {
    if (!sel.ids.has(id)) return;
    held.record.push_back(static_cast<uint32_t>(r));
    sel.xyz.get(sel.ids.rank(id), p);
    held.xyz.add(p);
  });
}

// Pass 2 of a share for one split level, with halo h: writes its .dec and .ctr files and returns true, or
// returns false (writing nothing) when one of the share's own records did not settle.
bool cluster_region(const ClusterShareInput& in, const ClusterShares& plan, unsigned share, size_t level, double h,
                    const Held& held, std::atomic<uint64_t>& clusterers, Progress& progress, uint64_t* held_in_box,
                    uint64_t* own) {
  const int axis = plan.axis;
  const double own_lo = plan.lo(share), own_hi = plan.hi(share);
  double box[6] = {-kInf, -kInf, -kInf, kInf, kInf, kInf};
  // A side past the scene's bounds holds everything on that side: infinite, so that nothing near it is
  // exposed (core/floating_cell_region.h), and the widest halo settles every decision.
  box[axis] = own_lo - h > in.bounds[axis] ? own_lo - h : -kInf;
  box[3 + axis] = own_hi + h <= in.bounds[3 + axis] ? own_hi + h : kInf;
  core::RegionClusterer rc(in.sizes[level], in.options, std::span<const double, 6>(box, 6));
  const bool centers = in.info == CellInfoKind::center;  // the merge reads the centers' positions for this kind only
  io::FileWriter dec(dec_path(in.prefix, share, level), 1 << 20), ctr;
  if (centers) ctr.open(ctr_path(in.prefix, share, level), 1 << 20);
  SharedPart part(clusterers);  // this level's part of `clusterers`
  *held_in_box = *own = 0;
  // The held records in the box go to the clusterer a block at a time (its pipeline fetches ahead within a
  // block), named by their records, so that a decision names its center's record.
  constexpr size_t kBlock = 4096;
  std::vector<uint32_t> tags;
  std::vector<double> xyz;
  std::vector<core::RegionDecision> decisions(kBlock);
  tags.reserve(kBlock);
  xyz.reserve(3 * kBlock);
  auto decide_block = [&] {  // false when one of the share's own records did not settle
    rc.assign_block(tags, xyz, std::span<core::RegionDecision>(decisions.data(), tags.size()));
    for (size_t i = 0; i < tags.size(); ++i) {
      const double* p = &xyz[3 * i];
      if (!(own_lo <= p[axis] && p[axis] < own_hi)) continue;
      const core::RegionDecision& d = decisions[i];
      if (d.status == core::RegionStatus::unsettled || !d.cell_settled) return false;  // the writers discard
      const uint32_t pair[2] = {tags[i], d.center};
      dec.write(pair, sizeof pair);
      if (centers && pair[0] == pair[1]) write_position(ctr, p, in.index.single_precision);
      ++*own;
    }
    tags.clear();
    xyz.clear();
    return true;
  };
  double p[3];
  for (size_t k = 0; k < held.record.size(); ++k) {
    if ((k & 0xfffff) == 0) {
      progress.check();
      const uint64_t total = part.set(rc.memory_bytes() + rc.growth_bytes());
      check_share_memory(in, fmt::format("level {}'s cells", level), held.bytes() + total);
    }
    held.xyz.get(k, p);
    if (!(box[axis] <= p[axis] && p[axis] < box[3 + axis])) continue;
    tags.push_back(held.record[k]);
    xyz.insert(xyz.end(), p, p + 3);
    ++*held_in_box;
    if (tags.size() == kBlock && !decide_block()) return false;
  }
  if (!decide_block()) return false;
  dec.commit();
  if (centers) ctr.commit();
  return true;
}

// Calls f(batch) for the records [lo, hi) of the weight index in weight order, a block of kBlockRecords
// records at a time (their ids and positions: stream/cluster_stage.h).
template <class F>
void for_each_record_batch(const ClusterShareInput& in, uint64_t lo, uint64_t hi, Progress& progress, F&& f) {
  const RecordPositions positions = record_positions(in.index, in.memory_bytes, in.chunk_cap);
  const io::MappedFile order(in.index.order_path);
  if (order.size() != in.index.records * 4) fail(Status::io_error, in.index.order_path + ": size does not match");
  RecordBatch batch;
  for (uint64_t first = lo; first < hi; first += kBlockRecords) {
    progress.check();
    batch.load(order, positions, first, std::min(kBlockRecords, hi - first));
    f(static_cast<const RecordBatch&>(batch));
  }
}

// A level split by records, its centers unit: one pass over every record in weight order
// (core::CenterPass), writing each center's record and position (store precision) to the level's .ctrs.
// Returns the stamp's files and value.
std::pair<std::vector<std::string>, nlohmann::ordered_json> find_centers(const ClusterShareInput& in, size_t level,
                                                                       Progress& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  // The covered voxels: a bitmap over the bounds of at most an eighth of the budget and 64 MiB (a bit a
  // voxel: the coarse levels' voxels of c/10 to c/31 on the 193 M-triangle city, 98.7-99.7 % of the records
  // skipped), else bricks in at most half the budget (the share's slab is not selected yet): on that
  // city's level 1 (847 K cells) the bricks took 144 MiB and skipped 91.7 %, where at 64 MiB they skipped 16 %.
  const uint64_t budget = in.memory_bytes ? in.memory_bytes : uint64_t{2} << 30;
  core::CenterPass pass(in.sizes[level], in.options, std::span<const double, 6>(in.bounds.data(), 6),
                        std::min<uint64_t>(uint64_t{64} << 20, budget / 8), budget / 2);
  const std::string path = cluster_centers_path(in.prefix, level);  // its directory: run_cluster_share's
  io::FileWriter out(path, 1 << 20);
  std::vector<uint8_t> is_center;
  for_each_record_batch(in, 0, in.index.records, progress, [&](const RecordBatch& b) {
    is_center.resize(b.ids.size());
    pass.visit_block(b.xyz, is_center);
    for (size_t i = 0; i < is_center.size(); ++i) {
      if (!is_center[i]) continue;
      const uint32_t r = static_cast<uint32_t>(b.at + i);
      out.write(&r, 4);
      write_position(out, &b.xyz[3 * i], in.index.single_precision);
    }
    check_share_memory(in, fmt::format("level {}'s covered voxels and cells", level), pass.memory_bytes());
  });
  out.commit();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return {{path},
          {{"level", level}, {"centers", pass.centers()}, {"skipped", pass.skipped()}, {"voxel", pass.voxel()},
           {"seconds", std::round(seconds * 1000) / 1000}, {"runner", unit_runner()}}};
}

// A level split by records, share `share`'s range [lo, hi): a Clusterer given first the centers before lo,
// then the range's records in weight order (core/floating_cell_centers.h: the whole pass's decisions);
// writes the range's .dec and .ctr as a slab's share does. It reads the centers file up to the first
// center at or past hi (no record of the range is in a later cell). Failure(io_error) when the centers
// file does not agree with the pass (a center that starts no cell, or a cell started by a record it does
// not list). `running`: what the levels clustered at once hold together (each adds its own; checked
// against the budget).
nlohmann::ordered_json cluster_records(const ClusterShareInput& in, const ClusterShares& plan, unsigned share, size_t level,
                                       uint64_t centers_count, std::atomic<uint64_t>& running, Progress& progress) {
  const uint64_t lo = plan.first_record(share, in.index.records), hi = plan.first_record(share + 1, in.index.records);
  const std::string path = cluster_centers_path(in.prefix, level);
  const size_t item = 4 + (in.index.single_precision ? 12 : 24);
  const io::MappedFile file(path);
  if (file.size() != centers_count * item) fail(Status::io_error, path + ": size does not match its stamp");
  SharedPart part(running);  // this level's part of `running`
  auto count = [&](uint64_t now, const char* what) {
    check_share_memory(in, fmt::format("level {}'s {}", level, what), part.set(now));
  };
  count(centers_count * 4, "centers");
  std::vector<uint32_t> center_record;  // cell id -> its center's record: the centers before hi
  core::Clusterer clusterer(std::span<const double>(&in.sizes[level], 1), in.options,
                            std::span<const double>(in.bounds.data(), in.bounds.size()));
  auto bad = [&](const std::string& what) { fail(Status::io_error, fmt::format("{}: {}", path, what)); };
  // The centers before the range, each starting its cell in order; then the range's, listed.
  const std::string unstarted = fmt::format("a center of level {} in records [{}, {}) starts no cell", level, lo, hi);
  std::vector<char> buffer;
  bool past = false;  // a center at or past hi was read
  for (uint64_t first = 0; first < centers_count && !past; first += kBlockRecords) {
    const uint64_t n = std::min(kBlockRecords, centers_count - first);
    buffer.resize(n * item);
    file.read(first * item, n * item, buffer.data());
    for (uint64_t i = 0; i < n; ++i) {
      const char* c = buffer.data() + i * item;
      uint32_t r;
      std::memcpy(&r, c, 4);
      if (!center_record.empty() && r <= center_record.back()) bad("centers out of order");
      if (r >= hi) {
        if (hi == in.index.records) bad(unstarted);  // past the last record
        past = true;
        break;
      }
      center_record.push_back(r);
      if (r >= lo) continue;
      double p[3];
      read_position(c + 4, in.index.single_precision, p);
      uint32_t cell = 0;
      clusterer.assign(r, std::span<const double, 3>(p, 3), std::span<uint32_t>(&cell, 1));
      if (cell != center_record.size() - 1) bad(fmt::format("center {} of level {} starts no cell", first + i, level));
    }
  }
  const uint64_t before = static_cast<uint64_t>(std::lower_bound(center_record.begin(), center_record.end(), lo) - center_record.begin());
  const bool centers = in.info == CellInfoKind::center;
  io::FileWriter dec(dec_path(in.prefix, share, level), 1 << 20), ctr;
  if (centers) ctr.open(ctr_path(in.prefix, share, level), 1 << 20);
  std::vector<uint32_t> cells;
  uint64_t next = before;  // the next cell's id
  for_each_record_batch(in, lo, hi, progress, [&](const RecordBatch& b) {
    cells.resize(b.ids.size());
    clusterer.assign_block(b.ids, b.xyz, cells);
    for (size_t i = 0; i < cells.size(); ++i) {
      const uint32_t r = static_cast<uint32_t>(b.at + i);
      if (cells[i] == next) {  // r starts a cell: the centers pass must have found it
        if (next >= center_record.size() || center_record[next] != r) bad(fmt::format("record {} of level {} is not listed as a center", r, level));
        ++next;
        if (centers) write_position(ctr, &b.xyz[3 * i], in.index.single_precision);
      }
      const uint32_t pair[2] = {r, center_record[cells[i]]};
      dec.write(pair, sizeof pair);
    }
    count(clusterer.memory_bytes() + clusterer.growth_bytes() + centers_count * 4, "cells");
  });
  if (next != center_record.size()) bad(unstarted);
  dec.commit();
  if (centers) ctr.commit();
  return {{"level", level}, {"first_record", lo}, {"own", hi - lo}, {"own_centers", next - before}, {"centers_before", before}};
}

}  // namespace

double ClusterShares::lo(unsigned s) const { return s == 0 ? -kInf : cuts[s - 1]; }
double ClusterShares::hi(unsigned s) const { return s + 1 >= count ? kInf : cuts[s]; }

nlohmann::ordered_json ClusterShares::json() const {
  std::vector<std::string> c;
  for (double x : cuts) c.push_back(fmt::format("{:a}", x));
  std::vector<int> records;
  for (char b : by_records) records.push_back(b);
  return {{"count", count}, {"axis", axis}, {"cuts", c}, {"whole_share", whole_share}, {"by_records", records}};
}

uint64_t ClusterShares::first_record(unsigned s, uint64_t records) const {
  return records * s / count;  // records < 2^32 (record ids are 32-bit) and s <= count < 2^32: no overflow
}

std::string cluster_centers_dir(const std::string& prefix) { return cluster_shares_dir(prefix) + "centers"; }
std::string cluster_centers_path(const std::string& prefix, size_t level) {
  return cluster_centers_dir(prefix) + fmt::format("/level-{}.ctrs", level);
}
std::string cluster_centers_stamp(const std::string& prefix, size_t level) {
  return cluster_centers_dir(prefix) + fmt::format("/level-{}.json", level);
}

std::string cluster_shares_dir(const std::string& prefix) { return prefix + "cluster-shares/"; }
std::string cluster_share_decisions_path(const std::string& prefix, unsigned share, size_t level) {
  return cluster_shares_dir(prefix) + fmt::format("share-{}-level-{}.dec", share, level);
}
std::string cluster_share_centers_path(const std::string& prefix, unsigned share, size_t level) {
  return cluster_shares_dir(prefix) + fmt::format("share-{}-level-{}.ctr", share, level);
}
std::string cluster_share_stamp(const std::string& prefix, unsigned index) {
  return cluster_shares_dir(prefix) + fmt::format("share-{}.json", index);
}

nlohmann::ordered_json cluster_centers_figures(const ClusterShareInput& in, const ClusterShares& plan) {
  nlohmann::ordered_json out = nlohmann::ordered_json::array();
  for (size_t l = 0; l < plan.by_records.size(); ++l) {
    if (!plan.by_records[l]) continue;
    try {
      out.push_back(nlohmann::ordered_json::parse(io::read_small_file(cluster_centers_stamp(in.prefix, l))).at("value"));
    } catch (const std::exception&) {
      // not stamped (a share that reused the stage): no figures
    }
  }
  return out;
}

ClusterShares plan_cluster_shares(const ClusterShareInput& in, unsigned count, Progress& progress) {
  ClusterShares plan;
  plan.count = count;
  const size_t levels = in.sizes.size();
  plan.whole_share.assign(levels, -1);
  plan.by_records.assign(levels, 0);
  // Floating cells over bounds, in shares: a level may split, by slabs (can_split: the bounds have an
  // extent across their longest axis) or, too coarse for the slabs, by ranges of records.
  const bool shared = count >= 2 && in.bounds.size() == 6 && in.options.clustering == core::Clustering::floating;
  const bool records_split = shared && in.split_by_records;
  const auto has_fine = [&](size_t l) { return in.fine && in.fine->sizes.at(l) > 0; };
  bool can_split = shared;
  if (can_split) {
    for (int a = 1; a < 3; ++a)
      if (in.bounds[3 + a] - in.bounds[a] > in.bounds[3 + plan.axis] - in.bounds[plan.axis]) plan.axis = a;
    can_split = in.bounds[3 + plan.axis] > in.bounds[plan.axis];
  }
  // The slabs: `slabs` parts of equal vertex counts across the axis, as count - 1 cuts; with fewer slabs than
  // shares, the whole levels' shares (1 to count - slabs) get empty slabs [c, c) (repeated cuts) and cluster
  // their whole levels only: on the 193 M-triangle city at 8 shares a slab of the split levels had added 13 s
  // to a whole levels' share's 46 s, where the other shares took 12-15 s, so the array ended on it.
  std::vector<uint64_t> hist;
  double lo = 0, hi = 0;
  // The histogram's bin of a coordinate on the axis (the ends' bins hold what lies past them).
  const auto bin_of = [&](double x) { return static_cast<size_t>(std::clamp((x - lo) / (hi - lo) * kBins, 0.0, kBins - 1.0)); };
  if (can_split) {
    lo = in.bounds[plan.axis], hi = in.bounds[3 + plan.axis];
    hist.assign(kBins, 0);
    for_each_position(in.index, progress, [&](uint64_t, const double* p) { ++hist[bin_of(p[plan.axis])]; });
  }
  // Cuts for `slabs` slabs (at least 2 when slabs < count), the empty ones after share 0's; and the narrowest
  // non-empty slab's width.
  auto cut = [&](unsigned slabs, double* min_width) {
    std::vector<double> cuts;
    uint64_t seen = 0;
    int bin = 0;
    for (unsigned k = 1; k < slabs; ++k) {
      const uint64_t want = (in.index.vertices * k + slabs - 1) / slabs;
      while (bin < kBins && seen + hist[static_cast<size_t>(bin)] < want) seen += hist[static_cast<size_t>(bin++)];
      // The edge after the bin that reaches the k-th part.
      cuts.push_back(lo + (hi - lo) * (std::min(bin + 1, kBins)) / kBins);
    }
    for (size_t k = 1; k < cuts.size(); ++k) cuts[k] = std::max(cuts[k], cuts[k - 1]);
    if (slabs < count) cuts.insert(cuts.begin() + 1, count - slabs, cuts.front());
    ClusterShares p;
    p.count = count, p.cuts = cuts;
    *min_width = kInf;
    for (unsigned s = 0; s < count; ++s)
      if (s == 0 || s > count - slabs) *min_width = std::min(*min_width, std::min(p.hi(s), hi) - std::max(p.lo(s), lo));
    return cuts;
  };
  // The levels too coarse to split at slabs of min_width (all of them when nothing splits).
  // (Those split by records are not whole.)
  auto by_slabs = [&](size_t l, double min_width) { return can_split && !has_fine(l) && in.sizes[l] * kSplitCells <= min_width; };
  auto by_records = [&](size_t l, double min_width) { return records_split && !has_fine(l) && !by_slabs(l, min_width); };
  auto whole_levels = [&](double min_width) {
    std::vector<size_t> w;
    for (size_t l = 0; l < levels; ++l)
      if (!by_slabs(l, min_width) && !by_records(l, min_width)) w.push_back(l);
    return w;
  };
  // The levels split by records, once the slabs are cut.
  auto mark_by_records = [&](double min_width) {
    for (size_t l = 0; l < levels; ++l) plan.by_records[l] = by_records(l, min_width);
  };
  // The whole levels to `shares` shares from share `first` on, in level order, as even runs: a share's levels
  // run in one cluster_levels pass over the index, whose cost is mostly fetching every position by id (the
  // column read once per batch), shared by its levels; a level in a share of its own costs that fetch again,
  // but the shares run at once (193 M-triangle city, 8 shares at --memory 1G: levels 2-4 in one share
  // 44.6 s).
  auto assign = [&](const std::vector<size_t>& whole, unsigned first, unsigned shares) {
    plan.whole_share.assign(levels, -1);
    for (size_t j = 0; j < whole.size(); ++j)
      plan.whole_share[whole[j]] = static_cast<int>(first + j * shares / whole.size());
  };
  // Whether every slab's share would hold its selection under the budget, estimated from the histogram as
  // select() counts it: the vertices within the widest first halo of the split levels, their positions by
  // id and their records and positions in weight order (each array of its exact size), and the bit and a
  // half per store vertex. Fewer slabs hold more each: the 193 M-triangle city at 1 GiB a share held up to
  // 1.2 GiB in 5 slabs while the selection's positions grew by doubling (counted then at 3 positions and a
  // record a vertex), where 7 peaked at 735 MiB.
  auto slabs_fit = [&](const std::vector<size_t>& whole, double min_width) {
    if (in.memory_bytes == 0) return true;
    double widest = 0;
    for (size_t l = 0; l < levels; ++l)
      if (by_slabs(l, min_width)) widest = std::max(widest, in.first_halo_cells * in.sizes[l]);
    const uint64_t position = in.index.single_precision ? 12 : 24;
    for (unsigned s = 0; s < count; ++s) {
      if (!(plan.lo(s) < plan.hi(s))) continue;
      uint64_t n = 0;  // the vertices of the bins the slab and its halo meet
      for (size_t k = bin_of(plan.lo(s) - widest), end = bin_of(plan.hi(s) + widest); k <= end; ++k) n += hist[k];
      if (in.index.vertices * 3 / 16 + n * (2 * position + 4) > in.memory_bytes) return false;
    }
    return true;
  };
  double min_width = 0;
  if (!can_split) {
    plan.cuts.assign(count ? count - 1 : 0, 0.0);
    assign(whole_levels(0), std::min(1u, count - 1), 1);
    mark_by_records(0);
    return plan;
  }
  // With N >= 3 and whole levels, the whole levels go to shares 1 to K of their own (no slab), K as many as
  // there are whole levels while at least two slabs remain: fewer slabs are wider, so fewer levels may be
  // whole, and hold more, so K steps down until every one of the K shares has a level and every slab's
  // selection fits the budget (slabs_fit; at K = 1, as before, a share over it stops with exit 64).
  // Shares 1 to K are the first that a scheduler starts after share 0 (which runs the stages before the
  // clustering under the lock while the others wait for it), so the longest shares do not run alone at
  // the end.
  if (count >= 3) {
    plan.cuts = cut(count - 1, &min_width);
    const size_t most = whole_levels(min_width).size();  // the most levels any K leaves whole (the most slabs)
    for (unsigned k = static_cast<unsigned>(std::min<size_t>(most, count - 2)); k >= 1; --k) {
      plan.cuts = cut(count - k, &min_width);
      const std::vector<size_t> whole = whole_levels(min_width);
      if (whole.size() >= k && (k == 1 || slabs_fit(whole, min_width))) {
        assign(whole, 1, k);
        mark_by_records(min_width);
        return plan;
      }
    }
  }
  plan.cuts = cut(count, &min_width);
  assign(whole_levels(min_width), std::min(1u, count - 1), 1);
  mark_by_records(min_width);
  return plan;
}

ClusterShares shared_cluster_plan(const ClusterShareInput& in, unsigned count, const nlohmann::ordered_json& key,
                                  Progress& progress) {
  const std::string path = cluster_shares_dir(in.prefix) + "plan.json";
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) {
    try {
      const nlohmann::ordered_json j = nlohmann::ordered_json::parse(io::read_small_file(path));
      const nlohmann::ordered_json& p = j.at("plan");
      if (j.at("key") == key && p.at("count") == count && p.at("whole_share").size() == in.sizes.size()) {
        ClusterShares plan;
        plan.count = count;
        plan.axis = p.at("axis");
        for (const auto& c : p.at("cuts")) plan.cuts.push_back(std::strtod(c.get<std::string>().c_str(), nullptr));  // hex: exact
        plan.whole_share = p.at("whole_share").get<std::vector<int>>();
        for (int b : p.at("by_records").get<std::vector<int>>()) plan.by_records.push_back(static_cast<char>(b));
        if (plan.by_records.size() != plan.whole_share.size()) throw std::runtime_error("by_records");
        if (plan.cuts.size() + 1 == count) return plan;
      }
    } catch (const std::exception&) {
      // unreadable: made again below
    }
  }
  const ClusterShares plan = plan_cluster_shares(in, count, progress);
  std::filesystem::create_directories(cluster_shares_dir(in.prefix));
  io::write_file_atomic(path, nlohmann::ordered_json{{"key", key}, {"plan", plan.json()}}.dump(1) + "\n");
  return plan;
}

std::vector<std::string> cluster_share_files(const ClusterShareInput& in, const ClusterShares& plan, unsigned index) {
  std::vector<std::string> files;
  for (size_t l = 0; l < plan.whole_share.size(); ++l) {
    if (plan.whole_share[l] < 0) {
      files.push_back(dec_path(in.prefix, index, l));
      if (in.info == CellInfoKind::center) files.push_back(ctr_path(in.prefix, index, l));
    } else if (plan.whole_share[l] == static_cast<int>(index)) {
      files.push_back(whole_map_path(in.prefix, l)), files.push_back(whole_info_path(in.prefix, l));
      if (in.vertex_cells) files.push_back(whole_vertex_cells_path(in.prefix, l));
    }
  }
  return files;
}

nlohmann::ordered_json run_cluster_share(const ClusterShareInput& in, const ClusterShares& plan, unsigned index,
                                         Progress& progress) {
  std::filesystem::create_directories(cluster_shares_dir(in.prefix));
  nlohmann::ordered_json figures = nlohmann::ordered_json::array();
  // The whole levels: cluster_levels over them alone, its files renamed to the level's.
  std::vector<size_t> whole;
  std::vector<double> whole_sizes;
  FineCells whole_fine;
  for (size_t l = 0; l < plan.whole_share.size(); ++l)
    if (plan.whole_share[l] == static_cast<int>(index)) {
      whole.push_back(l);
      whole_sizes.push_back(in.sizes[l]);
      if (in.fine) whole_fine.sizes.push_back(in.fine->sizes.at(l)), whole_fine.near.push_back(in.fine->near.at(l));
    }
  if (!whole.empty()) {
    if (in.fine) whole_fine.labels_path = in.fine->labels_path;
    const std::string stem = cluster_shares_dir(in.prefix) + fmt::format("share-{}-whole-", index);
    const ClusterSummary cs = cluster_levels(in.index, in.bounds, whole_sizes, in.options, in.info, in.memory_bytes, *in.work,
                                             progress, stem, in.fine ? &whole_fine : nullptr, in.chunk_cap);
    for (size_t j = 0; j < whole.size(); ++j) {
      std::filesystem::rename(cells_path(stem, j), whole_map_path(in.prefix, whole[j]));
      std::filesystem::rename(cell_info_path(stem, j), whole_info_path(in.prefix, whole[j]));
      figures.push_back({{"level", whole[j]}, {"cells", cs.cells[j]}});
    }
    // Their cells by vertex, which the prepare job would otherwise decode level by level after the merge.
    if (in.vertex_cells)
      for (size_t j = 0; j < whole.size(); ++j)
        write_vertex_cells_of(whole_map_path(in.prefix, whole[j]), in.index.order_path, in.canonical_path,
                              whole_vertex_cells_path(in.prefix, whole[j]), in.index.vertices, in.index.records, cs.cells[j],
                              in.memory_bytes, progress);
  }
  // The levels split by records: their centers units no other share holds, before the slab.
  std::vector<size_t> by_records;
  for (size_t l = 0; l < plan.by_records.size(); ++l)
    if (plan.by_records[l]) by_records.push_back(l);
  const std::string centers_dir = cluster_centers_dir(in.prefix);
  const nlohmann::ordered_json centers_key = in.key.is_null() ? plan.json() : in.key;
  auto centers_unit = [&](size_t j, bool wait) {
    const size_t l = by_records[j];
    return share_unless_held(centers_dir, static_cast<unsigned>(l), cluster_centers_stamp(in.prefix, l), centers_key, "", wait,
                             [&] { return find_centers(in, l, progress); });
  };
  if (!by_records.empty()) std::filesystem::create_directories(centers_dir);
  for (size_t k = 0; k < by_records.size(); ++k) centers_unit((index + k) % by_records.size(), false);
  // Then, once its slab is done, every centers unit (waiting for those others hold) and its range of records.
  auto decide_records = [&] {
    std::vector<uint64_t> centers(by_records.size());
    for (size_t j = 0; j < by_records.size(); ++j) centers[j] = centers_unit(j, true)->at("centers").get<uint64_t>();
    std::vector<nlohmann::ordered_json> f(by_records.size());
    std::atomic<uint64_t> running{0};  // the levels' clusterers and centers, together under the budget
    tbb::parallel_for(size_t{0}, by_records.size(),
                      [&](size_t j) { f[j] = cluster_records(in, plan, index, by_records[j], centers[j], running, progress); });
    for (auto& x : f) figures.push_back(std::move(x));
  };
  // The split levels: select with the widest halo any of them needs, cluster each, widen the ones that did
  // not settle, select again when a halo outgrows the selection.
  std::vector<size_t> split;
  std::vector<double> halo;
  std::vector<unsigned> tries;
  for (size_t l = 0; l < plan.whole_share.size(); ++l)
    if (plan.whole_share[l] < 0 && !plan.by_records[l])
      split.push_back(l), halo.push_back(in.first_halo_cells * in.sizes[l]), tries.push_back(0);
  if (!(plan.lo(index) < plan.hi(index))) {
    // An empty slab (the whole levels' share, plan_cluster_shares): no record of a split level is its own,
    // and its decision files are empty.
    for (size_t l : split) {
      io::FileWriter dec(dec_path(in.prefix, index, l), 1 << 12);
      dec.commit();
      if (in.info == CellInfoKind::center) {
        io::FileWriter ctr(ctr_path(in.prefix, index, l), 1 << 12);
        ctr.commit();
      }
      figures.push_back({{"level", l}, {"halo_cells", 0}, {"tries", 0}, {"held", 0}, {"own", 0}});
    }
    decide_records();
    return figures;
  }
  Held held;
  std::atomic<uint64_t> clusterers{0};  // the running levels' RegionClusterers, with their growth headroom
  double selected = -1;  // the halo of the selection
  std::vector<char> done(split.size(), 0);
  std::vector<nlohmann::ordered_json> split_figures(split.size());
  for (;;) {
    double widest = 0;
    for (size_t j = 0; j < split.size(); ++j)
      if (!done[j]) widest = std::max(widest, halo[j]);
    if (widest == 0) break;
    if (widest > selected) {
      selected = widest;
      for (size_t j = 0; j < split.size(); ++j)  // select once for every level still to do
        if (!done[j]) selected = std::max(selected, halo[j]);
      held = Held();
      select(in, plan.axis, plan.lo(index) - selected, plan.hi(index) + selected, progress, held);
    }
    // The levels are independent: one task each.
    std::vector<uint64_t> in_box(split.size()), own(split.size());
    std::vector<char> settled(split.size(), 0);
    tbb::parallel_for(size_t{0}, split.size(), [&](size_t j) {
      if (!done[j]) settled[j] = cluster_region(in, plan, index, split[j], halo[j], held, clusterers, progress, &in_box[j], &own[j]);
    });
    for (size_t j = 0; j < split.size(); ++j) {
      if (done[j]) continue;
      ++tries[j];
      if (settled[j]) {
        done[j] = true;
        split_figures[j] = {{"level", split[j]}, {"halo_cells", halo[j] / in.sizes[split[j]]}, {"tries", tries[j]},
                            {"held", in_box[j]}, {"own", own[j]}};
      } else {
        halo[j] *= 2;
      }
    }
  }
  for (auto& f : split_figures) figures.push_back(std::move(f));
  held = Held();
  decide_records();
  return figures;
}

ClusterSummary merge_cluster_shares(const ClusterShareInput& in, const ClusterShares& plan,
                                    const std::vector<nlohmann::ordered_json>& figures, Progress& progress) {
  // Alone in this process: units of an earlier call are not this one's.
  std::filesystem::remove_all(cluster_merge_dir(in.prefix));
  const nlohmann::ordered_json key{{"plan", plan.json()}, {"figures", figures}};
  const std::vector<uint64_t> split_cells = merge_split_levels(in, plan, key, 0, progress).cells;
  ClusterSummary summary = merge_cluster_shares(in, plan, figures, split_cells, progress);
  std::filesystem::remove_all(cluster_merge_dir(in.prefix));
  return summary;
}

ClusterSummary merge_cluster_shares(const ClusterShareInput& in, const ClusterShares& plan,
                                    const std::vector<nlohmann::ordered_json>& figures, const std::vector<uint64_t>& split_cells,
                                    Progress& progress) {
  ClusterSummary summary;
  const size_t levels = plan.whole_share.size();
  summary.cells.assign(levels, 0);
  for (size_t l = 0; l < levels; ++l)
    if (plan.whole_share[l] < 0) summary.cells[l] = split_cells.at(l);
  progress.report("cluster", 0.9);
  if (in.vertex_cells) summary.vertex_cells.assign(levels, 0);
  for (size_t l = 0; l < levels; ++l) {
    if (plan.whole_share[l] < 0) continue;
    link_file(whole_map_path(in.prefix, l), cells_path(in.prefix, l));
    link_file(whole_info_path(in.prefix, l), cell_info_path(in.prefix, l));
    if (in.vertex_cells) {
      link_file(whole_vertex_cells_path(in.prefix, l), vertex_cells_path(in.prefix, l));
      summary.vertex_cells[l] = 1;
    }
    bool found = false;
    for (const auto& f : figures.at(static_cast<size_t>(plan.whole_share[l])))
      if (f.at("level") == l) summary.cells[l] = f.at("cells"), found = true;
    if (!found) fail(Status::io_error, cluster_share_stamp(in.prefix, static_cast<unsigned>(plan.whole_share[l])) + ": level " +
                                           std::to_string(l) + " is missing");
  }
  progress.report("cluster", 1);
  return summary;
}

}  // namespace lodstream::stream
