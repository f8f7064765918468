// Crash safety (../shared/DESIGN.md "Resumable"; issue 13.5): the CLI runs as a child with `--progress
// json` and is killed with SIGKILL at chosen points; the same command then reruns on the same `--work` and
// must exit 0 with the outputs of an uninterrupted run, reusing exactly the resumable stages that finished
// before the kill and redoing the rest.
//
// Kill points, chosen from the progress lines of an uninterrupted reference run (so a stage added or
// renamed elsewhere is covered without changing this file):
// - the start of every progress stage: at its first line, the previous stage is done and this one has
//   begun;
// - the middle of every progress stage that reports one: its line with a fraction in (0, 1) nearest 0.5,
//   other than its first line (stages that report nothing more are listed on stdout as such);
// - between a stage's files and its stamp (or an output directory's last file), through the test-only
//   hook of stream/kill_point.h: the progress stream cannot stop a run there.
// The CLI stops itself after each progress line (LODSTREAM_TEST_STOP_AFTER_PROGRESS, tools/
// lodstream_cli.cpp), so the driver kills at exactly that line, or lets the child go on, and the state a
// kill leaves does not depend on how busy the machine is.
//
// After each kill: no file of the output directory is partial under a final name (each is absent, a
// `.partial`, or identical to the reference). After the rerun: the output directory holds the
// reference's files and nothing else, byte-identical (manifest.json and report.json without their
// timings, peaks and `reused` flags), the work directory holds the reference's files and nothing else (no
// scratch or partial file of the killed run), and the manifest's `reused` flags are as stated above.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "test_util.h"

extern char** environ;

namespace lodstream {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

struct Line {
  std::string stage;
  double fraction = 0;
};

struct ChildRun {
  int exit_code = -1;  // 128 + signal when killed
  bool killed_at_line = false;
  std::vector<Line> lines;
  std::string err;  // stderr lines that are not progress
};

// Runs `lodstream args...` with `env` added to the environment, stopping after each progress line; kills
// it (SIGKILL) at the first line for which `kill_at` is true.
ChildRun run_cli(std::vector<std::string> args, const std::vector<std::string>& env,
            const std::function<bool(const Line&)>& kill_at) {
  args.insert(args.begin(), LODSTREAM_CLI);
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::vector<std::string> env_strings(env);
  env_strings.push_back("LODSTREAM_TEST_STOP_AFTER_PROGRESS=1");
  std::vector<char*> envp;
  for (char** e = environ; *e; ++e) envp.push_back(*e);
  for (auto& e : env_strings) envp.push_back(e.data());
  envp.push_back(nullptr);

  int fds[2];
  EXPECT_EQ(pipe2(fds, O_CLOEXEC), 0);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_adddup2(&fa, fds[1], 2);
  pid_t pid = -1;
  EXPECT_EQ(posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), envp.data()), 0);
  posix_spawn_file_actions_destroy(&fa);
  close(fds[1]);

  ChildRun r;
  int status = 0;
  bool reaped = false;
  std::string buffer;
  char chunk[4096];
  for (;;) {
    const ssize_t n = read(fds[0], chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    buffer.append(chunk, static_cast<size_t>(n));
    for (size_t eol; !reaped && (eol = buffer.find('\n')) != std::string::npos;) {
      const std::string text = buffer.substr(0, eol);
      buffer.erase(0, eol + 1);
      Json j = Json::parse(text, nullptr, false);
      if (j.is_discarded() || !j.is_object() || !j.contains("stage")) {
        r.err += text + "\n";
        continue;
      }
      const Line line{j.at("stage").get<std::string>(), j.at("fraction").get<double>()};
      r.lines.push_back(line);
      // The child stops itself right after writing the line; wait until it has.
      EXPECT_EQ(waitpid(pid, &status, WUNTRACED), pid);
      if (!WIFSTOPPED(status)) {
        reaped = true;
        break;
      }
      if (kill_at(line)) {
        kill(pid, SIGKILL);
        r.killed_at_line = true;
      } else {
        kill(pid, SIGCONT);
      }
    }
    if (reaped) break;
  }
  close(fds[0]);
  if (!reaped) {
    EXPECT_EQ(waitpid(pid, &status, 0), pid);
  }
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.err += buffer;
  return r;
}

ChildRun run_to_end(const std::vector<std::string>& args) {
  return run_cli(args, {}, [](const Line&) { return false; });
}

// Every regular file under `dir`, by path relative to it.
std::set<std::string> files_under(const std::string& dir) {
  std::set<std::string> out;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    if (it->is_regular_file()) out.insert(fs::relative(it->path(), dir).string());
  return out;
}

// manifest.json / report.json without what differs between any two runs: times, peaks, rates, reuse, and
// the work directory (its path).
Json without_timings(Json j) {
  static const std::set<std::string> volatile_keys{"seconds", "cpu_seconds", "peak_rss_bytes", "reused", "ray_seconds",
                                                   "query_seconds", "rays_per_second", "queries_per_second",
                                                   "work_dir"};
  if (j.is_object()) {
    Json o = Json::object();
    for (auto& [k, v] : j.items())
      if (!volatile_keys.count(k)) o[k] = without_timings(v);
    return o;
  }
  if (j.is_array())
    for (auto& v : j) v = without_timings(v);
  return j;
}

bool is_summary(const std::string& name) { return name == "manifest.json" || name == "report.json"; }

// Whether `dir`/name holds the reference's bytes (a summary compared without timings).
bool same_as_reference(const std::string& dir, const std::string& reference, const std::string& name) {
  const std::string a = test::read_file(dir + "/" + name), b = test::read_file(reference + "/" + name);
  if (!is_summary(name)) return a == b;
  const Json ja = Json::parse(a, nullptr, false);
  return !ja.is_discarded() && without_timings(ja) == without_timings(Json::parse(b));
}

// The stage of the summary's `stages` list that a progress stage belongs to: itself, or for the grade
// stage's parts `weld` and `sort`, `grade`; for the report's `level N`, `measure`. Empty when unknown.
std::string summary_stage(const std::string& progress_stage, const std::vector<std::string>& stages) {
  std::string s = progress_stage;
  if (s == "weld" || s == "sort") s = "grade";
  if (s == "triangulate") s = "ingest";  // ingest's pass over concave polygons, before store.json
  if (s.rfind("level ", 0) == 0) s = "measure";
  return std::find(stages.begin(), stages.end(), s) != stages.end() ? s : std::string();
}

std::vector<std::string> stage_names(const Json& summary) {
  std::vector<std::string> names;
  for (const Json& s : summary.at("stages")) names.push_back(s.at("name").get<std::string>());
  return names;
}

std::map<std::string, bool> reused_flags(const Json& summary) {
  std::map<std::string, bool> r;
  for (const Json& s : summary.at("stages")) r[s.at("name").get<std::string>()] = s.at("reused").get<bool>();
  return r;
}

struct KillPoint {
  std::string label;        // for messages
  std::string stage;        // progress stage killed at ("" for a named point)
  double fraction = -1;     // kill at the first line of `stage` with at least this fraction
  std::string named;        // LODSTREAM_TEST_KILL_AT
  std::string owner;        // the summary stage the kill interrupts
};

// Start and middle of every progress stage of `lines`.
std::vector<KillPoint> progress_kill_points(const std::vector<Line>& lines, const std::vector<std::string>& stages) {
  std::vector<std::string> order;
  std::map<std::string, std::vector<double>> fractions;
  for (const Line& l : lines) {
    if (!fractions.count(l.stage)) order.push_back(l.stage);
    fractions[l.stage].push_back(l.fraction);
  }
  std::vector<KillPoint> points;
  for (const std::string& s : order) {
    const std::string owner = summary_stage(s, stages);
    EXPECT_FALSE(owner.empty()) << "progress stage '" << s << "' belongs to no stage of the summary: name its stage in summary_stage()";
    const std::vector<double>& f = fractions[s];
    points.push_back({s + " start", s, -1, "", owner});
    double middle = -1;
    for (size_t i = 1; i < f.size(); ++i)
      if (f[i] > f[0] && f[i] > 0 && f[i] < 1 && (middle < 0 || std::abs(f[i] - 0.5) < std::abs(middle - 0.5))) middle = f[i];
    if (middle >= 0) points.push_back({s + " middle", s, middle, "", owner});
    else std::printf("note: progress stage '%s' reports no fraction in (0, 1) after its first line (%zu line(s)); killed at its first line only\n", s.c_str(), f.size());
  }
  return points;
}

// One kill and rerun, checked against the reference output `ref_out` and work directory files `ref_work`.
// `resumable`: the stages an uninterrupted rerun reuses; `order`: the summary's stages in order.
void kill_and_resume(const KillPoint& p, const std::vector<std::string>& args_with_dirs, const std::string& out,
                     const std::string& work, const std::string& ref_out,
                     const std::set<std::string>& ref_work, const std::string& summary,
                     const std::set<std::string>& resumable, const std::vector<std::string>& order) {
  SCOPED_TRACE("kill point: " + p.label);
  std::printf("kill -9 at %s (stage %s)\n", p.label.c_str(), p.owner.c_str());
  fs::remove_all(out);
  fs::remove_all(work);

  std::vector<std::string> env;
  if (!p.named.empty()) env.push_back("LODSTREAM_TEST_KILL_AT=" + p.named);
  bool seen = false;
  const ChildRun killed = run_cli(args_with_dirs, env, [&](const Line& l) {
    if (p.stage.empty() || l.stage != p.stage) return false;
    if (p.fraction < 0 || l.fraction >= p.fraction) return !seen && (seen = true);
    return false;
  });
  ASSERT_EQ(killed.exit_code, 128 + SIGKILL) << "the run was not killed at " << p.label << ":\n" << killed.err;
  if (p.named.empty()) {
    ASSERT_TRUE(killed.killed_at_line);
  }

  // No file under a final name is partial: each is absent, a `.partial`, or the reference's.
  const std::set<std::string> after_kill = files_under(out), ref_files = files_under(ref_out);
  for (const std::string& f : after_kill) {
    if (f.size() > 8 && f.compare(f.size() - 8, 8, ".partial") == 0) continue;
    EXPECT_TRUE(ref_files.count(f)) << "after the kill, the output directory holds " << f << ", which the reference does not";
    if (ref_files.count(f)) {
      EXPECT_TRUE(same_as_reference(out, ref_out, f)) << "after the kill, " << f << " differs from the reference";
    }
  }
  EXPECT_FALSE(after_kill.count(summary)) << summary << " written before the run finished";

  const ChildRun rerun = run_to_end(args_with_dirs);
  ASSERT_EQ(rerun.exit_code, 0) << rerun.err;
  EXPECT_EQ(files_under(out), ref_files);
  for (const std::string& f : ref_files) {
    EXPECT_TRUE(same_as_reference(out, ref_out, f)) << f << " differs from the reference after resuming";
  }
  EXPECT_EQ(files_under(work), ref_work) << "the work directory after resuming is not the reference's";

  const Json s = Json::parse(test::read_file(out + "/" + summary));
  const std::map<std::string, bool> reused = reused_flags(s);
  const auto at = std::find(order.begin(), order.end(), p.owner) - order.begin();
  for (size_t i = 0; i < order.size(); ++i) {
    const bool expected = resumable.count(order[i]) && static_cast<ptrdiff_t>(i) < at;
    EXPECT_EQ(reused.at(order[i]), expected) << "stage " << order[i] << (expected ? " finished before the kill and should be reused"
                                                                                  : " was not finished before the kill and should be redone");
  }
}

// A reference run of `args` (output `out`, work `work`) and an uninterrupted rerun: returns the progress
// lines, and fills the stages in order and those the rerun reuses.
std::vector<Line> reference(const std::vector<std::string>& args, const std::string& out, const std::string& work,
                            const std::string& summary, std::vector<std::string>* order, std::set<std::string>* resumable) {
  const ChildRun first = run_to_end(args);
  EXPECT_EQ(first.exit_code, 0) << first.err;
  const Json j = Json::parse(test::read_file(out + "/" + summary));
  *order = stage_names(j);
  const std::string copy = out + ".first";
  fs::copy(out, copy, fs::copy_options::recursive);
  const std::set<std::string> work_files = files_under(work);
  const ChildRun again = run_to_end(args);
  EXPECT_EQ(again.exit_code, 0) << again.err;
  for (const std::string& f : files_under(copy)) {
    EXPECT_TRUE(same_as_reference(out, copy, f)) << f << " differs on an uninterrupted rerun";
  }
  EXPECT_EQ(files_under(work), work_files);
  for (const auto& [name, r] : reused_flags(Json::parse(test::read_file(out + "/" + summary)))) {
    if (r) resumable->insert(name);
  }
  fs::remove_all(copy);
  return first.lines;
}

std::string sample_room() { return test::source_dir() + "/tests/data/sample-room.ply"; }

// Small chunks and budget so that every stage has several progress steps; two levels to keep it short.
std::vector<std::string> simplify_args(const std::string& out, const std::string& work) {
  return {"simplify", sample_room(), "-o", out, "--work", work, "--levels", "2", "--chunk-bytes", "64k",
          "--memory", "64M", "--progress", "json"};
}

std::vector<std::string> report_args(const std::string& lods, const std::string& out, const std::string& work) {
  return {"report", lods, "-o", out, "--work", work, "--views", "4", "--resolution", "64", "--samples", "2000",
          "--html-views", "1", "--chunk-bytes", "64k", "--memory", "64M", "--progress", "json"};
}

TEST(CrashSafety, SimplifyAndReportResumeAfterKillNineAtEveryStageStartAndMiddle) {
  test::TempDir tmp;
  const std::string ref_out = tmp.file("ref-out"), ref_work = tmp.file("ref-work");

  // simplify
  std::vector<std::string> order;
  std::set<std::string> resumable;
  const std::vector<Line> lines = reference(simplify_args(ref_out, ref_work), ref_out, ref_work, "manifest.json", &order, &resumable);
  ASSERT_FALSE(lines.empty());
  for (const char* s : {"ingest", "grade", "cluster"}) {
    EXPECT_TRUE(resumable.count(s)) << "an uninterrupted rerun does not reuse " << s;
  }
  std::vector<KillPoint> points = progress_kill_points(lines, order);
  for (const auto& [file, owner] : std::vector<std::pair<std::string, std::string>>{
           {"store.json", "ingest"}, {"grade.json", "grade"}, {"cluster.json", "cluster"}, {"manifest.json", "write"}})
    points.push_back({"before " + file + " is written", "", -1, file, owner});
  const std::set<std::string> ref_work_files = files_under(ref_work);
  const std::string out = tmp.file("out"), work = tmp.file("work");
  for (const KillPoint& p : points)
    kill_and_resume(p, simplify_args(out, work), out, work, ref_out, ref_work_files, "manifest.json", resumable, order);

  // report, on the reference levels, with a work directory of its own (so that its ingest is killed too)
  const std::string rep_ref = tmp.file("rep-ref"), rep_ref_work = tmp.file("rep-ref-work");
  std::vector<std::string> rep_order;
  std::set<std::string> rep_resumable;
  const std::vector<Line> rep_lines =
      reference(report_args(ref_out, rep_ref, rep_ref_work), rep_ref, rep_ref_work, "report.json", &rep_order, &rep_resumable);
  ASSERT_FALSE(rep_lines.empty());
  EXPECT_TRUE(rep_resumable.count("ingest")) << "an uninterrupted rerun of report does not reuse its ingest";
  std::vector<KillPoint> rep_points = progress_kill_points(rep_lines, rep_order);
  rep_points.push_back({"before report.json is written", "", -1, "report.json", "write"});
  const std::set<std::string> rep_work_files = files_under(rep_ref_work);
  const std::string rep = tmp.file("rep"), rep_work = tmp.file("rep-work");
  for (const KillPoint& p : rep_points)
    kill_and_resume(p, report_args(ref_out, rep, rep_work), rep, rep_work, rep_ref, rep_work_files, "report.json",
                    rep_resumable, rep_order);
}

// A height field of n × n vertices as binary PLY: large enough that, under --memory 64M, the grade stage
// scatters its primitives into range buckets and the sort spills runs, scratch files a kill leaves behind.
std::string write_grid(const test::TempDir& tmp, int n) {
  std::string ply = fmt::format(
      "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n"
      "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
      n * n, 2 * (n - 1) * (n - 1));
  auto put = [&](const void* p, size_t bytes) { ply.append(static_cast<const char*>(p), bytes); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const float v[3] = {static_cast<float>(i) / n, static_cast<float>(j) / n,
                          static_cast<float>(0.05 * std::sin(i * 0.1) * std::cos(j * 0.13))};
      put(v, sizeof v);
    }
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t v = static_cast<uint32_t>(j * n + i), un = static_cast<uint32_t>(n);
      const uint32_t tris[2][3] = {{v, v + 1, v + un}, {v + 1, v + un + 1, v + un}};
      for (const auto& t : tris) {
        const uint8_t three = 3;
        put(&three, 1);
        put(t, sizeof t);
      }
    }
  return tmp.write("grid.ply", ply);
}

// simplify of the grid into `out` with `work`, two levels at the minimum budget, progress as JSON lines.
std::vector<std::string> grid_simplify_args(const std::string& grid, const std::string& out, const std::string& work) {
  return {"simplify", grid, "-o", out, "--work", work, "--levels", "2", "--memory", "64M", "--progress", "json"};
}

TEST(CrashSafety, ScratchFilesOfAKilledRunAreRemovedWhenItResumes) {
  test::TempDir tmp;
  const std::string grid = write_grid(tmp, 600);
  auto args = [&](const std::string& out, const std::string& work) { return grid_simplify_args(grid, out, work); };
  const std::string ref_out = tmp.file("ref-out"), ref_work = tmp.file("ref-work");
  std::vector<std::string> order;
  std::set<std::string> resumable;
  const std::vector<Line> lines = reference(args(ref_out, ref_work), ref_out, ref_work, "manifest.json", &order, &resumable);
  const std::set<std::string> ref_work_files = files_under(ref_work);
  for (const KillPoint& p : progress_kill_points(lines, order)) {
    if (p.stage != "grade") continue;
    const std::string out = tmp.file("out"), work = tmp.file("work");
    kill_and_resume(p, args(out, work), out, work, ref_out, ref_work_files, "manifest.json", resumable, order);
  }
}

// The levels' scratch files are in the output directory (stream/level_files.h), as `.partial` files: a run
// killed with the finest level's scratch complete (its parts all in, its files not yet written) leaves them,
// and the rerun replaces and removes them.
TEST(CrashSafety, LevelScratchInTheOutputDirectoryIsReplacedWhenItResumes) {
  test::TempDir tmp;
  const std::string grid = write_grid(tmp, 600);
  auto args = [&](const std::string& out, const std::string& work) { return grid_simplify_args(grid, out, work); };
  const std::string ref_out = tmp.file("ref-out"), ref_work = tmp.file("ref-work");
  std::vector<std::string> order;
  std::set<std::string> resumable;
  reference(args(ref_out, ref_work), ref_out, ref_work, "manifest.json", &order, &resumable);
  for (const std::string& f : files_under(ref_out)) EXPECT_EQ(f.find("scratch"), std::string::npos) << f << " left behind";
  const std::string out = tmp.file("out"), work = tmp.file("work");
  const ChildRun killed = run_cli(args(out, work), {"LODSTREAM_TEST_KILL_AT=lod0.scratch"}, [](const Line&) { return false; });
  ASSERT_EQ(killed.exit_code, 128 + SIGKILL) << killed.err;
  const std::set<std::string> left = files_under(out);
  for (const char* f : {"lod0.scratch-vertices.partial", "lod0.scratch-triangles.partial"}) {
    EXPECT_TRUE(left.count(f)) << f << " is not in the output directory after the kill";
  }
  for (const std::string& f : files_under(work)) EXPECT_EQ(f.find("level"), std::string::npos) << f << " in the work directory";
  kill_and_resume({"before lod0's files are written", "", -1, "lod0.scratch", "emit"}, args(out, work), out, work, ref_out,
                  files_under(ref_work), "manifest.json", resumable, order);
}

// manifest.json (report.json) is written last, so that its presence means the directory is complete. A
// run over an older run's output directory, killed while it writes its own files, must not leave the
// older summary vouching for a mix of the two runs' files.
TEST(CrashSafety, ARunKilledOverAnOlderOutputLeavesNoSummaryOfTheOlderOne) {
  test::TempDir tmp;
  const std::string out = tmp.file("out"), rep = tmp.file("rep"), work = tmp.file("work");
  auto simplify = [&](const char* levels) {
    return std::vector<std::string>{"simplify", sample_room(), "-o", out, "--work", work, "--levels", levels, "--progress", "json"};
  };
  ASSERT_EQ(run_to_end(simplify("3")).exit_code, 0);
  bool first_write = true;
  const ChildRun killed = run_cli(simplify("2"), {}, [&](const Line& l) { return l.stage == "write" && std::exchange(first_write, false); });
  ASSERT_TRUE(killed.killed_at_line) << killed.err;
  EXPECT_FALSE(fs::exists(out + "/manifest.json")) << "the older run's manifest.json survived a run killed while writing its levels";
  ASSERT_EQ(run_to_end(simplify("2")).exit_code, 0);
  EXPECT_EQ(Json::parse(test::read_file(out + "/manifest.json")).at("levels").size(), 2u);

  auto report = [&](const char* views) {
    return std::vector<std::string>{"report", out, "-o", rep, "--work", work, "--views", views, "--resolution", "64",
                                    "--samples", "2000", "--html-views", "1", "--progress", "json"};
  };
  ASSERT_EQ(run_to_end(report("4")).exit_code, 0);
  const ChildRun killed_report = run_cli(report("5"), {"LODSTREAM_TEST_KILL_AT=report.json"}, [](const Line&) { return false; });
  ASSERT_EQ(killed_report.exit_code, 128 + SIGKILL) << killed_report.err;
  EXPECT_FALSE(fs::exists(rep + "/report.json")) << "the older run's report.json survived a run killed after writing its CSVs";
}

// `info` keeps its census beside the store (census.json) and reuses it with the store. The source file
// changes, and the next run is killed after the new store is complete but before the new census is
// written: the rerun must not take the old file's census for the new one.
TEST(CrashSafety, InfoKilledBeforeItsCensusIsWrittenDoesNotReuseTheCensusOfAnOlderSource) {
  test::TempDir tmp;
  const std::string input = tmp.file("scene.obj"), work = tmp.file("work");
  tmp.write("scene.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  ASSERT_EQ(test::run_cli({"info", input, "--work", work, "--json"}, tmp).exit_code, 0);
  // Same triangle, every position stored twice: 6 vertices, 3 welded, 3 unused.
  tmp.write("scene.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const ChildRun killed = run_cli({"info", input, "--work", work, "--progress", "json"}, {"LODSTREAM_TEST_KILL_AT=census.json"},
                             [](const Line&) { return false; });
  ASSERT_EQ(killed.exit_code, 128 + SIGKILL) << killed.err;
  const test::CliRun rerun = test::run_cli({"info", input, "--work", work, "--json"}, tmp);
  ASSERT_EQ(rerun.exit_code, 0) << rerun.err;
  const test::CliRun fresh = test::run_cli({"info", input, "--json"}, tmp);
  ASSERT_EQ(fresh.exit_code, 0) << fresh.err;
  const Json a = Json::parse(rerun.out), b = Json::parse(fresh.out);
  EXPECT_EQ(a.at("vertices"), 6);
  for (const char* k : {"vertices", "vertices_welded", "unused_vertices"}) EXPECT_EQ(a.at(k), b.at(k)) << k;
}

}  // namespace
}  // namespace lodstream
