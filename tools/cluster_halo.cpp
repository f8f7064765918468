// How wide a halo clustering by region needs (issue 19): a measurement, not a stage.
//
// Usage: cluster_halo WORK OUTDIR [--axes xyz] [--cuts K] [--levels DIGITS] [--no-verify]
//   WORK: a `simplify --work` directory (its store and weight index, order.u32); OUTDIR: that run's output
//   directory (manifest.json: the levels' cell sizes and the cell options).
//
// For every level (cell size c), every axis asked and K cut planes at the 1/(K+1), ..., K/(K+1) quantiles
// of the vertices' coordinate on that axis, each side of the plane is a task's region: the tool runs
// core/floating_cell_region.h over the vertices a task would hold, the region plus a halo of width H
// beyond the plane (everything else held on the other axes, as if the scene were cut in slabs), and
// counts the region's vertices whose status or cell the task cannot settle. H = 0 first: the farthest
// unsettled vertex from the plane is the doubt's reach. Then H grows (the reach plus c, 2c, 4c, ...)
// until every region vertex is settled: the halo a task needs. It prints, per level: the reach and the
// halo needed in cells (the largest over the cuts), and the vertices a task holds over its
// region's (the halo's extra work). With verification (the default) every settled decision is also
// compared with a whole-scene Clusterer pass; any difference makes the tool exit 1.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include "core/floating_cell.h"
#include "core/floating_cell_region.h"
#include "core/status.h"
#include "io/mapped_file.h"
#include "stream/scene_store.h"
#include "stream/store_access.h"

using namespace lodstream;
using P = std::array<double, 3>;
static_assert(sizeof(P) == 3 * sizeof(double));  // a vector of P is a span of xyz
constexpr double kInf = std::numeric_limits<double>::infinity();

namespace {

struct Run {
  uint64_t held = 0, region = 0, unsettled = 0;  // unsettled: region vertices whose status or cell is not settled
  double reach = 0;                              // the farthest of them from the plane
  uint64_t mismatches = 0;                       // settled decisions that differ from the whole-scene pass
};

// The task of one side of the plane x[axis] = x0 with a halo of h: the region is p < x0 (side 0) or
// p >= x0 (side 1); the task holds p < x0 + h, or p >= x0 - h.
Run run_task(const std::vector<P>& pts, const std::vector<uint32_t>& whole, double c, core::ClusterOptions o, int axis,
             double x0, int side, double h) {
  std::array<double, 6> box = {-kInf, -kInf, -kInf, kInf, kInf, kInf};
  if (side == 0) box[3 + axis] = x0 + h;
  else box[axis] = x0 - h;
  core::RegionClusterer rc(c, o, box);
  Run r;
  for (uint32_t i = 0; i < pts.size(); ++i) {
    const double x = pts[i][axis];
    if (!(x >= box[axis] && x < box[3 + axis])) continue;
    const core::RegionDecision d = rc.assign(i, pts[i]);  // tagged by its whole-scene index
    ++r.held;
    if (!whole.empty()) {
      if (d.status != core::RegionStatus::unsettled && (d.status == core::RegionStatus::center) != (whole[i] == i))
        ++r.mismatches;
      if (d.cell_settled && d.center != whole[i]) ++r.mismatches;
    }
    const bool own = side == 0 ? x < x0 : x >= x0;
    if (!own) continue;
    ++r.region;
    if (!d.cell_settled) ++r.unsettled, r.reach = std::max(r.reach, std::fabs(x - x0));
  }
  return r;
}

}  // namespace

int main(int argc, char** argv) try {
  if (argc < 3) {
    std::fprintf(stderr, "usage: cluster_halo WORK OUTDIR [--axes xyz] [--cuts K] [--levels DIGITS] [--no-verify]\n");
    return 64;
  }
  const std::string work = argv[1], outdir = argv[2];
  std::string axes = "xy";
  int cuts = 1;
  bool verify = true;
  std::string levels;  // level numbers to measure, e.g. "01"; empty: all
  for (int i = 3; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--axes" && i + 1 < argc) axes = argv[++i];
    else if (a == "--cuts" && i + 1 < argc) cuts = std::stoi(argv[++i]);
    else if (a == "--no-verify") verify = false;
    else if (a == "--levels" && i + 1 < argc) levels = argv[++i];
    else {
      std::fprintf(stderr, "cluster_halo: unknown argument %s\n", a.c_str());
      return 64;
    }
  }
  std::ifstream manifest_file(outdir + "/manifest.json");
  if (!manifest_file) {
    std::fprintf(stderr, "cluster_halo: cannot read %s/manifest.json\n", outdir.c_str());
    return 66;
  }
  nlohmann::json manifest;
  manifest_file >> manifest;
  core::ClusterOptions o;
  const nlohmann::json& opts = manifest["options"];
  if (opts.value("clustering", std::string("floating")) != "floating") {
    std::fprintf(stderr, "cluster_halo: floating cells only (uniform cells need no halo)\n");
    return 64;
  }
  if (opts.value("cell", std::string("cube")) == "sphere") o.shape = core::CellShape::sphere;
  if (opts.value("variant", std::string("nearest")) == "heaviest") o.choice = core::CellChoice::heaviest;
  std::vector<double> sizes;
  for (const auto& l : manifest["levels"]) sizes.push_back(l["cell_size"].get<double>());

  stream::StoreMeta meta;
  if (!stream::read_store_meta(work + "/store", &meta)) {
    std::fprintf(stderr, "cluster_halo: %s/store holds no complete scene store\n", work.c_str());
    return 66;
  }
  io::MappedFile order(work + "/order.u32");
  const uint64_t n = order.size() / 4;
  const io::Window ow = order.map(0, order.size());
  const uint32_t* ids = reinterpret_cast<const uint32_t*>(ow.data());
  stream::StorePositions positions(work + "/store", meta);
  positions.acquire();
  std::vector<P> pts(n);
  for (uint64_t i = 0; i < n; ++i) positions.get(ids[i], pts[i].data());
  positions.release();
  fmt::print("{} vertices in weight order, {} levels, cells {} {}\n", n, sizes.size(),
             o.shape == core::CellShape::sphere ? "sphere" : "cube",
             o.choice == core::CellChoice::heaviest ? "heaviest" : "nearest");
  fmt::print("level | cell size | cuts | reach (cells): max / median | halo needed (cells): max | held / region: max | "
             "region unsettled at H=0: share | mismatches\n");

  // The tasks, the same in every level: each side of each cut plane.
  struct Cut {
    int axis;
    double x0;
    int side;
  };
  std::vector<Cut> jobs;
  for (char ax : axes) {
    const int axis = ax - 'x';
    std::vector<double> xs(n);
    for (uint64_t i = 0; i < n; ++i) xs[i] = pts[i][axis];
    std::sort(xs.begin(), xs.end());
    for (int k = 1; k <= cuts; ++k)
      for (int side = 0; side < 2; ++side) jobs.push_back({axis, xs[n * k / (cuts + 1)], side});
  }

  bool failed = false;
  for (size_t l = 0; l < sizes.size(); ++l) {
    if (!levels.empty() && levels.find(char('0' + l)) == std::string::npos) continue;
    const double c = sizes[l];
    const std::vector<uint32_t> whole =
        verify ? core::whole_scene_centers(std::span<const double>(pts.data()->data(), 3 * n), c, o) : std::vector<uint32_t>();
    struct Result {
      double reach, halo, held_ratio, unsettled_share;
      uint64_t mismatches;
    };
    std::vector<Result> results(jobs.size());
    tbb::parallel_for(size_t{0}, jobs.size(), [&](size_t j) {
      const Cut& cut = jobs[j];
      const Run first = run_task(pts, whole, c, o, cut.axis, cut.x0, cut.side, 0);
      Result res{first.reach / c, 0, 1, first.region ? double(first.unsettled) / double(first.region) : 0,
                 first.mismatches};
      double step = c;
      Run r = first;
      while (r.unsettled > 0) {
        const double h = first.reach + step;
        r = run_task(pts, whole, c, o, cut.axis, cut.x0, cut.side, h);
        res.mismatches += r.mismatches;
        res.halo = h / c;
        res.held_ratio = r.region ? double(r.held) / double(r.region) : 1;
        if (r.held == n) break;  // the task holds everything
        step *= 2;
      }
      results[j] = res;
    });
    std::vector<double> reach;
    double halo = 0, held = 0, share = 0;
    uint64_t mismatches = 0;
    for (const Result& r : results) {
      reach.push_back(r.reach), halo = std::max(halo, r.halo), held = std::max(held, r.held_ratio);
      share = std::max(share, r.unsettled_share), mismatches += r.mismatches;
    }
    std::sort(reach.begin(), reach.end());
    fmt::print("{} | {:.6g} | {} | {:.2f} / {:.2f} | {:.2f} | {:.3f} | {:.4f} % | {}\n", l, c, jobs.size(), reach.back(),
               reach[reach.size() / 2], halo, held, 100 * share, verify ? std::to_string(mismatches) : "-");
    std::fflush(stdout);
    failed |= mismatches > 0;
  }
  return failed ? 1 : 0;
} catch (const Failure& f) {
  std::fprintf(stderr, "cluster_halo: %s\n", f.what());
  return 70;
} catch (const std::exception& e) {  // a manifest.json that is not JSON
  std::fprintf(stderr, "cluster_halo: %s\n", e.what());
  return 66;
}
