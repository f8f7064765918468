// The public entry points: each runs its stages under one task arena and one memory plan, measures
// time and peak memory per stage, and turns every exception into a Result.
#include <cctype>
#include <chrono>
#include <new>

#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/reader.h"
#include "lodstream/lodstream.h"
#include "stream/disk_space.h"
#include "stream/ingest.h"
#include "stream/job.h"
#include "stream/kill_point.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/work_dir.h"

namespace lodstream {

using stream::guarded;
using stream::run_stage;

uint64_t peak_rss_bytes() { return stream::peak_rss_bytes(); }

Result input_format(const std::string& path, std::string* format) {
  return guarded([&] {
    const io::MappedFile file(path);
    const std::unique_ptr<io::Reader> reader = io::open_reader(file);
    reader->open();
    *format = reader->format();
  });
}

Result info(const std::string& path, const Options& options, SceneInfo* out) {
  return guarded([&] {
    const auto t0 = std::chrono::steady_clock::now();
    const stream::MemoryPlan plan = stream::plan_memory(options);
    stream::Progress progress(options);
    stream::WorkDir work(options.work_dir);
    if (options.check_disk_space) stream::check_info_space(path, work.path());
    const std::string store_dir = work.subdir("store");
    SceneInfo info;
    tbb::task_arena arena(static_cast<int>(plan.threads));
    arena.execute([&] {
      bool reused = false;
      const stream::StoreMeta meta =
          stream::run_ingest_stage(path, store_dir, plan, work, progress, &info.stages, &info, &reused);
      const stream::Census census = run_stage(&info.stages, "census", [&](StageStats& st) {
        // The census of the store's source: a run killed after a new store but before its census leaves the
        // old source's census.json beside it, which must not be taken for the new one.
        const std::string cache = store_dir + "/census.json";
        const nlohmann::json source{{"path", meta.source.path}, {"bytes", meta.source.bytes}, {"mtime_ns", meta.source.mtime_ns}};
        if (reused) {
          try {
            const auto j = nlohmann::json::parse(io::read_small_file(cache));
            if (j.at("source") == source) {
              st.reused = true;
              return stream::Census{j.at("vertices_welded").get<uint64_t>(), j.at("unused_vertices").get<uint64_t>()};
            }
          } catch (const std::exception&) {
          }
        }
        const stream::Census c = stream::census(store_dir, meta, plan, work, progress);
        stream::kill_point("census.json");
        io::write_file_atomic(cache, nlohmann::json{{"source", source},
                                                    {"vertices_welded", c.vertices_welded},
                                                    {"unused_vertices", c.unused_vertices}}.dump() + "\n");
        return c;
      });
      info.vertices_welded = census.vertices_welded;
      info.unused_vertices = census.unused_vertices;
    });
    info.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    info.peak_rss_bytes = stream::peak_rss_bytes();
    info.work_dir = stream::work_dir_usage(work.path(), info.file_bytes);
    *out = std::move(info);
  });
}

bool parse_size(const std::string& text, uint64_t* out) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    return false;
  }
  std::string unit = text.substr(used);
  for (char& c : unit) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  double mult = 1;
  if (unit.empty() || unit == "b") mult = 1;
  else if (unit == "k" || unit == "kb" || unit == "kib") mult = 1024.0;
  else if (unit == "m" || unit == "mb" || unit == "mib") mult = 1024.0 * 1024;
  else if (unit == "g" || unit == "gb" || unit == "gib") mult = 1024.0 * 1024 * 1024;
  else if (unit == "t" || unit == "tb" || unit == "tib") mult = 1024.0 * 1024 * 1024 * 1024;
  else return false;
  if (!(v >= 0) || v * mult > 1.8e19) return false;
  *out = static_cast<uint64_t>(v * mult);
  return true;
}

}  // namespace lodstream
