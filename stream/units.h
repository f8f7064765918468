// Stamps, shares and units: how the processes of a sharded run (stream/shard.h) divide a stage's work
// over a shared work directory without talking to each other. A stage or a share is done when its stamp
// (a small JSON file: the key of its inputs and options, its files, a value) is there and matches; a share
// runs under a lock of its own, so that two processes never run it at once, and a process killed while it
// runs one leaves no stamp, so that the next process runs it again. Units are shares that every process
// which needs the stage's result takes part in (take_units): the simplify grading shares' weld and merge
// units, the report tasks' sampling units.
#pragma once

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "io/file_writer.h"
#include "stream/kill_point.h"
#include "stream/shard.h"

namespace lodstream::stream {

// A stage's stamp: reused when it exists, holds `key`, and every listed file exists; sets *value then.
bool stamp_matches(const std::string& path, const nlohmann::ordered_json& key, nlohmann::ordered_json* value);
// Writes a stamp (atomically; the test kill point named after its file comes first).
void write_stamp(const std::string& path, const nlohmann::ordered_json& key, const std::vector<std::string>& files,
                 const nlohmann::ordered_json& value);

// One share of a stage run as N shares (grading, clustering, the weld's units): under its own lock in
// `dir` (one process a share), reused when its stamp is there, else run, then stamped. run() returns the
// stamp's files and value; `kill` is the test kill point just before the stamp (empty: none). Returns the
// stamp's value; with `wait` false, nothing when another process holds the share's lock.
// after(): called once the stamp is written, by the process that ran the share (a step that must not come
// before the stamp: freeing what only the share read).
struct NothingAfter {
  void operator()() const {}
};
template <class Run, class After = NothingAfter>
std::optional<nlohmann::ordered_json> share_unless_held(const std::string& dir, unsigned share, const std::string& stamp,
                                                        const nlohmann::ordered_json& key, const std::string& kill, bool wait,
                                                        Run&& run, const After& after = {}) {
  const ShardLock share_lock(dir, fmt::format("share-{}.lock", share), wait);
  if (!share_lock.held()) return std::nullopt;
  nlohmann::ordered_json v;
  if (stamp_matches(stamp, key, &v)) return v;
  std::filesystem::remove(stamp);
  const auto [files, value] = run();
  // tests/slurm_test.sh: a share task killed before its stamp (a later process runs the share again)
  if (!kill.empty()) kill_point(kill);
  write_stamp(stamp, key, files, value);
  after();
  return value;
}
template <class Run>
nlohmann::ordered_json stamped_share(const std::string& dir, unsigned share, const std::string& stamp,
                                     const nlohmann::ordered_json& key, const std::string& kill, Run&& run) {
  return *share_unless_held(dir, share, stamp, key, kill, true, std::forward<Run>(run));
}

// Units of a stage that every process of a sharded run takes part in, in `dir`, unit u stamped at
// stamp(u) with `key`: first every unit that no other process holds (from `index` on, so that processes
// starting together take different units), then every unit in turn, waiting for those another process
// holds; a unit whose holder died is run here. run(u) returns the unit's stamp's files and value; after(u)
// follows its stamp where this process ran it. Returns every unit's stamp value.
struct NothingAfterUnit {
  void operator()(unsigned) const {}
};
template <class Stamp, class Run, class After = NothingAfterUnit>
std::vector<nlohmann::ordered_json> take_units(const std::string& dir, unsigned units, unsigned index, const Stamp& stamp,
                                               const nlohmann::ordered_json& key, const Run& run, const After& after = {}) {
  std::filesystem::create_directories(dir);
  for (unsigned k = 0; k < units; ++k) {
    const unsigned u = (index + k) % units;
    share_unless_held(dir, u, stamp(u), key, "", false, [&] { return run(u); }, [&] { after(u); });
  }
  std::vector<nlohmann::ordered_json> values;
  for (unsigned u = 0; u < units; ++u)
    values.push_back(*share_unless_held(dir, u, stamp(u), key, "", true, [&] { return run(u); }, [&] { after(u); }));
  return values;
}

// Who runs a unit, for its stamp: "host:pid".
std::string unit_runner();

// How many of `units` units a process takes up at once: one a thread of its arena, at most `fit` (what its
// budget holds), at least one.
inline unsigned unit_threads(uint64_t units, uint64_t fit) {
  const uint64_t arena = static_cast<uint64_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  return static_cast<unsigned>(std::clamp<uint64_t>(std::min(arena, fit), 1, std::max<uint64_t>(units, 1)));
}

// take_units on `threads` of this process's threads at once, each starting at its own unit (index · threads
// + t), for units whose stamps are dir/STEM-u.json and which write their outputs in place (no files in the
// stamp). Each unit's stamp value gets its wall seconds ("seconds") and runner ("by"); after(u) as
// take_units'. Returns every unit's stamp value.
template <class Run, class After = NothingAfterUnit>
std::vector<nlohmann::ordered_json> take_units_on_threads(const std::string& dir, unsigned units, unsigned index, unsigned threads,
                                                          const char* stem, const nlohmann::ordered_json& key, const Run& run,
                                                          const After& after = {}) {
  std::vector<std::vector<nlohmann::ordered_json>> values(threads);
  tbb::parallel_for(0u, threads, [&](unsigned t) {
    values[t] = take_units(
        dir, units, (index * threads + t) % units, [&](unsigned u) { return dir + fmt::format("{}-{}.json", stem, u); }, key,
        [&](unsigned u) {
          const auto t0 = std::chrono::steady_clock::now();
          nlohmann::ordered_json v = run(u);
          v["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          v["by"] = unit_runner();
          return std::pair(std::vector<std::string>{}, std::move(v));
        },
        after);
  });
  return values.front();
}

// The units' wall seconds and runners, from their stamp values: {"seconds": [...], "by": [...]}.
nlohmann::ordered_json unit_figures(const std::vector<nlohmann::ordered_json>& values);

// The file that a set of units fills in place (`path`, in `dir`), made once for `key` under a lock of its
// own (dir/start.lock), whichever process comes first: unless dir/start.json holds `key` and `path`
// exists, the files of an older start (names beginning with one of `stale`: its units' stamps and
// outputs) are removed, make() makes `path`, and start.json is written.
template <class Make>
void start_once(const std::string& dir, const std::string& path, const nlohmann::ordered_json& key,
                std::initializer_list<const char*> stale, Make&& make) {
  std::filesystem::create_directories(dir);
  const ShardLock lock(dir, "start.lock");
  const std::string stamp = dir + "start.json";
  try {
    std::error_code ec;
    if (nlohmann::ordered_json::parse(io::read_small_file(stamp)).at("key") == key && std::filesystem::exists(path, ec)) return;
  } catch (const std::exception&) {
    // none yet, or unreadable: started below
  }
  for (const auto& e : std::filesystem::directory_iterator(dir))
    for (const char* name : stale)
      if (e.path().filename().string().rfind(name, 0) == 0) std::filesystem::remove(e.path());
  make();
  io::write_file_atomic(stamp, nlohmann::ordered_json{{"key", key}}.dump() + "\n");
}

}  // namespace lodstream::stream
