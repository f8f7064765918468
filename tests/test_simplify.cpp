// End-to-end tests of `simplify` (the LOD pipeline: ingest -> grade -> sort -> cluster -> emit -> write),
// through the public API and the CLI:
// - determinism: output bytes identical for any thread count, memory budget, chunk size and grading range
//   size (../shared/DESIGN.md "Same answer in memory and out of core");
// - validity of the sample room's levels, read back from the binary PLY files;
// - seam vertices: the same bytes for any grade_range_vertices;
// - Low & Tan's Figure 4 (§3.2.3) and Plate 5 (§3.2.2) on the whole pipeline, with exact coordinates;
// - target triangle counts; exit codes; input lines and points; thick edges with hand-derived thickness;
// - every model of ../shared/data (skipped when absent).
// Small inputs are OBJ text with dyadic coordinates, so every expected position is exact.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <spawn.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <span>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/grade.h"
#include "lodstream/lodstream.h"
#include "cli_harness.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;
using P3 = std::array<double, 3>;
using F3 = std::array<float, 3>;

std::string slurp(const fs::path& p) { return test::read_file(p.string()); }

std::string sample_room() { return test::source_dir() + "/tests/data/sample-room.ply"; }

// ---- running the library ----

Options make_options(unsigned threads, uint64_t memory = 0, uint64_t chunk = 0) {
  Options o;
  o.threads = threads;
  o.memory_bytes = memory;
  o.chunk_bytes = chunk;
  return o;
}

// The tests' expectations (exact coordinates, output positions that are input positions) are derived
// with the paper's center representative, so they ask for it; the default is quadric (see
// SimplifyDefaults.RepresentativeIsQuadric).
SimplifyOptions make_simplify(const std::string& out_dir) {
  SimplifyOptions s;
  s.output_dir = out_dir;
  s.representative = Representative::center;
  return s;
}

// Runs simplify and records a failure (status and message) when it does not succeed.
bool simplify_ok(const std::string& input, const SimplifyOptions& so, const Options& o, SimplifyReport* report = nullptr) {
  SimplifyReport local;
  const Result r = simplify(input, so, o, report ? report : &local);
  EXPECT_TRUE(r.ok()) << input << " -> " << so.output_dir << ": " << status_name(r.status) << ": " << r.message;
  return r.ok();
}

// ---- comparing output directories ----

// Every output file except manifest.json, by name.
std::map<std::string, std::string> output_files(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename() != "manifest.json") files[e.path().filename().string()] = slurp(e.path());
  return files;
}

// Timing, memory and work-directory fields legitimately vary between runs.
void strip_timings(Json& j) {
  if (j.is_object()) {
    for (const char* k : {"stages", "seconds", "peak_rss_bytes", "work_dir"}) j.erase(k);
    for (auto& [k, v] : j.items()) strip_timings(v);
  } else if (j.is_array()) {
    for (auto& v : j) strip_timings(v);
  }
}

Json manifest(const fs::path& dir) {
  const std::string text = slurp(dir / "manifest.json");
  EXPECT_FALSE(text.empty()) << (dir / "manifest.json");
  return text.empty() ? Json() : Json::parse(text);
}

Json manifest_without_timings(const fs::path& dir) {
  Json j = manifest(dir);
  strip_timings(j);
  return j;
}

void expect_same_output(const fs::path& a, const fs::path& b, const std::string& what) {
  SCOPED_TRACE(what);
  const auto fa = output_files(a), fb = output_files(b);
  std::vector<std::string> na, nb;
  for (const auto& [k, v] : fa) na.push_back(k);
  for (const auto& [k, v] : fb) nb.push_back(k);
  ASSERT_EQ(na, nb);
  for (const auto& [name, bytes] : fa) {
    const std::string& other = fb.at(name);
    if (bytes == other) continue;
    size_t at = 0;
    while (at < bytes.size() && at < other.size() && bytes[at] == other[at]) ++at;
    ADD_FAILURE() << name << " differs: " << bytes.size() << " vs " << other.size() << " bytes, first difference at byte "
                  << at;
  }
  EXPECT_EQ(manifest_without_timings(a), manifest_without_timings(b));
}

// ---- reading a level back (binary PLY as io/ply_writer.cpp writes it) ----

struct Level {
  std::vector<F3> positions, normals;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<std::array<uint32_t, 2>> edges;
  std::vector<float> thickness;
  std::vector<uint32_t> points;
  std::vector<float> point_size;
  bool ok = false;

  F3 at(uint32_t v) const { return positions.at(v); }
};

Level read_level(const std::string& path) {
  Level level;
  const std::string s = slurp(path);
  const size_t end = s.find("end_header\n");
  if (s.rfind("ply\nformat binary_little_endian 1.0\n", 0) != 0 || end == std::string::npos) {
    ADD_FAILURE() << path << ": not a binary little-endian PLY";
    return level;
  }
  // Element counts and the property layout, with comments removed.
  std::istringstream header(s.substr(0, end));
  std::string line, layout;
  std::map<std::string, uint64_t> count;
  while (std::getline(header, line)) {
    if (line.rfind("comment", 0) == 0 || line == "ply" || line.rfind("format", 0) == 0) continue;
    std::istringstream ls(line);
    std::string word, name;
    ls >> word;
    if (word == "element") {
      uint64_t n = 0;
      ls >> name >> n;
      count[name] = n;
      layout += "element " + name + "\n";
    } else {
      layout += line + "\n";
    }
  }
  const std::string xyz = "property float x\nproperty float y\nproperty float z\n";
  const std::string nxyz = "property float nx\nproperty float ny\nproperty float nz\n";
  const std::string rest =
      "element face\nproperty list uchar uint vertex_indices\n"
      "element edge\nproperty uint vertex1\nproperty uint vertex2\nproperty float thickness\n"
      "element point\nproperty uint vertex\nproperty float size\n";
  // With materials (io/ply_writer.h), face, edge and point each end with a uint material_index.
  const std::string m = "property uint material_index\n";
  const std::string rest_m =
      "element face\nproperty list uchar uint vertex_indices\n" + m +
      "element edge\nproperty uint vertex1\nproperty uint vertex2\nproperty float thickness\n" + m +
      "element point\nproperty uint vertex\nproperty float size\n" + m;
  const bool materials = layout == "element vertex\n" + xyz + nxyz + rest_m || layout == "element vertex\n" + xyz + rest_m;
  const bool with_normals = layout == "element vertex\n" + xyz + nxyz + (materials ? rest_m : rest);
  if (!with_normals && layout != "element vertex\n" + xyz + (materials ? rest_m : rest)) {
    ADD_FAILURE() << path << ": unexpected header layout:\n" << layout;
    return level;
  }
  const char* p = s.data() + end + std::strlen("end_header\n");
  const char* const stop = s.data() + s.size();
  auto take = [&](void* to, size_t n) {
    if (static_cast<size_t>(stop - p) < n) return false;
    std::memcpy(to, p, n);
    p += n;
    return true;
  };
  bool good = true;
  for (uint64_t v = 0; good && v < count["vertex"]; ++v) {
    F3 pos{}, nrm{};
    good = take(pos.data(), 12) && (!with_normals || take(nrm.data(), 12));
    level.positions.push_back(pos);
    if (with_normals) level.normals.push_back(nrm);
  }
  for (uint64_t t = 0; good && t < count["face"]; ++t) {
    uint8_t n = 0;
    std::array<uint32_t, 3> ids{};
    uint32_t material = 0;
    good = take(&n, 1) && n == 3 && take(ids.data(), 12) && (!materials || take(&material, 4));
    level.triangles.push_back(ids);
  }
  for (uint64_t e = 0; good && e < count["edge"]; ++e) {
    std::array<uint32_t, 2> ids{};
    float th = 0;
    uint32_t material = 0;
    good = take(ids.data(), 8) && take(&th, 4) && (!materials || take(&material, 4));
    level.edges.push_back(ids);
    level.thickness.push_back(th);
  }
  for (uint64_t i = 0; good && i < count["point"]; ++i) {
    uint32_t id = 0, material = 0;
    float size = 0;
    good = take(&id, 4) && take(&size, 4) && (!materials || take(&material, 4));
    level.points.push_back(id);
    level.point_size.push_back(size);
  }
  if (!good || p != stop) {
    ADD_FAILURE() << path << ": body does not match the header (" << (stop - p) << " bytes left)";
    return level;
  }
  level.ok = true;
  return level;
}

// A triangle as its corner positions, rotated so that the smallest corner comes first (winding kept).
using TriKey = std::array<F3, 3>;
TriKey tri_key(const Level& l, const std::array<uint32_t, 3>& t) {
  TriKey k{l.at(t[0]), l.at(t[1]), l.at(t[2])};
  const size_t first = static_cast<size_t>(std::min_element(k.begin(), k.end()) - k.begin());
  std::rotate(k.begin(), k.begin() + static_cast<std::ptrdiff_t>(first), k.end());
  return k;
}
// A triangle as the unordered set of its corner positions.
TriKey tri_set(const Level& l, const std::array<uint32_t, 3>& t) {
  TriKey k{l.at(t[0]), l.at(t[1]), l.at(t[2])};
  std::sort(k.begin(), k.end());
  return k;
}
using EdgeKey = std::array<F3, 2>;
EdgeKey edge_key(F3 a, F3 b) { return a < b ? EdgeKey{a, b} : EdgeKey{b, a}; }

std::vector<TriKey> sorted_triangles(const Level& l) {
  std::vector<TriKey> out;
  for (const auto& t : l.triangles) out.push_back(tri_key(l, t));
  std::sort(out.begin(), out.end());
  return out;
}

// Edges as unordered position pairs with their thickness.
std::map<EdgeKey, float> edges_of(const Level& l) {
  std::map<EdgeKey, float> out;
  for (size_t i = 0; i < l.edges.size(); ++i)
    out[edge_key(l.at(l.edges[i][0]), l.at(l.edges[i][1]))] = l.thickness[i];
  return out;
}

std::set<F3> points_of(const Level& l) {
  std::set<F3> out;
  for (uint32_t p : l.points) out.insert(l.at(p));
  return out;
}

std::string str(const F3& p) { return fmt::format("({}, {}, {})", p[0], p[1], p[2]); }

// Every rule of stream/emit_stage.h and core/mesh.h that can be checked on one level's file.
void check_level(const Level& l, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_TRUE(l.ok);
  const uint64_t n = l.positions.size();
  for (const F3& p : l.positions)
    for (float x : p) ASSERT_TRUE(std::isfinite(x)) << "position " << str(p);
  ASSERT_TRUE(l.normals.empty() || l.normals.size() == n);
  for (const F3& q : l.normals)
    for (float x : q) ASSERT_TRUE(std::isfinite(x)) << "normal " << str(q);
  std::vector<uint8_t> on_triangle(n, 0), on_edge(n, 0);
  std::set<TriKey> triangles;
  std::set<EdgeKey> sides;
  for (const auto& t : l.triangles) {
    for (uint32_t v : t) ASSERT_LT(v, n);
    for (uint32_t v : t) on_triangle[v] = 1;
    const TriKey k = tri_set(l, t);
    ASSERT_TRUE(k[0] != k[1] && k[1] != k[2]) << "two corners at one position: " << str(k[0]) << str(k[1]) << str(k[2]);
    EXPECT_TRUE(triangles.insert(k).second) << "two triangles on " << str(k[0]) << str(k[1]) << str(k[2]);
    for (int i = 0; i < 3; ++i) sides.insert(edge_key(l.at(t[i]), l.at(t[(i + 1) % 3])));
  }
  std::set<EdgeKey> edges;
  for (size_t i = 0; i < l.edges.size(); ++i) {
    const auto& e = l.edges[i];
    ASSERT_LT(e[0], n);
    ASSERT_LT(e[1], n);
    on_edge[e[0]] = on_edge[e[1]] = 1;
    const EdgeKey k = edge_key(l.at(e[0]), l.at(e[1]));
    ASSERT_NE(k[0], k[1]) << "edge of zero length at " << str(k[0]);
    EXPECT_TRUE(edges.insert(k).second) << "two edges on " << str(k[0]) << str(k[1]);
    EXPECT_FALSE(sides.count(k)) << "edge on a triangle side " << str(k[0]) << str(k[1]);
    EXPECT_TRUE(std::isfinite(l.thickness[i]) && l.thickness[i] >= 0) << "thickness " << l.thickness[i];
  }
  std::set<F3> covered, points;
  for (uint32_t v = 0; v < n; ++v)
    if (on_triangle[v] || on_edge[v]) covered.insert(l.at(v));
  for (uint32_t p : l.points) {
    ASSERT_LT(p, n);
    EXPECT_FALSE(covered.count(l.at(p))) << "point on a triangle or edge vertex " << str(l.at(p));
    EXPECT_TRUE(points.insert(l.at(p)).second) << "two points at " << str(l.at(p));
  }
  // Normals: unit on triangle vertices, zero on vertices used only by edges and points (core/mesh.h).
  for (uint32_t v = 0; v < l.normals.size(); ++v) {
    const F3& q = l.normals[v];
    const double len = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
    if (on_triangle[v]) EXPECT_NEAR(len, 1.0, 1e-3) << "vertex " << v;
    else EXPECT_EQ(len, 0.0) << "vertex " << v;
  }
}

// ---- small inputs ----

struct Mesh {
  std::vector<P3> v;
  std::vector<std::array<uint32_t, 3>> f;  // 0-based
};

// A cube-sphere of 6·n² quads (two triangles each, facing outwards), radius r, coordinates rounded to
// multiples of 1/64: dyadic, so any translation by a multiple of 1/64 is exact in float and double.
Mesh dyadic_sphere(int n, double r, P3 center = {0, 0, 0}) {
  Mesh m;
  std::map<P3, uint32_t> index;
  auto vertex = [&](P3 c) {
    const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    P3 p;
    for (int k = 0; k < 3; ++k) p[k] = std::round(c[k] / len * r * 64) / 64 + center[k];
    const auto [it, fresh] = index.emplace(p, static_cast<uint32_t>(m.v.size()));
    if (fresh) m.v.push_back(p);
    return it->second;
  };
  for (int axis = 0; axis < 3; ++axis)
    for (int sign = -1; sign <= 1; sign += 2) {
      auto at = [&](int i, int j) {
        P3 c;
        c[axis] = sign;
        c[(axis + 1) % 3] = -1 + 2.0 * i / n;
        c[(axis + 2) % 3] = -1 + 2.0 * j / n;
        return vertex(c);
      };
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          const uint32_t a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
          for (std::array<uint32_t, 3> t : {std::array<uint32_t, 3>{a, b, c}, std::array<uint32_t, 3>{a, c, d}}) {
            const P3 &p0 = m.v[t[0]], &p1 = m.v[t[1]], &p2 = m.v[t[2]];
            const P3 u{p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]}, w{p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
            const P3 nrm{u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
            double out = 0;
            for (int k = 0; k < 3; ++k) out += nrm[k] * (p0[k] - center[k]);
            if (out < 0) std::swap(t[1], t[2]);
            m.f.push_back(t);
          }
        }
    }
  return m;
}

const char* kTwoTriangles = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";

Mesh translated(Mesh m, P3 d) {
  for (P3& p : m.v)
    for (int k = 0; k < 3; ++k) p[k] += d[k];
  return m;
}

// Objects one after the other in one file.
std::string obj_text(const std::vector<Mesh>& meshes) {
  std::string s;
  char buf[128];
  uint32_t base = 1;
  for (size_t i = 0; i < meshes.size(); ++i) {
    s += "o object" + std::to_string(i) + "\n";
    for (const P3& p : meshes[i].v) {
      std::snprintf(buf, sizeof buf, "v %.17g %.17g %.17g\n", p[0], p[1], p[2]);
      s += buf;
    }
    for (const auto& t : meshes[i].f) {
      std::snprintf(buf, sizeof buf, "f %u %u %u\n", t[0] + base, t[1] + base, t[2] + base);
      s += buf;
    }
    base += static_cast<uint32_t>(meshes[i].v.size());
  }
  return s;
}

// ---- 1, 2, 6: the sample room ----

// One baseline run of the room (1 thread, 4 GiB, OBJ too) shared by the suite's tests.
class SimplifyRoom : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    tmp_ = new test::TempDir();
    SimplifyOptions so = make_simplify(tmp_->file("base"));
    so.write_obj = true;
    base_ok_ = simplify_ok(sample_room(), so, make_options(1, 4ull << 30), &base_report_);
  }
  static void TearDownTestSuite() {
    delete tmp_;
    tmp_ = nullptr;
  }
  static fs::path base() { return tmp_->path() / "base"; }

  // The room with the baseline's options except `options`, compared with the baseline.
  static void expect_same_as_base(const std::string& name, const Options& options, uint64_t grade_range = 0,
                                  SimplifyReport* report = nullptr) {
    ASSERT_TRUE(base_ok_);
    SimplifyOptions so = make_simplify(tmp_->file(name));
    so.write_obj = true;
    so.grade_range_vertices = grade_range;
    ASSERT_TRUE(simplify_ok(sample_room(), so, options, report));
    expect_same_output(base(), tmp_->path() / name, name);
  }

  static test::TempDir* tmp_;
  static bool base_ok_;
  static SimplifyReport base_report_;
};
test::TempDir* SimplifyRoom::tmp_ = nullptr;
bool SimplifyRoom::base_ok_ = false;
SimplifyReport SimplifyRoom::base_report_;

TEST_F(SimplifyRoom, BaselineWritesEveryFile) {
  ASSERT_TRUE(base_ok_);
  const auto files = output_files(base());
  ASSERT_EQ(base_report_.levels.size(), 5u);
  for (int l = 0; l < 5; ++l) {
    EXPECT_TRUE(files.count("lod" + std::to_string(l) + ".ply")) << l;
    EXPECT_TRUE(files.count("lod" + std::to_string(l) + ".obj")) << l;
  }
  EXPECT_TRUE(files.count("lods.glb"));
  EXPECT_EQ(files.size(), 11u);
  EXPECT_EQ(base_report_.scene.triangles, 261865u);
}

TEST_F(SimplifyRoom, SameBytesForOneAndTwoThreads) { expect_same_as_base("threads2", make_options(2, 4ull << 30)); }

TEST_F(SimplifyRoom, SameBytesAtTheMinimumMemoryBudget) {
  expect_same_as_base("mem64", make_options(1, min_memory_bytes));
}

TEST_F(SimplifyRoom, SameBytesWithOneByteChunks) { expect_same_as_base("chunk1", make_options(2, 4ull << 30, 1)); }

// The cluster stage maps the store's positions whole only where the column takes at most half the budget
// and --chunk-bytes is not below its size (stream/position_gather.h): the room's column (about 1.6 MB) under
// 64 KiB chunks is read through the page cache, by id, in batches of 16,384 records.
TEST_F(SimplifyRoom, SameBytesWithPositionsReadByIdInsteadOfMapped) {
  expect_same_as_base("read64k", make_options(2, 4ull << 30, 64 << 10));
}

TEST_F(SimplifyRoom, SameBytesWithSevenVertexGradingRanges) {
  SimplifyReport report;
  expect_same_as_base("range7", make_options(1, 4ull << 30), 7, &report);
  EXPECT_GE(report.grade_ranges, 24u);  // dozens at least (about vertices / 7)
  EXPECT_LT(base_report_.grade_ranges, report.grade_ranges);
}

TEST_F(SimplifyRoom, MeanAndQuadricRepresentativesSameBytesForOneAndTwoThreads) {
  for (Representative rep : {Representative::mean, Representative::quadric}) {
    const std::string name = rep == Representative::mean ? "mean" : "quadric";
    SimplifyOptions so = make_simplify(tmp_->file(name + "1"));
    so.representative = rep;
    so.write_obj = true;
    ASSERT_TRUE(simplify_ok(sample_room(), so, make_options(1)));
    so.output_dir = tmp_->file(name + "2");
    ASSERT_TRUE(simplify_ok(sample_room(), so, make_options(2, min_memory_bytes)));
    expect_same_output(tmp_->path() / (name + "1"), tmp_->path() / (name + "2"), name);
    // The representative did change the output, and the level is still valid.
    EXPECT_NE(slurp(tmp_->path() / (name + "1") / "lod2.ply"), slurp(base() / "lod2.ply")) << name;
    for (int l = 0; l < 5; ++l)
      check_level(read_level((tmp_->path() / (name + "1") / ("lod" + std::to_string(l) + ".ply")).string()),
                  name + " lod" + std::to_string(l));
  }
}

TEST_F(SimplifyRoom, LevelsAreValid) {
  ASSERT_TRUE(base_ok_);
  const Json m = manifest(base());
  ASSERT_EQ(m["levels"].size(), 5u);
  std::set<F3> room_positions;
  {
    const test::ReadAll room = test::read_all(sample_room(), 1 << 20);
    for (size_t i = 0; i + 2 < room.positions.size(); i += 3)
      room_positions.insert({float(room.positions[i]), float(room.positions[i + 1]), float(room.positions[i + 2])});
  }
  uint64_t previous = base_report_.scene.triangles;
  double previous_size = 0;
  for (int l = 0; l < 5; ++l) {
    const std::string name = "lod" + std::to_string(l);
    const Level level = read_level((base() / (name + ".ply")).string());
    check_level(level, name);
    const Json& ml = m["levels"][l];
    EXPECT_EQ(ml["triangles"].get<uint64_t>(), level.triangles.size()) << name;
    EXPECT_EQ(ml["edges"].get<uint64_t>(), level.edges.size()) << name;
    EXPECT_EQ(ml["points"].get<uint64_t>(), level.points.size()) << name;
    EXPECT_EQ(ml["vertices"].get<uint64_t>(), level.positions.size()) << name;
    EXPECT_LT(level.triangles.size(), previous) << name << ": triangle counts must fall strictly";
    EXPECT_GT(ml["cell_size"].get<double>(), previous_size) << name;
    EXPECT_GT(level.triangles.size(), 0u) << name;
    previous = level.triangles.size();
    previous_size = ml["cell_size"].get<double>();
    EXPECT_EQ(base_report_.levels[l].triangles, level.triangles.size());
    // With center representatives every output position is an input position of the room.
    size_t foreign = 0;
    for (const F3& p : level.positions) foreign += !room_positions.count(p);
    EXPECT_EQ(foreign, 0u) << name << ": output positions that are no input position";
  }
}

TEST_F(SimplifyRoom, TargetTriangleCountsAreMetWithinFifteenPercent) {
  SimplifyOptions so = make_simplify(tmp_->file("targets"));
  so.target_triangles = {40000, 8000};
  SimplifyReport report;
  ASSERT_TRUE(simplify_ok(sample_room(), so, make_options(2), &report));
  const Json m = manifest(tmp_->path() / "targets");
  ASSERT_EQ(m["levels"].size(), 2u);
  for (size_t l = 0; l < 2; ++l) {
    const double target = static_cast<double>(so.target_triangles[l]);
    const double got = m["levels"][l]["triangles"].get<double>();
    EXPECT_LE(std::abs(got - target), 0.15 * target) << "level " << l << ": " << got << " triangles for " << target;
    EXPECT_EQ(m["levels"][l]["target_triangles"].get<uint64_t>(), so.target_triangles[l]);
    check_level(read_level(tmp_->file("targets/lod" + std::to_string(l) + ".ply")), "target level " + std::to_string(l));
  }
  ASSERT_TRUE(m.contains("search")) << m.dump(1);
  EXPECT_GE(m["search"]["passes"].get<unsigned>(), 1u);
  EXPECT_EQ(m["search"]["passes"].get<unsigned>(), report.search_iterations);
  EXPECT_LE(report.search_iterations, 12u);
}

// ---- 1 (small input): every option that must not change the bytes, at once, per representative ----

TEST(SimplifyDeterminism, SphereWithTinyChunksAndRangesPerRepresentative) {
  test::TempDir tmp;
  const std::string input = tmp.write("sphere.obj", obj_text({dyadic_sphere(16, 4)}));  // 3072 triangles
  for (Representative rep : {Representative::center, Representative::mean, Representative::quadric}) {
    SimplifyOptions so = make_simplify(tmp.file("a"));
    so.representative = rep;
    so.write_obj = true;
    so.cell_sizes = {0.5, 1, 2};
    ASSERT_TRUE(simplify_ok(input, so, make_options(1)));
    so.output_dir = tmp.file("b");
    so.grade_range_vertices = 7;
    SimplifyReport report;
    ASSERT_TRUE(simplify_ok(input, so, make_options(2, min_memory_bytes, 1), &report));
    EXPECT_GE(report.grade_ranges, 24u);
    expect_same_output(tmp.path() / "a", tmp.path() / "b", "representative " + std::to_string(int(rep)));
    for (int l = 0; l < 3; ++l) check_level(read_level(tmp.file("a/lod" + std::to_string(l) + ".ply")), "sphere");
    fs::remove_all(tmp.path() / "a");
    fs::remove_all(tmp.path() / "b");
  }
}

// ---- default levels ----

TEST(SimplifyDefaults, RepresentativeIsQuadric) {
  // Chosen by measurement: lowest Hausdorff mean in 63 of 70 levels (README, "quality of floating cells").
  EXPECT_EQ(SimplifyOptions{}.representative, Representative::quadric);
  test::TempDir tmp;
  const test::CliRun r = test::run_cli({"simplify", sample_room(), "-o", tmp.file("out"), "--progress", "none"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto m = nlohmann::json::parse(slurp(tmp.path() / "out" / "manifest.json"));
  EXPECT_EQ(m["options"]["representative"], "quadric");
}

// Default levels (SimplifyOptions::levels = 0) stop where the counts stop falling: every level has
// triangles, each fewer than the level before, cell sizes increase, and the notice (and the manifest's
// levels_asked / levels_made / notice) says when fewer than default_levels levels were made.
void check_default_levels(const SimplifyReport& r, const std::string& out_dir, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_FALSE(r.levels.empty());
  EXPECT_LE(r.levels.size(), default_levels);
  EXPECT_EQ(r.levels_asked, default_levels);
  uint64_t previous = UINT64_MAX;
  double previous_size = 0;
  for (size_t l = 0; l < r.levels.size(); ++l) {
    const LevelStats& ls = r.levels[l];
    EXPECT_GT(ls.triangles, 0u) << l;
    EXPECT_LT(ls.triangles, previous) << l;
    EXPECT_GT(ls.cell_size, previous_size) << l;
    previous = ls.triangles;
    previous_size = ls.cell_size;
    const Level level = read_level(out_dir + "/lod" + std::to_string(l) + ".ply");
    check_level(level, what);
    EXPECT_EQ(level.triangles.size(), ls.triangles) << l;
  }
  EXPECT_EQ(r.notice.empty(), r.levels.size() == default_levels) << r.notice;
  const Json m = manifest(out_dir);
  EXPECT_EQ(m["levels_asked"], default_levels);
  EXPECT_EQ(m["levels_made"], r.levels.size());
  EXPECT_EQ(m.contains("notice"), !r.notice.empty());
  if (m.contains("notice")) {
    EXPECT_EQ(m["notice"], r.notice);
  }
}

std::vector<uint64_t> triangle_counts(const SimplifyReport& r) {
  std::vector<uint64_t> t;
  for (const LevelStats& ls : r.levels) t.push_back(ls.triangles);
  return t;
}

std::string small_model(const std::string& name) { return test::source_dir() + "/tests/data/small/" + name; }

// Four regular tetrahedra of edge 2·sqrt(2), 8 apart: 16 triangles. The estimate's finest cell (for 8
// triangles) is larger than a tetrahedron, so at that size every one collapses to a point.
std::string tetrahedra16() {
  std::string text;
  for (int k = 0; k < 4; ++k)
    text += fmt::format("v {0} 1 1\nv {0} -1 -1\nv {1} 1 -1\nv {1} -1 1\n", 8 * k + 1, 8 * k - 1);
  for (int k = 0; k < 4; ++k) {
    const int b = 4 * k + 1;
    text += fmt::format("f {0} {1} {2}\nf {0} {3} {1}\nf {0} {2} {3}\nf {1} {3} {2}\n", b, b + 1, b + 2, b + 3);
  }
  return text;
}

// A ridge roof of 4 x 2 quads: 15 vertices, 16 triangles.
std::string roof16() {
  std::string text;
  for (int j = 0; j <= 2; ++j)
    for (int i = 0; i <= 4; ++i) text += fmt::format("v {} {} {}\n", i, j, j == 1 ? 1 : 0);
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 4; ++i) {
      const int a = j * 5 + i + 1, b = a + 1, c = a + 6, d = a + 5;
      text += fmt::format("f {} {} {}\nf {} {} {}\n", a, b, c, a, c, d);
    }
  return text;
}

TEST(SimplifyDefaults, SmallInputsStopWhereCountsStopFalling) {
  // Before: five levels whatever the counts, e.g. 2, 2, 2, 0, 0 triangles for the tatami, and none in any
  // level for the four tetrahedra. Now the finest level has triangles (its cell size searched for when the
  // estimate leaves none: the tetrahedra) and a level is left out when it has none or no fewer than the one
  // before. Exact counts: they are the rule's outcome on these inputs, and a change to it shows here.
  test::TempDir tmp;
  struct Case {
    std::string name, path;
    std::vector<uint64_t> triangles;
  };
  const std::vector<Case> cases = {
      {"one", tmp.write("one.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), {1}},
      {"two", tmp.write("two.obj", kTwoTriangles), {2}},
      {"roof16", tmp.write("roof16.obj", roof16()), {3}},
      {"tetrahedra16", tmp.write("tetrahedra16.obj", tetrahedra16()), {16}},
      {"sphere", tmp.write("sphere.obj", obj_text({dyadic_sphere(6, 4)})), {270, 168, 48, 41, 8}},  // 432 triangles
      {"tatami", small_model("tatami.obj"), {2}},
      {"ammoBox", small_model("ammoBox.obj"), {28, 24, 4}},
      {"bedsideTable2", small_model("bedsideTable2.obj"), {75, 40, 12}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    SimplifyOptions so = make_simplify(tmp.file("out-" + c.name));
    SimplifyReport report;
    if (!simplify_ok(c.path, so, make_options(1), &report)) continue;  // reported; try the next
    check_default_levels(report, so.output_dir, c.name);
    EXPECT_EQ(triangle_counts(report), c.triangles);
  }
}

TEST(SimplifyDefaults, InputsWithoutTrianglesAreCountedByEdgesAndPoints) {
  // Levels aim at the input's segments and points (before: at one primitive, so every level was one edge),
  // and are kept while edges + points fall.
  test::TempDir tmp;
  std::string zigzag;
  for (int i = 0; i <= 64; ++i) zigzag += fmt::format("v {} {} 0\n", i, i % 2);
  zigzag += "l";
  for (int i = 1; i <= 65; ++i) zigzag += fmt::format(" {}", i);
  zigzag += "\n";
  struct Case {
    std::string name, text;
    std::vector<uint64_t> edges, points;
    std::string notice;
  };
  const std::vector<Case> cases = {
      {"zigzag", zigzag, {10, 7, 5, 3, 2}, {0, 0, 0, 0, 0}, ""},
      {"two-segments", "v 0 0 0\nv 1 0 0\nv 1 1 0\nl 1 2 3\n", {2, 0}, {0, 1},
       "made 2 levels, not the 5 asked: a level with no edges or points, or no fewer than the level before, is left "
       "out (edges and points per level at the estimated cell sizes: 2, 1, 1, 1, 1)"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    SimplifyOptions so = make_simplify(tmp.file(c.name));
    SimplifyReport report;
    ASSERT_TRUE(simplify_ok(tmp.write(c.name + ".obj", c.text), so, make_options(1), &report));
    std::vector<uint64_t> edges, points;
    for (const LevelStats& ls : report.levels) {
      EXPECT_EQ(ls.triangles, 0u);
      edges.push_back(ls.edges);
      points.push_back(ls.points);
    }
    EXPECT_EQ(edges, c.edges);
    EXPECT_EQ(points, c.points);
    EXPECT_EQ(report.notice, c.notice);
  }
}

TEST(SimplifyDefaults, TheNoticeNamesTheCounts) {
  test::TempDir tmp;
  SimplifyOptions so = make_simplify(tmp.file("out"));
  SimplifyReport report;
  ASSERT_TRUE(simplify_ok(small_model("ammoBox.obj"), so, make_options(1), &report));
  EXPECT_EQ(report.notice,
            "made 3 levels, not the 5 asked: a level with no triangles, or no fewer than the level before, is left out "
            "(triangles per level at the estimated cell sizes: 28, 24, 4, 0, 0)");
}

TEST(SimplifyDefaults, ExplicitLevelsAndSizesAreHonoured) {
  test::TempDir tmp;
  // --levels 5: five levels, empty and repeated ones included, as estimated: the ammo box's finest level
  // has triangles at its estimated size, so nothing is searched.
  {
    SimplifyOptions so = make_simplify(tmp.file("ammo5"));
    so.levels = 5;
    SimplifyReport report;
    ASSERT_TRUE(simplify_ok(small_model("ammoBox.obj"), so, make_options(1), &report));
    EXPECT_EQ(triangle_counts(report), (std::vector<uint64_t>{28, 24, 4, 0, 0}));
    EXPECT_EQ(report.levels_asked, 5u);
    EXPECT_TRUE(report.notice.empty()) << report.notice;
    EXPECT_EQ(manifest(so.output_dir)["levels_made"], 5);
  }
  // --levels 3 where the estimate leaves the finest level empty: still three levels, the finest searched
  // for (the coarser two stay at their estimated sizes, where each tetrahedron is a point).
  {
    SimplifyOptions so = make_simplify(tmp.file("tetra3"));
    so.levels = 3;
    SimplifyReport report;
    ASSERT_TRUE(simplify_ok(tmp.write("tetrahedra16.obj", tetrahedra16()), so, make_options(1), &report));
    EXPECT_EQ(triangle_counts(report), (std::vector<uint64_t>{16, 0, 0}));
    ASSERT_EQ(report.levels.size(), 3u);
    EXPECT_EQ(report.levels[2].points, 4u);
    EXPECT_TRUE(report.notice.empty()) << report.notice;
    // Each point replaces one regular tetrahedron whose corners are sqrt(3) from their mean: its size (the
    // diameter of what it replaces, twice the mean corner distance) is 2 sqrt(3).
    const Level l2 = read_level(so.output_dir + "/lod2.ply");
    ASSERT_TRUE(l2.ok);
    ASSERT_EQ(l2.point_size.size(), 4u);
    for (float size : l2.point_size) EXPECT_NEAR(size, 2 * std::sqrt(3.0), 1e-5);
  }
  // --cell-sizes: exactly those, even a level collapsed to one point.
  {
    SimplifyOptions so = make_simplify(tmp.file("sizes"));
    so.cell_sizes = {1, 1000};
    SimplifyReport report;
    ASSERT_TRUE(simplify_ok(small_model("ammoBox.obj"), so, make_options(1), &report));
    ASSERT_EQ(report.levels.size(), 2u);
    EXPECT_EQ(report.levels[0].cell_size, 1);
    EXPECT_EQ(report.levels[1].cell_size, 1000);
    EXPECT_EQ(report.levels[1].triangles, 0u);
    EXPECT_EQ(report.levels[1].points, 1u);
    EXPECT_EQ(report.levels_asked, 2u);
    EXPECT_TRUE(report.notice.empty()) << report.notice;
  }
}

TEST(SimplifyDefaults, SettledLevelsHaveTheSameBytesForAnyThreadsMemoryAndChunks) {
  // The tetrahedra's finest size is searched for and the ammo box's levels cut short, from counts that must not
  // depend on how the work is split.
  test::TempDir tmp;
  const std::vector<std::pair<std::string, std::string>> inputs = {
      {"tetrahedra16", tmp.write("tetrahedra16.obj", tetrahedra16())}, {"ammoBox", small_model("ammoBox.obj")}};
  for (const auto& [name, path] : inputs) {
    SCOPED_TRACE(name);
    SimplifyOptions a = make_simplify(tmp.file(name + "-a")), b = make_simplify(tmp.file(name + "-b"));
    ASSERT_TRUE(simplify_ok(path, a, make_options(1)));
    ASSERT_TRUE(simplify_ok(path, b, make_options(2, min_memory_bytes, 1)));
    expect_same_output(a.output_dir, b.output_dir, name);
    EXPECT_EQ(manifest_without_timings(a.output_dir), manifest_without_timings(b.output_dir));
  }
}

// ---- 3: seam vertices ----
// The cube corner's grade (cos 45°·Lmax) is covered by GradeKernel.CubeCornerIsCos45 in test_grade.cpp.

TEST(SimplifySeams, AnyGradeRangeSizeGivesTheSameBytes) {
  // A sphere whose faces are shuffled, and vertex 0's triangles moved to the very first and very last
  // place: every vertex's incident triangles lie far apart in the file and in the store, so small grading
  // ranges make most vertices seam vertices. Mean representatives weigh positions by grade, so the bytes
  // depend on the exact grade values, not only on their order.
  // 218 vertices: few enough that one vertex per range is possible (the grade stage caps the number of
  // ranges, so on a large mesh tiny grade_range_vertices values are raised).
  Mesh m = dyadic_sphere(6, 4);
  ASSERT_EQ(m.v.size(), 218u);
  std::mt19937 rng(5);
  for (size_t i = m.f.size() - 1; i > 0; --i) std::swap(m.f[i], m.f[rng() % (i + 1)]);
  std::vector<size_t> of0;
  for (size_t i = 0; i < m.f.size(); ++i)
    if (std::count(m.f[i].begin(), m.f[i].end(), 0u)) of0.push_back(i);
  ASSERT_GE(of0.size(), 2u);
  std::swap(m.f[0], m.f[of0.front()]);
  std::swap(m.f.back(), m.f[of0.back()]);
  ASSERT_TRUE(std::count(m.f.front().begin(), m.f.front().end(), 0u) && std::count(m.f.back().begin(), m.f.back().end(), 0u));

  test::TempDir tmp;
  const std::string input = tmp.write("shuffled.obj", obj_text({m}));
  for (Representative rep : {Representative::center, Representative::mean}) {
    std::vector<uint64_t> ranges;
    for (uint64_t size : {uint64_t{0}, uint64_t{1}, uint64_t{2}, uint64_t{3}, uint64_t{5}, uint64_t{1000}}) {
      SimplifyOptions so = make_simplify(tmp.file(fmt::format("r{}", size)));
      so.representative = rep;
      so.cell_sizes = {0.75, 1.5, 3};
      so.write_obj = true;
      so.grade_range_vertices = size;
      SimplifyReport report;
      ASSERT_TRUE(simplify_ok(input, so, make_options(2, 0, 512), &report));
      ranges.push_back(report.grade_ranges);
      if (size) expect_same_output(tmp.path() / "r0", so.output_dir, "grade_range_vertices " + std::to_string(size));
    }
    // The option did what it says: ranges of k vertices, ceil(218 / k) of them.
    EXPECT_EQ(ranges, (std::vector<uint64_t>{1, 218, 109, 73, 44, 1}));
    for (const char* d : {"r0", "r1", "r2", "r3", "r5", "r1000"}) fs::remove_all(tmp.path() / d);
  }
}

// ---- 4: Low & Tan Figure 4 (§3.2.3) ----

TEST(SimplifyFigure4, NearestKeepsTheThinTriangleThinHeaviestWidensIt) {
  // Cube cells of side c = 2 (a cell reaches 1 from its center on each axis). In the plane z = 0:
  //   T = (A, B, V3), A = (-8, 0), B = (8, 0), V3 = (0, 0.25): a thin triangle, 16 long, 0.25 high.
  //   V1 = (-0.75, 1.125): heavy (a triangle with two far vertices 16 above it: grade ≈ 16).
  //   V2 = (0.25, 0.0625): less heavy (a triangle with two vertices 8 below it: grade ≈ 8).
  // V2 − V1 = (1, -1.0625): V2 is outside V1's cell, so it centers its own.
  // V3 has grade ≈ 0.25 (nearly flat: its edges to A and B are almost opposite), so it comes last, and
  // lies in both cells: V3 − V1 = (0.75, -0.875), V3 − V2 = (-0.25, 0.1875); squared distances 1.328 and
  // 0.098. Heaviest puts V3 with V1, nearest with V2. With center representatives T becomes
  // (A, B, V1): 1.125 high, 4.5 times wider; or (A, B, V2): 0.0625 high, still thin.
  const P3 A{-8, 0, 0}, B{8, 0, 0}, V3{0, 0.25, 0}, V1{-0.75, 1.125, 0}, F1{-2.75, 17.125, 0}, G1{1.25, 17.125, 0},
      V2{0.25, 0.0625, 0}, F2{-1.75, -8, 0}, G2{2.25, -8, 0};
  Mesh m;
  m.v = {A, B, V3, V1, F1, G1, V2, F2, G2};
  m.f = {{0, 1, 2}, {3, 5, 4}, {6, 7, 8}};

  // The grade order the configuration relies on.
  auto grade_of = [&](uint32_t v) {
    std::vector<double> nb;
    for (const auto& t : m.f)
      if (std::count(t.begin(), t.end(), v))
        for (uint32_t u : t)
          if (u != v) nb.insert(nb.end(), m.v[u].begin(), m.v[u].end());
    core::GradeScratch scratch;
    return core::grade_vertex(std::span<const double, 3>(m.v[v]), nb, core::Grading::lowtan, scratch).grade;
  };
  const double g1 = grade_of(3), g2 = grade_of(6), g3 = grade_of(2);
  ASSERT_GT(g1, g2);
  ASSERT_GT(g2, g3);
  EXPECT_NEAR(g1, 16, 0.2);
  EXPECT_NEAR(g2, 8, 0.1);
  EXPECT_NEAR(g3, 0.25, 0.01);

  test::TempDir tmp;
  const std::string input = tmp.write("figure4.obj", obj_text({m}));
  auto f3 = [](const P3& p) { return F3{float(p[0]), float(p[1]), float(p[2])}; };
  for (CellVariant variant : {CellVariant::nearest, CellVariant::heaviest}) {
    const bool nearest = variant == CellVariant::nearest;
    SCOPED_TRACE(nearest ? "nearest" : "heaviest");
    SimplifyOptions so = make_simplify(tmp.file(nearest ? "nearest" : "heaviest"));
    so.cell_sizes = {2};
    so.variant = variant;
    so.representative = Representative::center;
    SimplifyReport report;
    ASSERT_TRUE(simplify_ok(input, so, make_options(1), &report));
    ASSERT_EQ(report.levels.size(), 1u);
    EXPECT_EQ(report.levels[0].cells, 8u);  // every vertex but V3 centers a cell
    const Level l = read_level(so.output_dir + "/lod0.ply");
    check_level(l, "figure 4");
    EXPECT_TRUE(l.edges.empty());
    EXPECT_TRUE(l.points.empty());
    // The three triangles, corners in input order (winding kept), exactly at input positions.
    const P3 apex = nearest ? V2 : V1;
    Level expected;
    expected.positions = {f3(A), f3(B), f3(apex), f3(V1), f3(G1), f3(F1), f3(V2), f3(F2), f3(G2)};
    expected.triangles = {{0, 1, 2}, {3, 4, 5}, {6, 7, 8}};
    EXPECT_EQ(sorted_triangles(l), sorted_triangles(expected));
    // T's height over its 16-long base.
    for (const auto& t : l.triangles) {
      const TriKey k = tri_key(l, t);
      if (k[0] == f3(A) && k[1] == f3(B)) {
        EXPECT_EQ(k[2][1], nearest ? 0.0625f : 1.125f);
      }
    }
  }
}

// ---- 5: Low & Tan Plate 5 (§3.2.2): consistency ----

std::vector<TriKey> triangles_below_x(const Level& l, float x_max) {
  std::vector<TriKey> out;
  for (const auto& t : l.triangles) {
    const TriKey k = tri_key(l, t);
    if (k[0][0] < x_max && k[1][0] < x_max && k[2][0] < x_max) out.push_back(k);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(SimplifyPlate5, DistantObjectChangesNothingTranslationOnlyUnderFloatingCells) {
  // Object A: a sphere of radius 4 at the origin (6912 triangles); object B: another sphere 64 to the +x,
  // after A in the file (56 units apart: many cell sizes). Cell sizes 0.5 and 1.25.
  const Mesh a = dyadic_sphere(24, 4, {0, 0, 0});
  const Mesh b = dyadic_sphere(20, 3.5, {64, 0.5, -0.25});
  const P3 offset{0.3125, 0.3125, 0.3125};  // not a multiple of either cell size
  const Mesh a_moved = translated(a, offset);
  test::TempDir tmp;
  const std::string alone = tmp.write("alone.obj", obj_text({a}));
  const std::string both = tmp.write("both.obj", obj_text({a, b}));
  const std::string moved = tmp.write("moved.obj", obj_text({a_moved}));

  for (Clustering clustering : {Clustering::floating, Clustering::uniform}) {
    const bool floating = clustering == Clustering::floating;
    for (CellVariant variant : {CellVariant::nearest, CellVariant::heaviest}) {
      if (!floating && variant == CellVariant::heaviest) continue;  // the variant is for floating cells only
      const std::string tag = std::string(floating ? "floating" : "uniform") + (variant == CellVariant::nearest ? "-nearest" : "-heaviest");
      SCOPED_TRACE(tag);
      auto run = [&](const std::string& input, const std::string& name) {
        SimplifyOptions so = make_simplify(tmp.file(tag + "-" + name));
        so.clustering = clustering;
        so.variant = variant;
        so.cell_sizes = {0.5, 1.25};
        so.representative = Representative::center;
        EXPECT_TRUE(simplify_ok(input, so, make_options(2)));
        return so.output_dir;
      };
      const std::string d_alone = run(alone, "alone"), d_both = run(both, "both"), d_moved = run(moved, "moved");
      for (int lv = 0; lv < 2; ++lv) {
        SCOPED_TRACE("level " + std::to_string(lv));
        const std::string f = "/lod" + std::to_string(lv) + ".ply";
        const Level la = read_level(d_alone + f), lb = read_level(d_both + f), lm = read_level(d_moved + f);
        ASSERT_TRUE(la.ok && lb.ok && lm.ok);
        const std::vector<TriKey> ta = triangles_below_x(la, 32);
        ASSERT_EQ(ta.size(), la.triangles.size());
        ASSERT_GT(ta.size(), 50u);
        // A distant object changes nothing (both modes: the uniform grid is anchored at the origin).
        const std::vector<TriKey> tb = triangles_below_x(lb, 32);
        EXPECT_EQ(ta.size(), tb.size());
        EXPECT_TRUE(ta == tb) << "A's triangles changed when B was added";
        EXPECT_GT(lb.triangles.size(), tb.size());  // B has triangles of its own
        // Translating A by a non-grid offset: floating cells move with it, the uniform grid does not.
        std::vector<TriKey> shifted = ta;
        for (TriKey& k : shifted)
          for (F3& p : k)
            for (int c = 0; c < 3; ++c) p[c] += static_cast<float>(offset[c]);  // exact: dyadic
        std::sort(shifted.begin(), shifted.end());
        const std::vector<TriKey> tm = sorted_triangles(lm);
        if (floating) {
          EXPECT_TRUE(tm == shifted) << "floating cells: the translated object simplifies differently ("
                                     << tm.size() << " vs " << shifted.size() << " triangles)";
        } else {
          EXPECT_FALSE(tm == shifted) << "uniform cells: expected the grid to cut the translated object differently";
        }
      }
    }
  }
}

// ---- 7: errors through the CLI ----

using test::CliRun;
using test::run_cli;

// Regular files under `dir`, recursively, relative names.
std::vector<std::string> files_under(const fs::path& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  if (!fs::exists(dir, ec)) return out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out.push_back(fs::relative(e.path(), dir).string());
  std::sort(out.begin(), out.end());
  return out;
}

TEST(SimplifyCli, ExitCodes) {
  test::TempDir tmp;
  const std::string obj = tmp.write("t.obj", kTwoTriangles);
  const std::string out = tmp.file("out");
  struct Case {
    std::vector<std::string> args;
    int exit_code;
  };
  const std::vector<Case> cases = {
      {{"simplify", tmp.file("missing.obj"), "-o", out}, 66},
      {{"simplify", tmp.path().string(), "-o", out}, 66},  // a directory
      {{"simplify", obj, "-o", out, "--cell-sizes", "2,1"}, 64},
      {{"simplify", obj, "-o", out, "--cell-sizes", "1,1"}, 64},
      {{"simplify", obj, "-o", out, "--cell-sizes", "0"}, 64},
      {{"simplify", obj, "-o", out, "--cell-sizes", "-1"}, 64},
      {{"simplify", obj, "-o", out, "--cell-sizes", "1,x"}, 64},
      {{"simplify", obj, "-o", out, "--target-triangles", "10,100"}, 64},
      {{"simplify", obj, "-o", out, "--target-triangles", "0"}, 64},
      {{"simplify", obj, "-o", out, "--cell-sizes", "1", "--target-triangles", "10"}, 64},
      {{"simplify", obj, "-o", out, "--levels", "0"}, 64},
      {{"simplify", obj, "-o", out, "--variant", "lightest"}, 64},
      {{"simplify", obj, "-o", out, "--no-ply", "--no-glb"}, 64},
      {{"simplify", obj}, 64},  // no -o
      {{"simplify", tmp.write("only-v.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"), "-o", out}, 65},
      {{"simplify", tmp.write("bad.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\n"), "-o", out}, 65},
  };
  for (const Case& c : cases) {
    std::string cmd;
    for (const auto& a : c.args) cmd += a + " ";
    const CliRun r = run_cli(c.args, tmp);
    EXPECT_EQ(r.exit_code, c.exit_code) << cmd << "\n" << r.err;
    EXPECT_FALSE(r.err.empty()) << cmd;
    EXPECT_TRUE(files_under(out).empty()) << cmd << ": left " << files_under(out).front();
  }
  const CliRun ok = run_cli({"simplify", obj, "-o", out, "--cell-sizes", "0.5,4"}, tmp);
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_EQ(files_under(out), (std::vector<std::string>{"lod0.ply", "lod1.ply", "lods.glb", "manifest.json"}));
}

// ---- progress and cancellation (item 7) ----

TEST(SimplifyCli, ProgressJsonHasOneLinePerStepAndEveryStageFinishes) {
  test::TempDir tmp;
  const std::string out = tmp.file("out");
  const CliRun r = run_cli({"simplify", sample_room(), "-o", out, "--progress", "json"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::map<std::string, double> last;
  std::vector<std::string> order;
  std::istringstream lines(r.err);
  for (std::string line; std::getline(lines, line);) {
    const Json j = Json::parse(line);  // every stderr line is one JSON object
    const std::string stage = j.at("stage");
    const double f = j.at("fraction");
    EXPECT_GE(f, 0.0) << line;
    EXPECT_LE(f, 1.0) << line;
    if (last.count(stage)) {
      EXPECT_GE(f, last[stage]) << line;  // never goes back within a stage
    } else {
      order.push_back(stage);
    }
    last[stage] = f;
  }
  for (const char* stage : {"ingest", "grade", "sort", "cluster", "emit", "write"}) {
    ASSERT_TRUE(last.count(stage)) << stage << " never reported";
    EXPECT_EQ(last[stage], 1.0) << stage << " did not finish";
  }
  EXPECT_EQ(order.front(), "ingest");
  EXPECT_EQ(order.back(), "write");
}

TEST(SimplifyCli, QuietWhenNotATerminal) {
  test::TempDir tmp;
  const CliRun r = run_cli({"simplify", tmp.write("t.obj", kTwoTriangles), "-o", tmp.file("out"), "--cell-sizes", "0.5"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");  // --progress auto and stderr is a file
}

TEST(SimplifyCli, NoticeWhenFewerLevelsAreMadeThanAsked) {
  test::TempDir tmp;
  const std::string input = test::source_dir() + "/tests/data/small/ammoBox.obj";
  const std::string notice =
      "notice: made 3 levels, not the 5 asked: a level with no triangles, or no fewer than the level before, is left "
      "out (triangles per level at the estimated cell sizes: 28, 24, 4, 0, 0)\n";
  const CliRun table = run_cli({"simplify", input, "-o", tmp.file("table"), "--progress", "none"}, tmp);
  ASSERT_EQ(table.exit_code, 0) << table.err;
  EXPECT_EQ(table.err, notice);
  const CliRun json = run_cli({"simplify", input, "-o", tmp.file("json"), "--progress", "none", "--json"}, tmp);
  ASSERT_EQ(json.exit_code, 0) << json.err;
  EXPECT_EQ(json.err, notice);
  const Json m = Json::parse(json.out);
  EXPECT_EQ(m["levels_asked"], 5);
  EXPECT_EQ(m["levels_made"], 3);
  EXPECT_EQ(m["levels"].size(), 3u);
  EXPECT_EQ(m["notice"], notice.substr(8, notice.size() - 9));
  // Asked for exactly: no notice.
  for (const std::vector<std::string>& extra : {std::vector<std::string>{"--levels", "5"}, {"--cell-sizes", "1,2,4,8,16"}}) {
    std::vector<std::string> args{"simplify", input, "-o", tmp.file("exact"), "--progress", "none"};
    args.insert(args.end(), extra.begin(), extra.end());
    const CliRun r = run_cli(args, tmp);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err, "") << extra[0];
    EXPECT_EQ(manifest(tmp.path() / "exact")["levels_made"], 5) << extra[0];
  }
}

TEST(SimplifyApi, CancellingFromTheCallbackReturnsCancelledAndWritesNoManifest) {
  // Cancels at the n-th progress call for several n, so that every stage gets cancelled somewhere.
  for (int cancel_at : {1, 5, 20, 60, 200}) {
    test::TempDir tmp;
    struct Counter {
      int calls = 0, limit = 0;
    } counter{0, cancel_at};
    Options options;
    options.progress = [](void* user, const char*, double) {
      auto* c = static_cast<Counter*>(user);
      return ++c->calls < c->limit;
    };
    options.progress_user = &counter;
    SimplifyOptions so;
    so.output_dir = tmp.file("out");
    SimplifyReport report;
    const Result r = simplify(sample_room(), so, options, &report);
    if (r.ok()) {
      EXPECT_LT(counter.calls, cancel_at) << "ran to the end although the callback said stop";
      continue;
    }
    EXPECT_EQ(r.status, Status::cancelled) << cancel_at << ": " << r.message;
    for (const std::string& f : files_under(tmp.file("out"))) {
      EXPECT_NE(f, "manifest.json") << cancel_at;
      EXPECT_EQ(f.find(".partial"), std::string::npos) << cancel_at << ": left " << f;
    }
  }
}

TEST(SimplifyCli, OutputDirectoryThatCannotBeCreatedExits74AndLeavesNothing) {
  test::TempDir tmp;
  const std::string obj = tmp.write("t.obj", kTwoTriangles);
  const std::string blocker = tmp.write("blocker", "a regular file\n");
  const CliRun r = run_cli({"simplify", obj, "-o", blocker + "/out", "--obj", "--cell-sizes", "0.5,4"}, tmp);
  EXPECT_EQ(r.exit_code, 74) << r.err;
  EXPECT_NE(r.err.find(blocker), std::string::npos) << r.err;
  EXPECT_EQ(slurp(blocker), "a regular file\n");
  for (const std::string& f : files_under(tmp.path()))
    EXPECT_TRUE(f == "t.obj" || f == "blocker" || f == "stdout" || f == "stderr") << "left behind: " << f;
}

TEST(SimplifyCli, UnwritableGlbExits74WithoutManifestOrPartialFiles) {
  // lods.glb is a directory: the write stage fails after the PLY files. The manifest, which marks a
  // complete output directory, must not appear, and no temporary may be left.
  test::TempDir tmp;
  const std::string obj = tmp.write("t.obj", kTwoTriangles);
  const std::string out = tmp.file("out");
  fs::create_directories(out + "/lods.glb/x");
  const CliRun r = run_cli({"simplify", obj, "-o", out, "--cell-sizes", "0.5"}, tmp);
  EXPECT_EQ(r.exit_code, 74) << r.err;
  EXPECT_FALSE(fs::exists(out + "/manifest.json"));
  for (const std::string& f : files_under(out)) {
    EXPECT_EQ(f.find(".partial"), std::string::npos) << "left behind: " << f;
    EXPECT_NE(f, "manifest.json");
  }
}

TEST(SimplifyCli, GlbScratchFileIsGoneAfterTheRun) {
  // The GLB's binary data is gathered level by level in a scratch file beside it in the output directory
  // (io::GlbBuilder; not in the work directory, whose size it would add to): gone after the run, and after
  // a run whose GLB cannot be written.
  test::TempDir tmp;
  const std::string obj = tmp.write("t.obj", kTwoTriangles);
  const std::string out = tmp.file("out"), bad = tmp.file("bad"), work = tmp.file("work");
  auto scratch_left = [&] {
    std::vector<std::string> left;
    for (const std::string& dir : {work, out, bad})
      for (const std::string& f : files_under(dir))
        if (f.find("scratch") != std::string::npos || f.find(".partial") != std::string::npos) left.push_back(f);
    return left;
  };
  const CliRun ok = run_cli({"simplify", obj, "-o", out, "--work", work, "--cell-sizes", "0.5,4"}, tmp);
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(fs::exists(out + "/lods.glb"));
  EXPECT_TRUE(scratch_left().empty()) << scratch_left().front();
  fs::create_directories(bad + "/lods.glb/x");
  const CliRun r = run_cli({"simplify", obj, "-o", bad, "--work", work, "--cell-sizes", "0.5,4"}, tmp);
  EXPECT_EQ(r.exit_code, 74) << r.err;
  EXPECT_TRUE(scratch_left().empty()) << scratch_left().front();
}

TEST(SimplifyCli, DiskFullWhileWritingLevelsExits74AndLeavesNoPartialFile) {
  test::TempDir tmp;
  const std::string mnt = tmp.file("tiny");
  fs::create_directories(mnt);
  if (geteuid() != 0 || mount("tmpfs", mnt.c_str(), "tmpfs", 0, "size=2m") != 0)
    GTEST_SKIP() << "skipped: cannot mount a small tmpfs here (needs root)";
  // lod0.ply of the room is about 3 MB: the first level does not fit (past the free-space check).
  const CliRun r =
      run_cli({"simplify", sample_room(), "-o", mnt + "/out", "--work", tmp.file("work"), "--no-space-check"}, tmp);
  const std::vector<std::string> left = files_under(mnt);
  umount(mnt.c_str());
  EXPECT_EQ(r.exit_code, 74) << r.err;
  EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
  for (const std::string& f : left) {
    EXPECT_EQ(f.find(".partial"), std::string::npos) << "left behind: " << f;
    EXPECT_NE(f, "out/manifest.json");
  }
}

TEST(SimplifyCli, CellsBeyondTheMemoryBudgetExit64AndTheRunResumesWithMore) {
  // A 1000 × 1000 grid of spacing 1 (binary PLY) whose finest cells (0.5) are smaller than its spacing:
  // 1,000,000 cells, whose tables and records need more than --memory 64M leaves them. The estimate made
  // before the cluster stage says so at once (exit 64, one line with the figures): the stage never starts,
  // nothing is written to the output, and the stages done before it are reused when the same command runs
  // again with more memory.
  test::TempDir tmp;
  constexpr uint32_t n = 1000;
  std::string ply = fmt::format("ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n"
                                "property float y\nproperty float z\nelement face {}\n"
                                "property list uchar int vertex_indices\nend_header\n", n * n, 2 * (n - 1) * (n - 1));
  std::vector<float> xyz;
  for (uint32_t y = 0; y < n; ++y)
    for (uint32_t x = 0; x < n; ++x) xyz.insert(xyz.end(), {float(x), float(y), float((x * 7 + y * 13) % 16) * 0.0625f});
  ply.append(reinterpret_cast<const char*>(xyz.data()), xyz.size() * sizeof(float));
  for (uint32_t y = 0; y + 1 < n; ++y)
    for (uint32_t x = 0; x + 1 < n; ++x) {
      const int32_t a = static_cast<int32_t>(y * n + x), tri[2][3] = {{a, a + 1, a + int32_t{n}}, {a + 1, a + int32_t{n} + 1, a + int32_t{n}}};
      for (const auto& t : tri) {
        ply.push_back(3);
        ply.append(reinterpret_cast<const char*>(t), sizeof t);
      }
    }
  const std::string input = tmp.write("grid.ply", ply);
  const std::string out = tmp.file("out"), work = tmp.file("work");
  const std::vector<std::string> args{"simplify", input, "-o", out, "--work", work, "--cell-sizes", "0.5,8",
                                      "--no-glb", "--progress", "none"};
  std::vector<std::string> small = args, large = args;
  small.insert(small.end(), {"--memory", "64M"});
  large.insert(large.end(), {"--memory", "1G"});
  const CliRun r = run_cli(small, tmp);
  EXPECT_EQ(r.exit_code, 64) << r.err;
  EXPECT_NE(r.err.find("clustering would need more memory than --memory allows (estimated cells per level: 1000000, "),
            std::string::npos) << r.err;
  EXPECT_TRUE(files_under(out).empty()) << "left " << files_under(out).front();
  for (const std::string& f : files_under(work)) EXPECT_EQ(f.find("cells-"), std::string::npos) << "the stage ran: " << f;
  const CliRun ok = run_cli(large, tmp);
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  const Json m = manifest(out);
  EXPECT_EQ(m["levels"][0]["cells"], n * n);
  for (const Json& st : m["stages"]) {
    if (st["name"] == "ingest" || st["name"] == "grade") {
      EXPECT_TRUE(st["reused"].get<bool>()) << st;
    }
  }
}

TEST(SimplifyCli, EveryStageStaysUnderTheMinimumBudget) {
  // The memory contract on the sample room, run as its own process (VmHWM is per process): at --memory 64M
  // every stage's peak in the manifest, mapped pages included, is at most 64 MiB.
  test::TempDir tmp;
  const std::string out = tmp.file("out");
  const CliRun r = run_cli({"simplify", sample_room(), "-o", out, "--memory", "64M", "--progress", "none"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json m = manifest(out);
  ASSERT_EQ(m["stages"].size(), 5u);
  for (const Json& st : m["stages"]) {
    EXPECT_GT(st["peak_rss_bytes"].get<uint64_t>(), 0u) << st;
    EXPECT_LE(st["peak_rss_bytes"].get<uint64_t>(), uint64_t{64} << 20) << st;
  }
}

TEST(SimplifyCli, FourMillionVerticesWeldUnderTheSmallestBudget) {
  // 4 million stored vertices (binary PLY, one triangle), every position twice. A weld that held a
  // canonical id per vertex (16 MiB) with its key batches did not fit what --memory 64M leaves a stage;
  // the weld now holds 1/8 byte a vertex and sorts the welded pairs, so the file simplifies under the cap.
  // (The floor's refusal is tested in test_distinct_count.cpp: no test file is large enough to reach it.)
  test::TempDir tmp;
  constexpr uint32_t n = 4'000'000;
  std::string ply = fmt::format("ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n"
                                "property float y\nproperty float z\nelement face 1\n"
                                "property list uchar int vertex_indices\nend_header\n", n);
  std::vector<float> xyz(3 * size_t{n});
  for (uint32_t i = 0; i < n; ++i) xyz[3 * i] = static_cast<float>(i % 1000), xyz[3 * i + 1] = static_cast<float>(i / 2000);
  ply.append(reinterpret_cast<const char*>(xyz.data()), xyz.size() * sizeof(float));
  const unsigned char count = 3;
  const int32_t face[3] = {0, 1, 2000};
  ply.append(reinterpret_cast<const char*>(&count), 1);
  ply.append(reinterpret_cast<const char*>(face), sizeof face);
  const std::string input = tmp.write("points.ply", ply);
  const std::string out = tmp.file("out");
  const CliRun r = run_cli({"simplify", input, "-o", out, "--memory", "64M", "--cell-sizes", "0.5,4", "--progress", "none"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json m = manifest(out);
  for (const Json& st : m["stages"]) EXPECT_LE(st["peak_rss_bytes"].get<uint64_t>(), uint64_t{64} << 20) << st;
  EXPECT_EQ(m["input"]["distinct_positions"].get<uint64_t>(), n / 2) << m["input"];
}

// ---- 8: input lines and points ----

TEST(SimplifyLinesAndPoints, SegmentsBecomeEdgesOrPointsAndCoveredOnesAreEliminated) {
  // Cell size 1 (cells reach 0.5 from their centers). Grades: a segment end has one edge direction, so
  // its grade is its longest edge (θ = 0).
  test::TempDir tmp;
  const std::string input = tmp.write("lines.obj",
                                      "v 0 0 0\n"        // 1  grade 4: center
                                      "v 4 0 0\n"        // 2
                                      "v 0.25 0 0\n"     // 3  grade 0.25: joins 1's cell
                                      "v 20 0 0\n"       // 4  grade 0.25, lower id than 5: center
                                      "v 20.25 0 0\n"    // 5  joins 4
                                      "v 30 0 0\n"       // 6  a lone point
                                      "v 0 10 0\n"       // 7  polyline 7-8-9
                                      "v 4 10 0\n"       // 8
                                      "v 4 14 0\n"       // 9
                                      "v 50 0 0\n"       // 10 triangle
                                      "v 54 0 0\n"       // 11
                                      "v 50 4 0\n"       // 12
                                      "v 0 20 0\n"       // 13 two parallel segments 0.25 apart
                                      "v 4 20 0\n"       // 14
                                      "v 0 20.25 0\n"    // 15
                                      "v 4 20.25 0\n"    // 16
                                      "l 1 2\n"          // edge (0,0,0)-(4,0,0), thickness 0
                                      "l 1 3\n"          // one cell: a point, covered by the edge above
                                      "l 4 5\n"          // one cell: the point (20,0,0)
                                      "p 6\n"            // the point (30,0,0)
                                      "l 7 8 9\n"        // two edges, thickness 0
                                      "f 10 11 12\n"     // a triangle
                                      "l 10 11\n"        // a side of the triangle: eliminated
                                      "p 12\n"           // a triangle corner: covered
                                      "l 13 14\n"        // with 15-16: one edge 0.125 + 0.125 thick
                                      "l 15 16\n");
  SimplifyOptions so = make_simplify(tmp.file("out"));
  so.cell_sizes = {1};
  so.write_obj = true;
  SimplifyReport report;
  ASSERT_TRUE(simplify_ok(input, so, make_options(1), &report));
  EXPECT_EQ(report.scene.lines, 8u);
  EXPECT_EQ(report.scene.points, 2u);
  const Level l = read_level(tmp.file("out/lod0.ply"));
  check_level(l, "lines");
  ASSERT_EQ(l.triangles.size(), 1u);
  EXPECT_EQ(tri_key(l, l.triangles[0]), (TriKey{F3{50, 0, 0}, F3{54, 0, 0}, F3{50, 4, 0}}));
  const std::map<EdgeKey, float> expected_edges = {
      {edge_key({0, 0, 0}, {4, 0, 0}), 0.0f},
      {edge_key({0, 10, 0}, {4, 10, 0}), 0.0f},
      {edge_key({4, 10, 0}, {4, 14, 0}), 0.0f},
      {edge_key({0, 20, 0}, {4, 20, 0}), 0.25f},
  };
  EXPECT_EQ(edges_of(l), expected_edges);
  EXPECT_EQ(points_of(l), (std::set<F3>{F3{20, 0, 0}, F3{30, 0, 0}}));
  ASSERT_EQ(report.levels.size(), 1u);
  EXPECT_EQ(report.levels[0].edges_on_triangles, 1u);
  EXPECT_EQ(report.levels[0].points_covered, 2u);
  const Json m = manifest(tmp.path() / "out");
  EXPECT_EQ(m["levels"][0]["triangles"], 1);
  EXPECT_EQ(m["levels"][0]["edges"], 4);
  EXPECT_EQ(m["levels"][0]["points"], 2);
  EXPECT_EQ(m["levels"][0]["eliminated"]["edges_on_triangles"], 1);
  EXPECT_EQ(m["levels"][0]["eliminated"]["points_covered"], 2);
  // The OBJ has the same primitives: one f, four l, two p.
  const std::string objout = slurp(tmp.file("out/lod0.obj"));
  auto lines_starting = [&](const std::string& prefix) {
    std::istringstream in(objout);
    std::string line;
    int n = 0;
    while (std::getline(in, line)) n += line.rfind(prefix, 0) == 0;
    return n;
  };
  EXPECT_EQ(lines_starting("f "), 1);
  EXPECT_EQ(lines_starting("l "), 4);
  EXPECT_EQ(lines_starting("p "), 2);
}

// ---- 9: thick edges ----

// The one level of `obj` simplified at cell size 2 (one thread), checked as a level.
Level level_at_cell_size_2(const std::string& name, const std::string& obj) {
  test::TempDir tmp;
  const std::string input = tmp.write(name + ".obj", obj);
  SimplifyOptions so = make_simplify(tmp.file("out"));
  so.cell_sizes = {2};
  EXPECT_TRUE(simplify_ok(input, so, make_options(1)));
  const Level l = read_level(tmp.file("out/lod0.ply"));
  check_level(l, name);
  return l;
}

// The thickness of the single edge that `obj` (one thin strip between x = 0 and x = 4) collapses to at
// cell size 2.
float strip_thickness(const std::string& obj) {
  const Level l = level_at_cell_size_2("strip", obj);
  EXPECT_TRUE(l.triangles.empty());
  EXPECT_TRUE(l.points.empty());
  EXPECT_EQ(l.edges.size(), 1u);
  return l.thickness.empty() ? -1.0f : l.thickness[0];
}

TEST(SimplifyThickEdge, TwoTriangleStripHasExactlyItsWidthEitherDiagonal) {
  // A quad 4 long (x) and w = 0.25 wide (y): a0 = (0,0), b0 = (4,0), b1 = (4,w), a1 = (0,w). Cell size 2:
  // the ends fall in two cells A ∋ a0, a1 and B ∋ b0, b1. Over the distinct corners (Low & Tan §3.3.1):
  // P_A = (0, w/2), P_B = (4, w/2); every corner is w/2 from that line: D_A = D_B = w/2, thickness w.
  // Counting a corner once per collapsing triangle would weigh the diagonal's ends twice and give 8w/9
  // (0.2222) with the diagonal a0 b1; the other diagonal, a1 b0, must give the same w.
  const std::string v = "v 0 0 0\nv 4 0 0\nv 4 0.25 0\nv 0 0.25 0\n";
  EXPECT_EQ(strip_thickness(v + "f 1 2 3\nf 1 3 4\n"), 0.25f);  // diagonal a0 b1
  EXPECT_EQ(strip_thickness(v + "f 1 2 4\nf 2 3 4\n"), 0.25f);  // diagonal b0 a1
  // The same quad as one polygon (ingest triangulates it), and as both pairs of triangles overlapping.
  EXPECT_EQ(strip_thickness(v + "f 1 2 3 4\n"), 0.25f);
  EXPECT_EQ(strip_thickness(v + "f 1 2 3\nf 1 3 4\nf 2 3 4\nf 1 2 4\n"), 0.25f);  // both diagonals, overlapping
}

TEST(SimplifyThickEdge, ThreeCornerEndHasHandDerivedThicknessForAnyTriangulation) {
  // End A: a0 = (0,0), a1 = (0,w); end B: b0 = (4,0), bm = (4,w/2), b1 = (4,w); w = 0.25, cell size 2.
  // Distinct corners: P_A = (0, w/2), P_B = (4, w/2), so the line is y = w/2: D_A = (w/2 + w/2)/2 = w/2,
  // D_B = (w/2 + 0 + w/2)/3 = w/3; thickness 5w/6. Three triangles fanned from a0 use a0 three times, fanned
  // from a1 a1 three times; a count per triangle would tilt the line one way or the other.
  const std::string v = "v 0 0 0\nv 0 0.25 0\nv 4 0 0\nv 4 0.125 0\nv 4 0.25 0\n";  // a0 a1 b0 bm b1
  const float want = static_cast<float>(5.0 * 0.25 / 6.0);
  EXPECT_FLOAT_EQ(strip_thickness(v + "f 1 3 4\nf 1 4 5\nf 1 5 2\n"), want);  // fan from a0
  EXPECT_FLOAT_EQ(strip_thickness(v + "f 2 1 3\nf 2 3 4\nf 2 4 5\n"), want);  // fan from a1
  EXPECT_FLOAT_EQ(strip_thickness(v + "f 1 3 4\nf 1 4 2\nf 2 4 5\n"), want);  // mixed
}

TEST(SimplifyThickEdge, RepeatedPositionsCountOnce) {
  // The two-triangle strip with every corner written anew per triangle (as STL or an OBJ with split
  // seams stores it): the welded corners are the same four vertices, so the thickness is still w.
  EXPECT_EQ(strip_thickness("v 0 0 0\nv 4 0 0\nv 4 0.25 0\nv 0 0 0\nv 4 0.25 0\nv 0 0.25 0\n"
                            "f 1 2 3\nf 4 5 6\n"),
            0.25f);
}

TEST(SimplifyThickEdge, SymmetricStripHasExactlyItsWidth) {
  // The same strip, ±h = ±0.125 about the x axis, as four triangles that use each end vertex three times:
  // P_A = (0,0,0), P_B = (4,0,0), every corner exactly h from the x axis: thickness = 2h = 0.25 exactly.
  const Level l = level_at_cell_size_2("strip", "v 0 -0.125 0\nv 0 0.125 0\nv 4 -0.125 0\nv 4 0.125 0\n"  // a0 a1 b0 b1
                                                "f 1 3 4\nf 1 4 2\nf 2 1 3\nf 2 3 4\n");
  EXPECT_TRUE(l.triangles.empty());
  ASSERT_EQ(l.edges.size(), 1u);
  EXPECT_EQ(l.thickness[0], 0.25f);
  const F3 e0 = l.at(l.edges[0][0]), e1 = l.at(l.edges[0][1]);
  EXPECT_EQ(std::min(e0[0], e1[0]), 0.0f);
  EXPECT_EQ(std::max(e0[0], e1[0]), 4.0f);
  EXPECT_EQ(std::abs(e0[1]), 0.125f);
  EXPECT_EQ(std::abs(e1[1]), 0.125f);
}

TEST(SimplifyThickEdge, CornerPairsSpilledToDiskGiveTheSameBytes) {
  // The {kept edge, corner} pairs of the thickness and point-size passes go through an external sort; with
  // --chunk-bytes 4096 its buffer holds 1024 pairs, so a level with more kept edges than that (two corners
  // each at least) spills sorted runs and merges them. Every file must be the in-memory run's.
  test::TempDir tmp;
  SimplifyOptions a = make_simplify(tmp.file("a")), b = make_simplify(tmp.file("b"));
  a.cell_sizes = b.cell_sizes = {0.02, 0.08, 0.3};
  a.representative = b.representative = Representative::quadric;
  ASSERT_TRUE(simplify_ok(sample_room(), a, make_options(2)));
  ASSERT_TRUE(simplify_ok(sample_room(), b, make_options(2, 0, 4096)));
  const Json m = manifest(a.output_dir);
  uint64_t most = 0;
  for (const auto& l : m["levels"]) most = std::max(most, l["edges"].get<uint64_t>() + l["points"].get<uint64_t>());
  EXPECT_GT(most, 1024u) << "no level has enough kept edges and points to spill";
  expect_same_output(a.output_dir, b.output_dir, "corner sort in memory vs spilled");
}

// ---- points at their size (issue 14) over distinct corners ----

// The size of the single point that `obj` (inside [0, 0.5]²) collapses to at cell size 2.
float collapsed_point_size(const std::string& obj) {
  const Level l = level_at_cell_size_2("square", obj);
  EXPECT_TRUE(l.triangles.empty());
  EXPECT_TRUE(l.edges.empty());
  EXPECT_EQ(l.point_size.size(), 1u);
  return l.point_size.empty() ? -1.0f : l.point_size[0];
}

TEST(SimplifyPointSize, DistinctCornersCountOnceAsForAnEdge) {
  // A square of side 0.5 fanned from its centre m = (0.25, 0.25): four triangles that use m four times and
  // each corner twice. Over the distinct corners (as an edge's thickness, Low & Tan §3.3.1) the mean is m,
  // the distances 0 and four times r = 0.25·sqrt(2): size 2·4r/5 = 0.4·sqrt(2). Counting a corner once per
  // triangle would give 2·8r/12 = sqrt(2)/6 instead.
  const double want = 0.4 * std::sqrt(2.0);
  const std::string v = "v 0 0 0\nv 0.5 0 0\nv 0.5 0.5 0\nv 0 0.5 0\nv 0.25 0.25 0\n";
  EXPECT_NEAR(collapsed_point_size(v + "f 5 1 2\nf 5 2 3\nf 5 3 4\nf 5 4 1\n"), want, 1e-6);
  // The same fan with every corner written anew per triangle: the welded corners are the same five.
  EXPECT_NEAR(collapsed_point_size("v 0.25 0.25 0\nv 0 0 0\nv 0.5 0 0\nv 0.25 0.25 0\nv 0.5 0 0\nv 0.5 0.5 0\n"
                                   "v 0.25 0.25 0\nv 0.5 0.5 0\nv 0 0.5 0\nv 0.25 0.25 0\nv 0 0.5 0\nv 0 0 0\n"
                                   "f 1 2 3\nf 4 5 6\nf 7 8 9\nf 10 11 12\n"),
              want, 1e-6);
}

// ---- every model of ../shared/data ----

TEST(SimplifySharedData, EveryModelSimplifies) {
  const std::string data = test::shared_data_dir();
  if (data.empty()) {
    std::printf("skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA)\n");
    GTEST_SKIP() << "skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA)";
  }
  constexpr uint64_t kMaxBytes = 50ull << 20;  // keeps the test's runtime bounded
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(data)) {
    if (!e.is_regular_file()) continue;
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext == ".obj" || ext == ".ply" || ext == ".stl") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  test::TempDir tmp;
  int done = 0, skipped = 0, checked = 0;
  std::vector<std::string> failures, not_falling;
  const auto t0 = std::chrono::steady_clock::now();
  for (const fs::path& f : files) {
    if (fs::file_size(f) > kMaxBytes) {
      std::printf("skipped: %s (%ju bytes, above the %ju-byte cap of this test)\n", f.c_str(),
                  static_cast<uintmax_t>(fs::file_size(f)), static_cast<uintmax_t>(kMaxBytes));
      ++skipped;
      continue;
    }
    SimplifyOptions so = make_simplify(tmp.file("out"));
    SimplifyReport report;
    const Result r = simplify(f.string(), so, make_options(2, 256ull << 20), &report);
    if (!r.ok()) failures.push_back(f.string() + ": " + status_name(r.status) + ": " + r.message);
    if (r.ok()) {
      EXPECT_TRUE(fs::exists(tmp.file("out/manifest.json"))) << f;
      EXPECT_FALSE(report.levels.empty()) << f;
      // Inputs whose default levels are checked: each level has triangles, fewer than the one before.
      if (report.scene.triangles > 0 && report.scene.triangles < (uint64_t{4000} << default_levels)) {
        ++checked;
        uint64_t previous = UINT64_MAX;
        for (const LevelStats& ls : report.levels) {
          if (ls.triangles == 0 || ls.triangles >= previous) {
            not_falling.push_back(f.string());
            break;
          }
          previous = ls.triangles;
        }
      }
    }
    fs::remove_all(tmp.path() / "out");
    ++done;
  }
  std::printf("%d models run, %zu failed, %d skipped (too large), %.1f s\n", done, failures.size(), skipped,
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  EXPECT_GT(done, 0);
  std::string list;
  for (const std::string& f : failures) list += "\n  " + f;
  EXPECT_TRUE(failures.empty()) << failures.size() << " of " << done << " models failed:" << list;
  std::printf("%d models below %ju triangles: default levels checked\n", checked, static_cast<uintmax_t>(uint64_t{4000} << default_levels));
  EXPECT_GT(checked, 0);
  std::string empty_or_flat;
  for (const std::string& f : not_falling) empty_or_flat += "\n  " + f;
  EXPECT_TRUE(not_falling.empty()) << not_falling.size() << " models have a level without triangles or no fewer than the one before:"
                                   << empty_or_flat;
}

TEST(SimplifySharedData, SmallRealModelsStopWhereCountsStopFalling) {
  // Mechanical parts (STL) and KiCad components (PLY) of 220 to 94,176 triangles, all below the size where
  // default levels are checked: every one gets levels that have triangles and fall. Exact counts for the
  // models whose old levels did not fall (C_Rect: 54, 22, 27, 12, 2; C_0402: 44, 28, 28, 12, 12).
  const std::string data = test::shared_data_dir();
  if (data.empty()) {
    std::printf("skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA)\n");
    GTEST_SKIP() << "skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA)";
  }
  const std::map<std::string, std::vector<uint64_t>> exact = {
      {"C_Rect_L9.0mm_W2.7mm_P7.50mm_MKT.ply", {54, 22, 12, 2}},
      {"C_0402_1005Metric.ply", {44, 28, 12}},
      {"Balun_Johanson_0896BM15A0001.ply", {116, 38, 30, 21, 2}},
      {"M3_hex_nut.stl", {140, 72, 52, 44, 6}},
  };
  std::vector<fs::path> files;
  for (const char* dir : {"mechanical", "kicad-sample"})
    for (const auto& e : fs::directory_iterator(fs::path(data) / dir))
      if (e.path().extension() == ".stl" || e.path().extension() == ".ply") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  ASSERT_GT(files.size(), 40u);
  test::TempDir tmp;
  size_t found = 0;
  for (const fs::path& f : files) {
    SimplifyOptions so = make_simplify(tmp.file("out"));
    SimplifyReport report;
    if (simplify_ok(f.string(), so, make_options(2), &report)) {
      check_default_levels(report, so.output_dir, f.filename().string());
      const auto it = exact.find(f.filename().string());
      if (it != exact.end()) {
        ++found;
        EXPECT_EQ(triangle_counts(report), it->second) << f;
      }
    }
    fs::remove_all(tmp.path() / "out");
  }
  EXPECT_EQ(found, exact.size());
}

}  // namespace
}  // namespace lodstream
