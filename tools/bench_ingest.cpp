// Ingest benchmark: for each file, `cat FILE > /dev/null` and `lodstream info FILE` run in the same
// process tree, alternately, several times; prints medians, throughputs, their ratio, and the peak
// resident memory of the lodstream child (ru_maxrss, i.e. its VmHWM, mapped pages included: the whole
// run's peak; before issue 13.3 lodstream reset VmHWM at each stage, and this showed the last stage's).
//
// usage: bench_ingest [--runs N] [--memory 1G] [--threads N] [--lodstream PATH] [--work-root DIR]... FILE...
// The first run of each file also warms the page cache; the benchmark measures files in page cache.
// Each --work-root (default: $TMPDIR or /tmp) is measured in turn: the store lodstream writes (about as
// many bytes as it reads) goes through that file system, so a disk-backed one and a tmpfs one (/dev/shm)
// separate lodstream's own time from the machine's writeback.
#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

extern char** environ;

namespace {

struct Run {
  double seconds = 0;
  uint64_t max_rss = 0;
  std::string out;
  int status = 0;
};

// Runs argv, optionally capturing stdout to a temp file, returns wall time and the child's peak RSS.
Run spawn(const std::vector<std::string>& args, const std::string& stdout_path) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, stdout_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  Run r;
  const auto t0 = std::chrono::steady_clock::now();
  pid_t pid;
  if (posix_spawnp(&pid, argv[0], &fa, nullptr, argv.data(), environ) != 0) {
    std::fprintf(stderr, "cannot run %s\n", argv[0]);
    std::exit(1);
  }
  int status = 0;
  struct rusage ru {};
  wait4(pid, &status, 0, &ru);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.max_rss = static_cast<uint64_t>(ru.ru_maxrss) * 1024;
  r.status = status;
  posix_spawn_file_actions_destroy(&fa);
  if (stdout_path != "/dev/null") {
    FILE* f = std::fopen(stdout_path.c_str(), "rb");
    char buf[65536];
    size_t n;
    while (f && (n = std::fread(buf, 1, sizeof buf, f)) > 0) r.out.append(buf, n);
    if (f) std::fclose(f);
  }
  return r;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : (v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]));
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 3;
  std::string memory = "1G", threads = "0";
  std::string lodstream = (std::filesystem::path(argv[0]).parent_path() / "lodstream").string();
  std::vector<std::string> files, roots;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--runs" && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (a == "--memory" && i + 1 < argc) memory = argv[++i];
    else if (a == "--threads" && i + 1 < argc) threads = argv[++i];
    else if (a == "--lodstream" && i + 1 < argc) lodstream = argv[++i];
    else if (a == "--work-root" && i + 1 < argc) roots.push_back(argv[++i]);
    else files.push_back(a);
  }
  if (files.empty()) {
    std::fprintf(stderr, "usage: bench_ingest [--runs N] [--memory 1G] [--threads N] [--lodstream PATH] [--work-root DIR]... FILE...\n");
    return 64;
  }
  if (roots.empty()) roots.push_back(std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp");
  const std::string out_path = std::filesystem::temp_directory_path() / ("bench_ingest." + std::to_string(getpid()) + ".json");
  fmt::print("lodstream ingest benchmark: {} runs each, --memory {}, --threads {}, {} cores\n", runs, memory, threads,
             sysconf(_SC_NPROCESSORS_ONLN));
  fmt::print("{:<16} {:<12} {:>6} {:>7} {:>8} {:>8} {:>7} {:>6} {:>7} {:>8} {:>8}\n", "file", "work root", "MB", "cat s",
             "cat MB/s", "ingest s", "MB/s", "ratio", "info s", "census s", "peak MB");
  for (const std::string& root : roots)
  for (const std::string& file : files) {
    const double mb = static_cast<double>(std::filesystem::file_size(file)) / 1e6;
    spawn({"cat", file}, "/dev/null");  // warm the page cache
    std::vector<double> cat_s, ingest_s, info_s, weld_s, peak;
    for (int r = 0; r < runs; ++r) {
      cat_s.push_back(spawn({"cat", file}, "/dev/null").seconds);
      const std::string work = root + "/bench_ingest.work." + std::to_string(getpid());
      const Run l = spawn({lodstream, "info", file, "--json", "--progress", "none", "--memory", memory, "--threads", threads,
                           "--work", work},
                          out_path);
      std::filesystem::remove_all(work);
      if (!WIFEXITED(l.status) || WEXITSTATUS(l.status) != 0) {
        std::fprintf(stderr, "lodstream failed on %s (status %d)\n", file.c_str(), l.status);
        return 1;
      }
      const auto j = nlohmann::json::parse(l.out);
      info_s.push_back(l.seconds);
      for (const auto& s : j.at("stages")) {
        if (s.at("name") == "ingest") ingest_s.push_back(s.at("seconds").get<double>());
        if (s.at("name") == "census") weld_s.push_back(s.at("seconds").get<double>());
      }
      peak.push_back(static_cast<double>(l.max_rss) / 1e6);
    }
    const double cat = median(cat_s), ing = median(ingest_s);
    fmt::print("{:<16} {:<12} {:>6.0f} {:>7.3f} {:>8.0f} {:>8.3f} {:>7.0f} {:>5.0f}% {:>7.3f} {:>8.3f} {:>8.0f}\n",
               std::filesystem::path(file).filename().string(), root, mb, cat, mb / cat, ing, mb / ing,
               100.0 * (mb / ing) / (mb / cat), median(info_s), median(weld_s), *std::max_element(peak.begin(), peak.end()));
  }
  std::filesystem::remove(out_path);
  std::printf("ratio = ingest throughput / cat throughput (medians); peak = max child VmHWM over the runs\n");
  return 0;
}
