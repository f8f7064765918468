// The clustering shares' merge as units. This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.2
// See cluster_merge.h for the phases and the invariant.
#include "stream/cluster_merge.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <queue>
#include <span>

#include <fmt/format.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "stream/cell_map_file.h"
#include "stream/cluster_stage.h"
#include "stream/position_gather.h"
#include "stream/ranked_bits.h"
#include "stream/units.h"
#include "stream/vertex_pairs.h"

namespace lodstream::stream {

namespace {

constexpr uint64_t kReadBuffer = uint64_t{1} << 20;  // bytes of a share's file read at a time
constexpr uint64_t kInfoFlush = uint64_t{1} << 16;   // centers' positions a map unit writes at a time
constexpr uint64_t kPairsRead = uint64_t{1} << 19;  // records a pairs unit reads at a time (their ids and cells: 4 MiB)

using json = nlohmann::ordered_json;

// Reads a file of fixed-size items front to back, from item `first` to item `last` (or the file's end), a
// buffer of whole items at a time (pread: a mapped window costs a page fault a page, which on the 193 M-
// triangle city's 1.6 GB of decisions was a tenth of the map units' time). Nothing past `last` is read: the
// map units free their items as they finish (Merge::free_unit_share_bytes), and a hole reads as zeros.
class ItemReader {
 public:
  ItemReader(const std::string& path, size_t item, uint64_t first = 0, uint64_t last = UINT64_MAX)
      : file_(path), item_(item), at_(first * item), end_(at_), limit_(std::min<uint64_t>(file_.size(), last == UINT64_MAX ? last : last * item)) {
    if (file_.size() % item || at_ > limit_) fail(Status::io_error, path + ": cut short");
  }
  // The next item, or null after the last.
  const char* next() {
    if (at_ == end_) {
      if (at_ >= limit_) return nullptr;
      const uint64_t n = std::min<uint64_t>(limit_ - at_, kReadBuffer / item_ * item_);
      buffer_.resize(n);
      file_.read(at_, n, buffer_.data());
      end_ = at_ + n;
    }
    const char* p = buffer_.data() + (at_ - (end_ - buffer_.size()));
    at_ += item_;
    return p;
  }

 private:
  io::MappedFile file_;
  size_t item_;
  std::vector<char> buffer_;
  uint64_t at_, end_, limit_;
};

// The records [lo(u), hi(u)) of unit u: whole 64-record words (the last unit's end aside).
struct Units {
  uint64_t records = 0, words = 0;
  unsigned count = 0;
  uint64_t lo(unsigned u) const { return std::min(records, words * u / count * 64); }
  uint64_t hi(unsigned u) const { return std::min(records, words * (u + 1) / count * 64); }
};

// The index of share s's first decision of split level `level` at or after record `lo` (each share's file
// is in record order: a binary search). Phase 1 only: phase 2 takes it from phase 1's stamps, since the
// decisions of the units done are freed meanwhile (their holes read as zeros).
uint64_t decision_index(const ClusterShareInput& in, unsigned s, size_t level, uint64_t lo) {
  if (lo == 0) return 0;
  const std::string path = cluster_share_decisions_path(in.prefix, s, level);
  const io::OffsetFile file(path, O_RDONLY);
  return file.partition_point<std::array<uint32_t, 2>>(std::filesystem::file_size(path) / 8,
                                                       [&](const std::array<uint32_t, 2>& d) { return d[0] < lo; });
}
std::unique_ptr<ItemReader> decisions_from(const ClusterShareInput& in, unsigned s, size_t level, uint64_t index,
                                           uint64_t last = UINT64_MAX) {
  return std::make_unique<ItemReader>(cluster_share_decisions_path(in.prefix, s, level), 8, index, last);
}

// Frees bytes [from, to) of the file at `path` (their blocks: a hole reads as zeros), where the file system
// can (fallocate's PUNCH_HOLE; else nothing: the bytes stay until the file is emptied).
void free_bytes(const std::string& path, uint64_t from, uint64_t to) {
  if (to <= from) return;
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fallocate(fd, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, static_cast<off_t>(from), static_cast<off_t>(to - from));
  ::close(fd);
}

// Calls f(record, its center, share) for every record of [lo, hi) of split level `level`, in record order,
// from the shares' decision files merged by record, share s's decisions [first[s], last[s]) (last: UINT64_MAX
// for the file's end). Failure(io_error) when a record is decided twice, by no
// share or past the index's records, or a decision names a later record as its center.
// ahead(center) is called kDecisionsAhead decisions before f is called with that center, so that a caller
// who looks the center up at random (its rank among the centers) can fetch it meanwhile.
constexpr size_t kDecisionsAhead = 16;
template <class Ahead, class F>
void for_each_decision(const ClusterShareInput& in, const ClusterShares& plan, size_t level, uint64_t lo, uint64_t hi,
                       std::span<const uint64_t> first, std::span<const uint64_t> last, Progress& progress, Ahead&& ahead,
                       F&& f) {
  struct Decision {
    uint64_t record;
    uint32_t center;
    unsigned share;
  };
  Decision ring[kDecisionsAhead];
  uint64_t queued = 0;  // decisions given to ahead; f has had all but the last min(queued, kDecisionsAhead)
  auto decided = [&](uint64_t r, uint32_t center, unsigned s) {
    ahead(center);
    Decision& slot = ring[queued % kDecisionsAhead];
    if (queued >= kDecisionsAhead) f(slot.record, slot.center, slot.share);
    slot = {r, center, s};
    ++queued;
  };
  const uint64_t records = in.index.records;
  std::vector<std::unique_ptr<ItemReader>> decs;
  using Head = std::pair<uint32_t, unsigned>;  // (record, share)
  std::priority_queue<Head, std::vector<Head>, std::greater<Head>> heads;
  std::vector<uint32_t> pending(plan.count);  // each share's next record's center
  // The head of the share just read stays out of the heap while it comes first: a level split by records
  // (cluster_shares.h) gives one run of consecutive records a share, where a push and a pop a record were
  // the merge's own cost. The order is the heap's (record, then share).
  std::optional<Head> held;
  auto advance = [&](unsigned s) {
    if (const char* p = decs[s]->next()) {
      uint32_t pair[2];
      std::memcpy(pair, p, 8);
      if (pair[1] > pair[0]) fail(Status::io_error, cluster_share_decisions_path(in.prefix, s, level) + ": not a share's decisions");
      if (pair[0] >= hi && hi < records) return;  // the next unit's
      pending[s] = pair[1];
      held = Head{pair[0], s};
    }
  };
  for (unsigned s = 0; s < plan.count; ++s) {
    decs.push_back(decisions_from(in, s, level, first[s], last[s]));
    advance(s);
    if (held) heads.push(*held), held.reset();
  }
  auto missing = [&](uint64_t r, const char* how) {
    fail(Status::io_error, fmt::format("{}: record {} of level {} is decided {}", cluster_shares_dir(in.prefix), r, level, how));
  };
  for (uint64_t r = lo; r < hi; ++r) {
    if ((r & 0xfffff) == 0) progress.check();
    Head head;
    if (held && (heads.empty() || *held < heads.top())) {
      head = *held;
    } else {
      if (held) heads.push(*held);
      if (heads.empty()) missing(r, "by no share");
      head = heads.top();
      heads.pop();
    }
    held.reset();
    const auto [record, s] = head;
    if (record != r) missing(r, record < r ? "twice" : "by no share");
    decided(r, pending[s], s);
    advance(s);
  }
  if (held) heads.push(*held), held.reset();
  if (!heads.empty()) missing(heads.top().first, heads.top().first < hi ? "twice" : "past the weight index's records");
  for (uint64_t k = queued > kDecisionsAhead ? queued - kDecisionsAhead : 0; k < queued; ++k) {
    const Decision& d = ring[k % kDecisionsAhead];
    f(d.record, d.center, d.share);
  }
}

// The bits of a cell map before record `end`: record i's cell takes bit_width(rank(i)) bits, rank(i) the
// centers before it (cell_map_file.h). A word whose ranks keep one width counts 64 of it at once.
uint64_t map_bits_before(const RankedBits& centers, uint64_t end) {
  uint64_t total = 0;
  const uint64_t whole = end / 64;
  for (uint64_t w = 0; w < whole; ++w) {
    const uint64_t first = centers.before[w], last = first + static_cast<uint64_t>(std::popcount(centers.bits[w] & (~uint64_t{0} >> 1)));
    const unsigned width = static_cast<unsigned>(std::bit_width(first));
    if (width == std::bit_width(last)) {
      total += 64 * width;
    } else {
      for (uint64_t i = 64 * w; i < 64 * w + 64; ++i) total += static_cast<unsigned>(std::bit_width(centers.rank(i)));
    }
  }
  for (uint64_t i = 64 * whole; i < end; ++i) total += static_cast<unsigned>(std::bit_width(centers.rank(i)));
  return total;
}

std::string spent_path(const std::string& prefix) { return cluster_shares_dir(prefix) + "spent.json"; }

std::vector<size_t> split_levels(const ClusterShares& plan) {
  std::vector<size_t> split;
  for (size_t l = 0; l < plan.whole_share.size(); ++l)
    if (plan.whole_share[l] < 0) split.push_back(l);
  return split;
}

unsigned merge_unit_count(const ClusterShareInput& in, const ClusterShares& plan) {
  const uint64_t words = (in.index.records + 63) / 64;
  const uint64_t asked = in.merge_units ? in.merge_units : std::min<uint64_t>(plan.count, kMaxClusterMergeUnits);
  return static_cast<unsigned>(std::clamp<uint64_t>(asked, 1, std::max<uint64_t>(words, 1)));
}

// The key every unit's stamp holds. map_entries, vertex_pairs: the sums and pairs units enter the maps at
// their first records (no plain cells; a map unit's stamp holds where its records begin in each map, for
// the pairs unit of the same records), and a phase of their own after the sums writes the pairs, packed (a
// set of units started by an older build wrote plain cells, or pairs of the older layout, or none).
json merge_unit_key(const ClusterShareInput& in, const ClusterShares& plan, const json& key) {
  return {{"key", key}, {"split", split_levels(plan)}, {"units", merge_unit_count(in, plan)}, {"records", in.index.records},
          {"map_entries", "in the map units' stamps"}, {"vertex_pairs", "after the sums, packed"},
          {"decisions", "freed by the map units"}};
}

struct Merge {
  const ClusterShareInput& in;
  const ClusterShares& plan;
  std::vector<size_t> split;  // the split levels
  Units units;
  std::string dir, bits_path;
  uint64_t center_bytes() const { return in.index.single_precision ? 12 : 24; }
  bool centers_info() const { return in.info == CellInfoKind::center; }

  // Split level j's center bits, from the centers units' file.
  RankedBits load_centers(size_t j) const {
    RankedBits c(in.index.records);
    io::OffsetFile(bits_path, O_RDONLY).read(c.bits.data(), c.bits.size() * 8, j * units.words * 8);
    c.count();
    return c;
  }

  // Phase 1, unit u: its records' center bits, each split level's, in place; returns its centers per level
  // and share. Each share's decisions of the unit are read in turn, unmerged: phase 2 merges them and checks
  // that they decide each record once (a record decided twice or by no share sets no wrong bit that it
  // would not find).
  json centers_unit(unsigned u, Progress& progress) const {
    const uint64_t lo = units.lo(u), hi = units.hi(u);
    const io::OffsetFile bits(bits_path, O_WRONLY);
    json centers = json::array(), share_centers = json::array(), first_decisions = json::array();
    for (size_t j = 0; j < split.size(); ++j) {
      std::vector<uint64_t> words((hi - lo + 63) / 64, 0);
      std::vector<uint64_t> per_share(plan.count, 0), first(plan.count, 0);
      uint64_t n = 0;
      for (unsigned s = 0; s < plan.count; ++s) {
        first[s] = decision_index(in, s, split[j], lo);
        const std::unique_ptr<ItemReader> dec = decisions_from(in, s, split[j], first[s]);
        uint64_t seen = 0;
        while (const char* p = dec->next()) {
          uint32_t pair[2];
          std::memcpy(pair, p, 8);
          if (pair[0] >= hi) break;
          if (pair[1] > pair[0])
            fail(Status::io_error, cluster_share_decisions_path(in.prefix, s, split[j]) + ": not a share's decisions");
          if ((++seen & 0xfffff) == 0) progress.check();
          if (pair[1] != pair[0]) continue;
          uint64_t& w = words[(pair[0] - lo) >> 6];
          const uint64_t bit = uint64_t{1} << ((pair[0] - lo) & 63);
          if (!(w & bit)) w |= bit, ++per_share[s], ++n;
        }
      }
      bits.write(words.data(), words.size() * 8, (j * units.words + lo / 64) * 8);
      centers.push_back(n);
      share_centers.push_back(per_share);
      first_decisions.push_back(first);
    }
    return {{"centers", centers}, {"share_centers", share_centers}, {"first_decisions", first_decisions}};
  }

  // Where record r's cell starts in split level j's map, whose centers' bits are c (cell_map_file.h).
  static MapEntry entry_at(const RankedBits& c, uint64_t r) { return {map_bits_before(c, r), c.rank(r)}; }

  // Where phase 3's unit summing cells [first, end) of the split levels (their cells one level after another)
  // starts: at the first of its levels' first cells' centers (sum_cell_info_range), the maps of those levels
  // entered there (the others are not read).
  SumStart sums_start(uint64_t first, uint64_t end, const std::vector<uint64_t>& split_cells) const {
    SumStart start;
    start.record = in.index.records;
    std::vector<std::optional<RankedBits>> centers(split.size());
    for (size_t j = 0, before = 0; j < split.size(); before += split_cells[j], ++j)
      if (first < before + split_cells[j] && end > before) {
        centers[j] = load_centers(j);
        start.record = std::min<uint64_t>(start.record, centers[j]->select(std::max<uint64_t>(first, before) - before));
      }
    for (size_t j = 0; j < split.size(); ++j) start.entries.push_back(centers[j] ? entry_at(*centers[j], start.record) : MapEntry{});
    return start;
  }

  // Sizes every split level's map (and center info) for phase 2, from the centers' bits.
  void size_outputs() const {
    for (size_t j = 0; j < split.size(); ++j) {
      const RankedBits c = load_centers(j);
      const uint64_t bits = map_bits_before(c, in.index.records);
      io::OffsetFile(cells_path(in.prefix, split[j]), O_WRONLY | O_CREAT | O_TRUNC).resize((bits + 63) / 64 * 8);
      if (centers_info())
        io::OffsetFile(cell_info_path(in.prefix, split[j]), O_WRONLY | O_CREAT | O_TRUNC).resize(c.ones() * center_bytes());
    }
  }

  // Share s's first decision of split level j in unit u (its index in the share's file), from phase 1's
  // stamps; past the last unit, UINT64_MAX (the file's end).
  static uint64_t first_decision(const std::vector<json>& centers_values, unsigned u, size_t j, unsigned s) {
    return u < centers_values.size() ? centers_values[u].at("first_decisions").at(j).at(s).get<uint64_t>() : UINT64_MAX;
  }

  // Share s's centers of split level j in the units before u (where unit u's begin in its .ctr file).
  static uint64_t centers_before(const std::vector<json>& centers_values, unsigned u, size_t j, unsigned s) {
    uint64_t before = 0;
    for (unsigned v = 0; v < u; ++v) before += centers_values[v].at("share_centers").at(j).at(s).get<uint64_t>();
    return before;
  }

  // After map unit u's stamp (stream/units.h: its records are in the map for good), the shares' decisions
  // (and centers) of its records are read by nothing: freed, so that the decisions give back their disk as
  // the map units go rather than all at the phase's end (spend_share_files). Their start in each file is
  // phase 1's stamp's, as phase 2 reads them; the last unit's end is the file's.
  void free_unit_share_bytes(unsigned u, const std::vector<json>& centers_values) const {
    if (!in.spend_decisions) return;
    for (size_t j = 0; j < split.size(); ++j)
      for (unsigned s = 0; s < plan.count; ++s) {
        const std::string dec = cluster_share_decisions_path(in.prefix, s, split[j]);
        std::error_code ec;
        const uint64_t items = std::filesystem::file_size(dec, ec) / 8;
        if (!ec)
          free_bytes(dec, 8 * first_decision(centers_values, u, j, s), 8 * std::min(items, first_decision(centers_values, u + 1, j, s)));
        if (centers_info())
          free_bytes(cluster_share_centers_path(in.prefix, s, split[j]), centers_before(centers_values, u, j, s) * center_bytes(),
                     centers_before(centers_values, u + 1, j, s) * center_bytes());
      }
  }

  // Phase 2, unit u: its records' cells in every split level's map, in place (the words shared with its
  // neighbours returned as [level j, word, bits]), and its centers' positions for center representatives.
  json map_unit(unsigned u, const std::vector<json>& centers_values, Progress& progress) const {
    const uint64_t lo = units.lo(u), hi = units.hi(u), records = in.index.records;
    json edges = json::array(), entries = json::array();
    for (size_t j = 0; j < split.size(); ++j) {
      const size_t level = split[j];
      const RankedBits c = load_centers(j);
      const uint64_t start = map_bits_before(c, lo), made_before = lo < records ? c.rank(lo) : 0;
      entries.push_back({start, made_before});  // where the pairs unit enters the map
      std::vector<uint64_t> words(1, 0);  // from word start / 64
      unsigned used = static_cast<unsigned>(start % 64);
      auto put = [&](uint64_t value, unsigned bits) {
        if (bits == 0) return;
        words.back() |= value << used;
        if (used + bits >= 64) {
          const unsigned spill = used + bits - 64;
          words.push_back(spill ? value >> (bits - spill) : 0);
          used = spill;
        } else {
          used += bits;
        }
      };
      // The centers' positions: share s's first center of this unit is its centers in the units before.
      std::vector<std::unique_ptr<ItemReader>> ctrs;
      std::vector<char> info;
      uint64_t info_cell = made_before;
      std::unique_ptr<io::OffsetFile> info_file;
      if (centers_info()) {
        for (unsigned s = 0; s < plan.count; ++s)
          ctrs.push_back(std::make_unique<ItemReader>(cluster_share_centers_path(in.prefix, s, level), center_bytes(),
                                                      centers_before(centers_values, u, j, s)));
        info_file = std::make_unique<io::OffsetFile>(cell_info_path(in.prefix, level), O_WRONLY);
      }
      auto flush_info = [&] {
        info_file->write(info.data(), info.size(), info_cell * center_bytes());
        info_cell += info.size() / center_bytes();
        info.clear();
      };
      uint64_t bits = 0, made = info_cell;  // the bits put, and the cells made before the record (its rank)
      auto fetch = [&](uint32_t center) { c.prefetch(center); };  // a center earlier in the order, at random
      std::vector<uint64_t> share_from(plan.count), share_to(plan.count);  // each share's decisions of the unit
      for (unsigned s = 0; s < plan.count; ++s)
        share_from[s] = first_decision(centers_values, u, j, s), share_to[s] = first_decision(centers_values, u + 1, j, s);
      for_each_decision(in, plan, level, lo, hi, share_from, share_to, progress, fetch,
                        [&](uint64_t r, uint32_t center, unsigned s) {
        if (!c.has(center))
          fail(Status::io_error, cluster_share_decisions_path(in.prefix, s, level) + ": a member of a record that is no center");
        const unsigned width = static_cast<unsigned>(std::bit_width(made));
        const uint64_t cell = center == r ? made : c.rank(center);
        put(cell, width);
        bits += width;
        made += center == r;
        if (center == r && info_file) {
          const char* q = ctrs[s]->next();
          if (!q) fail(Status::io_error, cluster_share_centers_path(in.prefix, s, level) + ": cut short");
          info.insert(info.end(), q, q + center_bytes());
          if (info.size() >= kInfoFlush * center_bytes()) flush_info();
        }
      });
      if (info_file) flush_info();
      if (bits == 0) continue;
      // Words [first, last] hold bits [start, start + bits); the first is shared unless the unit starts
      // it, the last unless the unit ends it or is the map's end.
      const uint64_t end = start + bits, first = start / 64, last = (end - 1) / 64;
      words.resize(last - first + 1);
      const bool head = start % 64 != 0, tail = end % 64 != 0 && hi < records;
      uint64_t from = first, to = last + 1;  // the words written here
      if (first == last) {
        if (head || tail) edges.push_back({j, first, words.front()}), from = to;
      } else {
        if (head) edges.push_back({j, first, words.front()}), ++from;
        if (tail) edges.push_back({j, last, words.back()}), --to;
      }
      if (from < to)
        io::OffsetFile(cells_path(in.prefix, level), O_WRONLY).write(&words[from - first], (to - from) * 8, from * 8);
    }
    return {{"edges", edges}, {"entries", entries}};
  }

  // Before phase 2 frees a byte of the shares' files: the units' key, in cluster-shares/spent.json, so that
  // a merge under another key knows it cannot read them (forget_shares_spent_elsewhere). Returns false when
  // the shares' directory is gone (another process has stamped the stage: nothing is left to spend).
  bool mark_shares_spent(const json& unit_key) const {
    if (!in.spend_decisions) return false;
    std::error_code ec;
    try {
      io::write_file_atomic(spent_path(in.prefix), json{{"key", unit_key}}.dump() + "\n", io::Sync::durable, io::Writers::several);
    } catch (const Failure&) {
      if (!std::filesystem::exists(cluster_shares_dir(in.prefix), ec)) return false;
      throw;
    }
    return true;
  }

  // The shares' decisions (and centers) of the split levels, once every map unit is stamped: nothing reads
  // them again, and the pairs units are about to write as many bytes. Emptied (what the map units freed
  // as they went, and what a file system without holes kept), not removed, so that the shares' stamps,
  // which name them, still hold for a process that comes late (it finds every unit done). Every process
  // that gets here does it (the same result whoever does; the mark is written before phase 2); one that
  // comes after the stage's stamp, which removes the shares' directory, finds nothing left to do.
  void spend_share_files() const {
    if (!in.spend_decisions) return;
    for (unsigned s = 0; s < plan.count; ++s)
      for (size_t level : split)
        for (const std::string& path : {cluster_share_decisions_path(in.prefix, s, level), cluster_share_centers_path(in.prefix, s, level)})
          if (::truncate(path.c_str(), 0) != 0 && errno != ENOENT)
            fail(Status::io_error, path + ": cannot empty: " + std::strerror(errno));
  }

  json sums_phase(const json& unit_key, const std::vector<uint64_t>& split_cells, unsigned index, Progress& progress) const;

  // Phase 4, unit u: its records' cells of every split level as (vertex, cell) pairs by vertex range
  // (stream/vertex_pairs.h; the cells by vertex's), from the map entered at its first record and the order's
  // ids, a buffer at a time. Apart from phase 2 so that they are written once the shares' decisions are
  // spent: on the 193 M-triangle city at N = 8 the two made 7.8 GB together.
  json pairs_unit(unsigned u, const std::vector<uint64_t>& split_cells, const std::vector<json>& maps, Progress& progress) const {
    const uint64_t lo = units.lo(u), hi = units.hi(u);
    const io::OffsetFile order(in.index.order_path, O_RDONLY);
    std::vector<uint32_t> ids(kPairsRead), cells(kPairsRead);
    std::vector<uint64_t> bucket_counts(kVertexPairBuckets, 0);  // the same for every split level
    for (uint64_t r = lo; r < hi; r += kPairsRead) {
      const uint64_t n = std::min<uint64_t>(kPairsRead, hi - r);
      order.read(ids.data(), 4 * n, 4 * r);
      for (uint64_t i = 0; i < n; ++i)
        if (ids[i] >= in.index.vertices) fail(Status::io_error, in.index.order_path + ": vertex id out of range");
      count_vertex_pairs(std::span<const uint32_t>(ids.data(), n), in.index.vertices, bucket_counts);
    }
    for (size_t j = 0; j < split.size(); ++j) {
      // The map entered at the unit's first record, where its map unit began (the whole map is written:
      // phase 2's shared words too).
      const json& entry = maps.at(u).at("entries").at(j);
      CellMapReader map(cells_path(in.prefix, split[j]), MapEntry{entry.at(0).get<uint64_t>(), entry.at(1).get<uint64_t>()});
      VertexPairsWriter pairs(vertex_pairs_path(in.prefix, split[j], u), in.index.vertices, lo, hi, split_cells[j], bucket_counts);
      for (uint64_t r = lo; r < hi; r += kPairsRead) {
        progress.check();
        const uint64_t n = std::min<uint64_t>(kPairsRead, hi - r);
        order.read(ids.data(), 4 * n, 4 * r);
        map.read(std::span<uint32_t>(cells.data(), n));
        for (uint64_t i = 0; i < n; ++i) pairs.add(ids[i], cells[i]);
      }
      if (hi == in.index.records) map.finish(in.index.records, split_cells[j]);
      pairs.commit();
    }
    return json::object();
  }

  // The words units share, once every map unit is stamped: each the OR of its parts (written by every
  // process that gets here, the same value each time).
  void write_edges(const std::vector<json>& map_values) const {
    std::map<std::pair<size_t, uint64_t>, uint64_t> words;
    for (const json& v : map_values)
      for (const json& e : v.at("edges")) words[{e.at(0).get<size_t>(), e.at(1).get<uint64_t>()}] |= e.at(2).get<uint64_t>();
    for (const auto& [at, bits] : words) io::OffsetFile(cells_path(in.prefix, split.at(at.first)), O_WRONLY).write(&bits, 8, at.second * 8);
  }
};

}  // namespace

std::string cluster_merge_dir(const std::string& prefix) { return prefix + "cluster-merge/"; }

void remove_vertex_pairs(const std::string& prefix) {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(cluster_merge_dir(prefix) + "map/", ec)) {
    const std::string name = e.path().filename().string();
    if (name.starts_with("pairs-") && name.ends_with(".bin")) std::filesystem::remove(e.path(), ec);
  }
}

std::string vertex_pairs_path(const std::string& prefix, size_t level, unsigned unit) {
  return cluster_merge_dir(prefix) + fmt::format("map/pairs-{}-{}.bin", level, unit);
}

std::vector<std::string> vertex_pairs_paths(const std::string& prefix, size_t level) {
  std::vector<std::pair<unsigned, std::string>> found;  // (unit, path)
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(cluster_merge_dir(prefix) + "map/", ec)) {
    const std::string name = e.path().filename().string();
    unsigned l = 0, u = 0;
    int end = 0;
    if (std::sscanf(name.c_str(), "pairs-%u-%u.bin%n", &l, &u, &end) == 2 && static_cast<size_t>(end) == name.size() && l == level)
      found.emplace_back(u, e.path().string());
  }
  std::sort(found.begin(), found.end());
  std::vector<std::string> paths;
  for (auto& f : found) paths.push_back(std::move(f.second));
  return paths;
}

bool forget_shares_spent_elsewhere(const ClusterShareInput& in, const ClusterShares& plan, const nlohmann::ordered_json& key) {
  std::error_code ec;
  if (!std::filesystem::exists(spent_path(in.prefix), ec)) return false;
  try {
    if (json::parse(io::read_small_file(spent_path(in.prefix))).at("key") == merge_unit_key(in, plan, key)) return false;
  } catch (const std::exception&) {
    // unreadable: spent by someone
  }
  for (unsigned s = 0; s < plan.count; ++s) std::filesystem::remove(cluster_share_stamp(in.prefix, s), ec);
  std::filesystem::remove(spent_path(in.prefix), ec);
  return true;
}

SplitMerge merge_split_levels(const ClusterShareInput& in, const ClusterShares& plan, const nlohmann::ordered_json& key,
                              unsigned index, Progress& progress) {
  SplitMerge out;
  std::vector<uint64_t>& cells = out.cells;
  cells.assign(plan.whole_share.size(), 0);
  // The records' positions in weight order are read by nothing after the sums (and the shares, all run
  // before the merge): spent (position_gather.h), before the pairs are written.
  auto spend_positions = [&] {
    if (in.spend_decisions && !in.index.ordered_positions_path.empty()) spend_ordered_positions(in.index.ordered_positions_path);
  };
  Merge m{in, plan, split_levels(plan), {}, cluster_merge_dir(in.prefix), ""};
  if (m.split.empty()) {
    spend_positions();
    return out;
  }
  const uint64_t records = in.index.records;
  m.units.records = records;
  m.units.words = (records + 63) / 64;
  m.units.count = merge_unit_count(in, plan);
  if (records == 0) {  // empty maps and infos
    for (size_t l : m.split) {
      io::OffsetFile(cells_path(in.prefix, l), O_WRONLY | O_CREAT | O_TRUNC).close();
      if (m.centers_info()) io::OffsetFile(cell_info_path(in.prefix, l), O_WRONLY | O_CREAT | O_TRUNC).close();
    }
    return out;
  }
  // A unit at a time on each thread the budget holds: a bit and a half a record (a level's centers' bits),
  // a window of each share's files (two with centers) (a map unit), or the buffers of its records' ids and
  // cells and of their pairs (a pairs unit).
  const uint64_t buffers = 8 * kPairsRead + kVertexPairBuckets * VertexPairsWriter::kBufferPairs * 8;
  const uint64_t unit_bytes = records * 3 / 16 + uint64_t{plan.count} * (m.centers_info() ? 2 : 1) * kReadBuffer + buffers;
  const uint64_t fit = in.memory_bytes ? std::max<uint64_t>(in.memory_bytes / unit_bytes, 1) : m.units.count;
  const unsigned threads = unit_threads(m.units.count, fit);
  const json unit_key = merge_unit_key(in, plan, key);
  const std::string centers_dir = m.dir + "centers/", map_dir = m.dir + "map/";
  m.bits_path = centers_dir + "centers.bits";
  start_once(centers_dir, m.bits_path, unit_key, {"merge-centers-"}, [&] {
    io::OffsetFile(m.bits_path, O_WRONLY | O_CREAT | O_TRUNC).resize(m.split.size() * m.units.words * 8);
  });
  const std::vector<json> centers = take_units_on_threads(centers_dir, m.units.count, index, threads, "merge-centers", unit_key,
                                                        [&](unsigned u) { return m.centers_unit(u, progress); });
  progress.report("cluster", 0.2);
  // An older start's stamps and pairs go (each unit writes its pairs file whole).
  // (and an older build's plain cells, map/cells-L.u32, which the sums and pairs units read until 2026-12-05)
  start_once(map_dir, cells_path(in.prefix, m.split.back()), unit_key, {"merge-map-", "pairs-", "cells-"}, [&] { m.size_outputs(); });
  m.mark_shares_spent(unit_key);
  const std::vector<json> maps = take_units_on_threads(
      map_dir, m.units.count, index, threads, "merge-map", unit_key, [&](unsigned u) { return m.map_unit(u, centers, progress); },
      [&](unsigned u) { m.free_unit_share_bytes(u, centers); });
  m.write_edges(maps);
  m.spend_share_files();
  std::vector<uint64_t> split_cells(m.split.size(), 0);
  for (size_t j = 0; j < m.split.size(); ++j) {
    for (const json& v : centers) split_cells[j] += v.at("centers").at(j).get<uint64_t>();
    cells[m.split[j]] = split_cells[j];
  }
  out.units = {{"units", m.units.count}, {"centers", unit_figures(centers)}, {"map", unit_figures(maps)}};
  if (!m.centers_info()) out.units["sums"] = m.sums_phase(unit_key, split_cells, index, progress);
  spend_positions();
  // Phase 4: the pairs by vertex range. Started is its own stamp (start_once's file argument is for a file
  // the units fill in place; they write their own).
  const std::string pairs_dir = m.dir + "pairs/";
  start_once(pairs_dir, pairs_dir + "start.json", unit_key, {"merge-pairs-"}, [] {});
  const std::vector<json> pairs = take_units_on_threads(pairs_dir, m.units.count, index, threads, "merge-pairs", unit_key,
                                                        [&](unsigned u) { return m.pairs_unit(u, split_cells, maps, progress); });
  out.units["pairs"] = unit_figures(pairs);
  return out;
}

// Phase 3 (mean and quadric representatives): the infos by ranges of cells, once every map is whole; returns
// the units' figures.
json Merge::sums_phase(const json& unit_key, const std::vector<uint64_t>& split_cells, unsigned index, Progress& progress) const {
  const uint64_t records = in.index.records;
  progress.report("cluster", 0.6);
  const std::string sums_dir = dir + "sums/";
  const uint64_t info_bytes = cell_info_bytes(in.info, in.index.single_precision);
  start_once(sums_dir, cell_info_path(in.prefix, split.back()), unit_key, {"merge-sums-"}, [&] {
    for (size_t j = 0; j < split.size(); ++j)
      io::OffsetFile(cell_info_path(in.prefix, split[j]), O_WRONLY | O_CREAT | O_TRUNC).resize(split_cells[j] * info_bytes);
  });
  uint64_t total = 0;
  for (uint64_t c : split_cells) total += c;
  // A unit a thread, each with its share of the budget while that leaves it kMinSumsUnitBytes.
  const uint64_t sum_fit = in.memory_bytes ? std::max<uint64_t>(in.memory_bytes / kMinSumsUnitBytes, 1) : units.count;
  const unsigned sum_threads = unit_threads(units.count, sum_fit);
  const std::vector<json> sums = take_units_on_threads(sums_dir, units.count, index, sum_threads, "merge-sums", unit_key, [&](unsigned u) {
    const uint64_t first = total * u / units.count, end = total * (u + 1) / units.count;
    if (first == end) return json{{"cells", 0}, {"from_record", records}};
    const SumStart start = sums_start(first, end, split_cells);
    sum_cell_info_range(in.index, split, split_cells, in.info, in.memory_bytes / sum_threads, in.chunk_cap, progress, in.prefix,
                        first, end, 1, start);
    return json{{"cells", end - first}, {"from_record", start.record}};
  });
  return unit_figures(sums);
}

}  // namespace lodstream::stream
