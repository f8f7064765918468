// `lodstream slurm`: runs a sharded simplify (stream/shard.h) or report (stream/report_shard.h) on a Slurm
// cluster. It only writes sbatch
// scripts (readable, resubmittable by hand) under OUT/slurm/ and submits them with sbatch: for a text
// input (--ingest-ranges, ranges_pay), an ingest array job of N range tasks (each parses an N-th of the
// input's bytes, a report's of every original's, stream/ingest_range.h); for simplify, a grade array job of
// N shares (the first joins the ranges, or ingests the input, under the work directory's lock; then every
// share takes up weld units until the weld is done, then the weld map's units, the first back under the
// lock makes the grading plan, and each grades and sorts its share: stream/grade_shares.h)
// and a cluster array job of N shares (they take up the grading shares' merge as units, then each
// clusters its share: stream/cluster_shares.h); then the array job of N tasks. A simplify task first takes
// up, as units, the rest of the shared stages: the clustering shares' merge (stream/cluster_merge.h), the
// block boxes and the split levels' cells by vertex (a whole level's come from its cluster share), the
// first back under the lock stamping each stage; then it emits its share. A report has a prepare job (the
// join alone) before its tasks (--dependency=afterok). The merge runs after the task array. The cluster
// array and a simplify task array wait for the array before them to end, not to succeed (afterany): the
// share that did not finish is run by the next step. The scheduler is Slurm's; lodstream adds none of its own. Each script records its command's exit
// status in OUT/slurm/status/NAME.rc (and the command's pid in NAME.pid while it runs), which is how
// --wait tells a failed task's one-machine exit code from the merge's.
#include "tools/slurm_cli.h"

#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lodstream/lodstream.h"

namespace lodstream::cli {

namespace {

namespace fs = std::filesystem;
using nlohmann::ordered_json;

constexpr int kUsage = 64, kNoInput = 66, kInternal = 70, kIoError = 74;

const char* const kUsageText =
    "usage: lodstream slurm simplify INPUT -o OUTDIR --shards N [--work DIR] [--wait] [--sbatch-arg ARG]... [simplify options]\n"
    "       lodstream slurm report RUNDIR -o REPORTDIR --shards N [--work DIR] [--wait] [--sbatch-arg ARG]... [report options]\n"
    "       lodstream slurm resubmit OUTDIR [--wait]\n"
    "  simplify  writes OUTDIR/slurm/{ingest,grade,cluster,tasks,merge}.sbatch and submits them (afterok dependencies);\n"
    "            --work: the work directory every task shares (default OUTDIR/slurm/work; on a shared file system)\n"
    "  report    the same for `lodstream report RUNDIR -o REPORTDIR` (scripts in REPORTDIR/slurm/; more report\n"
    "            arguments go to every job as given, relative paths from the current directory)\n"
    "  resubmit  submits again the tasks that did not finish (and the merge), or the whole chain when no\n"
    "            task did (a report: when its prepare job did not), from the ingest ranges that did not finish\n"
    "            (the scripts keep the first submission's sbatch options)\n"
    "  --wait    wait for the merge and exit with the one-machine exit code (a failed job's, else the merge's)\n"
    "  --ingest-ranges auto|yes|no  parse the input as N byte ranges in an array before the join (default auto:\n"
    "            for text inputs, OBJ and ASCII PLY and STL, whose parsing is the cost; a binary input is ingested\n"
    "            by the first grade share, or for a report the prepare job, as one machine does)\n"
    "  --sbatch-arg ARG  an sbatch option for every job (repeat), e.g. --sbatch-arg=--partition=big --sbatch-arg=--mem=2G\n";

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string absolute(const std::string& p) { return fs::absolute(p).lexically_normal().string(); }

// Runs `command` (sh -c) and returns its stdout; `status` its exit status.
std::string run(const std::string& command, int* status) {
  std::string out;
  FILE* p = ::popen(command.c_str(), "r");
  if (!p) {
    *status = -1;
    return out;
  }
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int s = ::pclose(p);
  *status = WIFEXITED(s) ? WEXITSTATUS(s) : 128 + (WIFSIGNALED(s) ? WTERMSIG(s) : 0);
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

bool write_text(const std::string& path, const std::string& text, bool executable) {
  const std::string tmp = path + ".partial";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << text;
    if (!f.flush()) return false;
  }
  if (executable) ::chmod(tmp.c_str(), 0755);
  std::error_code ec;
  fs::rename(tmp, path, ec);
  return !ec;
}

// A job script: the #SBATCH lines, then the command, its pid and exit status recorded under `name`
// (NAME may hold ${SLURM_ARRAY_TASK_ID}).
std::string script(const std::string& slurm_dir, const std::string& job_name, const std::string& log, const std::string& array,
                   const std::vector<std::string>& sbatch_args, const std::string& name, const std::string& command) {
  std::string s = "#!/bin/bash\n";
  s += "# Written by `lodstream slurm`: submit with sbatch (see README, \"Running on a cluster\").\n";
  s += "#SBATCH --job-name=" + job_name + "\n";
  s += "#SBATCH --output=" + slurm_dir + "/logs/" + log + "\n";
  if (!array.empty()) s += "#SBATCH --array=" + array + "\n";
  for (const std::string& a : sbatch_args) s += "#SBATCH " + a + "\n";
  s += "status=" + quote(slurm_dir + "/status") + "/" + name + "\n";
  s += "rm -f \"$status.rc\"\n";
  s += command + " &\n";
  s += "pid=$!\necho $pid > \"$status.pid\"\nwait $pid\nrc=$?\n";
  s += "echo $rc > \"$status.rc.partial\" && mv \"$status.rc.partial\" \"$status.rc\"\nrm -f \"$status.pid\"\nexit $rc\n";
  return s;
}

// sbatch --parsable [args] SCRIPT: the job id, or "" with a message.
std::string submit(const std::string& args, const std::string& script_path) {
  int status = 0;
  const std::string out = run("sbatch --parsable " + args + " " + quote(script_path) + " 2>&1", &status);
  if (status != 0) {
    std::fprintf(stderr, "lodstream slurm: sbatch %s failed (exit %d): %s\n", script_path.c_str(), status, out.c_str());
    return {};
  }
  return out.substr(0, out.find(';'));  // "id;cluster" on federated clusters
}

int read_rc(const std::string& path) {
  std::ifstream f(path);
  int rc = -1;
  if (!(f >> rc)) return -1;
  return rc;
}

struct Submission {
  std::string slurm_dir;
  unsigned shards = 0;
  std::vector<std::string> sbatch_args;
  bool ranges = false;  // the chain starts with the ingest array (ingest.sbatch); false: a submission of older code
  bool clusters = false;  // the cluster array (cluster.sbatch) runs before the tasks (simplify)
  bool grades = false;    // the grade array (grade.sbatch) runs before the cluster array (simplify)
  // A prepare job runs before the tasks (prepare.sbatch): a report's join. A simplify chain has none (its
  // tasks take up the shared stages' units); one submitted by an older build had, as an array of N
  // (`prepares`), which a resubmission of it keeps.
  bool prepare_job = true;
  bool prepares = false;
  std::string ingest, grade, cluster, prepare, tasks, merge;  // job ids
};

bool save(const Submission& s) {
  const ordered_json j{{"shards", s.shards},
                       {"sbatch_args", s.sbatch_args},
                       {"ingest_ranges", s.ranges},
                       {"grade_shares", s.grades},
                       {"cluster_shares", s.clusters},
                       {"prepare_job", s.prepare_job},
                       {"prepare_array", s.prepares},
                       {"jobs",
                        {{"ingest", s.ingest}, {"grade", s.grade}, {"cluster", s.cluster}, {"prepare", s.prepare}, {"tasks", s.tasks}, {"merge", s.merge}}}};
  return write_text(s.slurm_dir + "/submit.json", j.dump(2) + "\n", false);
}

// Submits the chain from its start when `from_start` (else the tasks in `array`, then the merge): the
// ingest ranges in `ingest_array` first when it is not empty.
// sbatch's dependency options: after `ok` succeeded and `any` ended (job ids; empty: no such job), or
// nothing when both are empty.
std::string dependency(const std::string& ok, const std::string& any = {}) {
  std::string deps = ok.empty() ? std::string() : "afterok:" + ok;
  if (!any.empty()) deps += (deps.empty() ? "" : ",") + std::string("afterany:") + any;
  return deps.empty() ? std::string() : "--kill-on-invalid-dep=yes --dependency=" + deps + " ";
}

int submit_chain(Submission& s, bool from_start, const std::string& array, const std::string& ingest_array) {
  std::string after_ok, after_any;  // the tasks' dependencies
  s.ingest.clear();
  s.grade.clear();
  s.cluster.clear();
  if (from_start && !ingest_array.empty()) {
    s.ingest = submit("--array=" + ingest_array, s.slurm_dir + "/ingest.sbatch");
    if (s.ingest.empty()) return kIoError;
  }
  const std::string all_shares = fmt::format("--array=0-{}", s.shards - 1);
  if (from_start && s.grades) {
    s.grade = submit(dependency(s.ingest) + all_shares, s.slurm_dir + "/grade.sbatch");
    if (s.grade.empty()) return kIoError;
  }
  if (from_start && s.clusters) {
    s.cluster = submit(dependency(s.ingest, s.grade) + all_shares, s.slurm_dir + "/cluster.sbatch");
    if (s.cluster.empty()) return kIoError;
  }
  if (from_start && s.prepare_job) {
    s.prepare = submit(dependency(s.ingest, s.cluster) + (s.prepares ? all_shares : std::string()), s.slurm_dir + "/prepare.sbatch");
    if (s.prepare.empty()) return kIoError;
    after_ok = s.prepare;
  } else if (from_start) {  // the tasks run the shared stages' units, and any share that did not finish
    after_ok = s.ingest, after_any = s.cluster;
  }
  s.tasks = submit(dependency(after_ok, after_any) + "--array=" + array, s.slurm_dir + "/tasks.sbatch");
  if (s.tasks.empty()) return kIoError;
  s.merge = submit(dependency(s.tasks), s.slurm_dir + "/merge.sbatch");
  if (s.merge.empty()) return kIoError;
  if (!save(s)) {
    std::fprintf(stderr, "lodstream slurm: cannot write %s/submit.json\n", s.slurm_dir.c_str());
    return kIoError;
  }
  if (!s.ingest.empty()) std::printf("ingest  job %s (array %s of %u)\n", s.ingest.c_str(), ingest_array.c_str(), s.shards);
  if (!s.grade.empty()) std::printf("grade   job %s (array 0-%u of %u)\n", s.grade.c_str(), s.shards - 1, s.shards);
  if (!s.cluster.empty()) std::printf("cluster job %s (array 0-%u of %u)\n", s.cluster.c_str(), s.shards - 1, s.shards);
  if (!s.prepare.empty() && s.prepares) std::printf("prepare job %s (array 0-%u of %u)\n", s.prepare.c_str(), s.shards - 1, s.shards);
  else if (!s.prepare.empty()) std::printf("prepare job %s\n", s.prepare.c_str());
  std::printf("tasks   job %s (array %s of %u)\nmerge   job %s\n", s.tasks.c_str(), array.c_str(), s.shards, s.merge.c_str());
  std::fflush(stdout);
  return 0;
}

// The prepare job's exit code (nonzero or -1: it failed or did not finish), and its name: with an array,
// the first job of the array that did not succeed.
std::pair<int, std::string> prepare_failure(const Submission& s) {
  const std::string st = s.slurm_dir + "/status/";
  if (!s.prepares) return {read_rc(st + "prepare.rc"), "the prepare job"};
  for (unsigned i = 0; i < s.shards; ++i)
    if (const int rc = read_rc(st + fmt::format("prepare-{}.rc", i)); rc != 0) return {rc, fmt::format("prepare job {}", i)};
  return {0, ""};
}

// Waits until the merge has recorded its status, or none of the chain's jobs is queued any more (a failed
// task's merge is cancelled by Slurm, --kill-on-invalid-dep; the other tasks are left to finish, so that a
// resubmission reruns the failed ones only); returns the one-machine exit code: the merge's, else the
// first failed ingest range's, the prepare job's or the first failed task's (a task killed by a signal
// records 128 + the signal).
int wait_chain(const Submission& s, const std::vector<unsigned>& tasks, const std::vector<unsigned>& ranges) {
  const std::string st = s.slurm_dir + "/status/";
  std::string ids = s.prepare.empty() ? (s.tasks.empty() ? s.merge : s.tasks + "," + s.merge) : s.prepare + "," + s.tasks + "," + s.merge;
  if (!s.cluster.empty()) ids = s.cluster + "," + ids;
  if (!s.grade.empty()) ids = s.grade + "," + ids;
  if (!s.ingest.empty()) ids = s.ingest + "," + ids;
  for (;;) {
    const int merge_rc = read_rc(st + "merge.rc");
    if (merge_rc >= 0) return merge_rc;
    int status = 0;
    const std::string queued = run("squeue -h -o %i -j " + ids + " 2>/dev/null", &status);
    if (status != 0 || !queued.empty()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      continue;
    }
    if (const int rc = read_rc(st + "merge.rc"); rc >= 0) return rc;
    int failed = -1;
    std::string failed_name;
    for (unsigned r : ranges) {
      const int rc = read_rc(st + fmt::format("ingest-{}.rc", r));
      if (rc > 0) {
        failed = rc, failed_name = fmt::format("ingest range {}", r);
        break;
      }
    }
    if (failed < 0 && !s.prepare.empty())
      if (const auto [rc, name] = prepare_failure(s); rc != 0) failed = rc, failed_name = name;
    for (unsigned t : tasks) {
      if (failed >= 0) break;
      const int rc = read_rc(st + fmt::format("task-{}.rc", t));
      if (rc > 0) failed = rc, failed_name = fmt::format("task {}", t);
    }
    if (failed > 0) {
      std::fprintf(stderr, "lodstream slurm: %s failed with exit %d (logs: %s/logs/); `lodstream slurm resubmit %s` reruns what did not finish\n",
                   failed_name.c_str(), failed, s.slurm_dir.c_str(), quote(fs::path(s.slurm_dir).parent_path().string()).c_str());
      return failed;
    }
    std::fprintf(stderr, "lodstream slurm: the jobs ended without recording a status (cancelled, or killed with their scripts); see %s/logs/\n",
                 s.slurm_dir.c_str());
    return kInternal;
  }
}

// Whether the chain of `command` on `input` parses it in byte ranges first (--ingest-ranges auto). A range
// task parses its bytes into a segment that the join reads back to write the store, so the ranges pay only
// where parsing costs more than that round trip: text (OBJ, ASCII PLY and STL). A binary input's parse is
// about a copy: on the 193 M-triangle city (binary PLY, 4.15 GB; one node, 8 ranges) the range array took
// 14-15 s and the join 10.7-11.1 s, where one machine's whole ingest took 8.0-10.6 s. A report's input is
// the original named in the simplify run's manifest. An input whose format cannot be read here: ranges
// (the jobs then report the error as one machine would).
bool ranges_pay(const std::string& command, const std::string& input) {
  std::string format;
  if (command == "simplify") {
    if (!lodstream::input_format(input, &format).ok()) return true;
  } else {
    std::ifstream f(input + "/manifest.json");
    const ordered_json m = ordered_json::parse(f, nullptr, false);
    if (m.is_discarded() || !m.contains("input") || !m["input"].contains("format") || !m["input"]["format"].is_string()) return true;
    format = m["input"]["format"].get<std::string>();
  }
  return format == "obj" || format == "ply-ascii" || format == "stl-ascii";
}

// `command`: simplify (INPUT: the input file) or report (INPUT: a simplify output directory).
int submit_sharded(const std::string& self, const std::vector<std::string>& args, const std::string& command) {
  std::string input, out, work, ranges = "auto";
  unsigned shards = 0;
  bool wait = false;
  std::vector<std::string> sbatch_args, passthrough;
  if (args.empty() || args[0].empty() || args[0][0] == '-') {
    std::fputs(kUsageText, stderr);
    return kUsage;
  }
  input = args[0];
  for (size_t i = 1; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&](const std::string& name, std::string* v) {
      if (a == name) {
        if (i + 1 >= args.size()) return false;
        *v = args[++i];
        return true;
      }
      if (a.rfind(name + "=", 0) == 0) {
        *v = a.substr(name.size() + 1);
        return true;
      }
      return false;
    };
    std::string v;
    if (value("-o", &v) || value("--output", &v)) out = v;
    else if (value("--work", &v)) work = v;
    else if (value("--sbatch-arg", &v)) sbatch_args.push_back(v);
    else if (value("--ingest-ranges", &v)) {
      if (v != "auto" && v != "yes" && v != "no") {
        std::fprintf(stderr, "lodstream slurm: --ingest-ranges: '%s' is not auto, yes or no\n", v.c_str());
        return kUsage;
      }
      ranges = v;
    }
    else if (value("--shards", &v)) {
      char* end = nullptr;
      const unsigned long n = std::strtoul(v.c_str(), &end, 10);
      if (*end || n == 0 || n > 100000) {
        std::fprintf(stderr, "lodstream slurm: --shards: '%s' is not a task count (1 to 100000)\n", v.c_str());
        return kUsage;
      }
      shards = static_cast<unsigned>(n);
    } else if (a == "--wait") wait = true;
    else if (a == "--shard" || a == "--shard-from-env" || a == "--shard-prepare" || a.rfind("--shard=", 0) == 0 ||
             a == "--shard-ingest" || a.rfind("--shard-ingest=", 0) == 0 || a == "--shard-cluster" ||
             a.rfind("--shard-cluster=", 0) == 0 || a == "--cluster-shards" || a.rfind("--cluster-shards=", 0) == 0 ||
             a == "--shard-grade" || a.rfind("--shard-grade=", 0) == 0) {
      std::fprintf(stderr, "lodstream slurm: %s is for the tasks; give --shards N\n", a.c_str());
      return kUsage;
    } else passthrough.push_back(a);
  }
  if (out.empty() || shards == 0) {
    std::fputs(kUsageText, stderr);
    return kUsage;
  }
  std::error_code ec;
  if (command == "simplify" ? !fs::is_regular_file(input, ec) : !fs::is_directory(input, ec)) {
    std::fprintf(stderr, "lodstream slurm: %s: no such %s\n", input.c_str(), command == "simplify" ? "input file" : "simplify output directory");
    return kNoInput;
  }
  input = absolute(input), out = absolute(out);
  Submission s;
  s.slurm_dir = out + "/slurm";
  s.shards = shards;
  s.sbatch_args = sbatch_args;
  s.ranges = ranges == "yes" || (ranges == "auto" && ranges_pay(command, input));
  s.clusters = command == "simplify";
  s.grades = command == "simplify";
  s.prepare_job = command == "report";  // a simplify task takes up the shared stages' units itself
  work = work.empty() ? s.slurm_dir + "/work" : absolute(work);
  for (const char* d : {"", "/logs", "/status"}) fs::create_directories(s.slurm_dir + d, ec);
  if (ec) {
    std::fprintf(stderr, "lodstream slurm: %s: cannot create: %s\n", s.slurm_dir.c_str(), ec.message().c_str());
    return kIoError;
  }
  for (const auto& e : fs::directory_iterator(s.slurm_dir + "/status", ec)) fs::remove(e.path(), ec);
  // A script of an earlier submission into OUTDIR whose job this chain does not have (an older build's
  // prepare array, an ingest array where ranges do not pay) goes, so that the scripts there are the chain.
  for (const auto& [job, in_chain] : {std::pair{"ingest", s.ranges}, {"grade", s.grades}, {"cluster", s.clusters}, {"prepare", s.prepare_job}})
    if (!in_chain) fs::remove(s.slurm_dir + "/" + job + ".sbatch", ec);
  std::string common = quote(self) + " " + command + " " + quote(input) + " -o " + quote(out) + " --work " + quote(work);
  for (const std::string& a : passthrough) common += " " + quote(a);
  const std::string tasks_array = fmt::format("0-{}", shards - 1);
  const bool ok =
      (!s.ranges ||
       write_text(s.slurm_dir + "/ingest.sbatch",
                  script(s.slurm_dir, "lodstream-ingest", "ingest-%a.out", tasks_array, sbatch_args, "ingest-${SLURM_ARRAY_TASK_ID}",
                         common + fmt::format(" --shard-ingest \"${{SLURM_ARRAY_TASK_ID}}/{}\"", shards)),
                  true)) &&
      (!s.grades ||
       write_text(s.slurm_dir + "/grade.sbatch",
                  script(s.slurm_dir, "lodstream-grade", "grade-%a.out", tasks_array, sbatch_args, "grade-${SLURM_ARRAY_TASK_ID}",
                         common + fmt::format(" --shard-grade \"${{SLURM_ARRAY_TASK_ID}}/{}\"", shards)),
                  true)) &&
      (!s.clusters ||
       write_text(s.slurm_dir + "/cluster.sbatch",
                  script(s.slurm_dir, "lodstream-cluster", "cluster-%a.out", tasks_array, sbatch_args, "cluster-${SLURM_ARRAY_TASK_ID}",
                         common + fmt::format(" --shard-cluster \"${{SLURM_ARRAY_TASK_ID}}/{}\"", shards)),
                  true)) &&
      (!s.prepare_job ||
       write_text(s.slurm_dir + "/prepare.sbatch",
                  script(s.slurm_dir, "lodstream-prepare", "prepare.out", "", sbatch_args, "prepare", common + " --shard-prepare"), true)) &&
      write_text(s.slurm_dir + "/tasks.sbatch",
                 script(s.slurm_dir, "lodstream-" + command, "task-%a.out", tasks_array, sbatch_args, "task-${SLURM_ARRAY_TASK_ID}",
                        common + fmt::format(" --shard \"${{SLURM_ARRAY_TASK_ID}}/{}\"", shards) +
                            (s.clusters ? fmt::format(" --cluster-shards {}", shards) : std::string())),
                 true) &&
      write_text(s.slurm_dir + "/merge.sbatch",
                 script(s.slurm_dir, "lodstream-merge", "merge.out", "", sbatch_args, "merge", quote(self) + " merge " + quote(out)), true);
  if (!ok) {
    std::fprintf(stderr, "lodstream slurm: cannot write the scripts in %s\n", s.slurm_dir.c_str());
    return kIoError;
  }
  std::printf("scripts %s/{%s%s%s%stasks,merge}.sbatch\n", s.slurm_dir.c_str(), s.ranges ? "ingest," : "", s.grades ? "grade," : "",
              s.clusters ? "cluster," : "", s.prepare_job ? "prepare," : "");
  if (const int rc = submit_chain(s, true, tasks_array, s.ranges ? tasks_array : std::string())) return rc;
  if (!wait) return 0;
  std::vector<unsigned> all(shards);
  for (unsigned t = 0; t < shards; ++t) all[t] = t;
  return wait_chain(s, all, s.ranges ? all : std::vector<unsigned>());
}

int resubmit(const std::vector<std::string>& args) {
  std::string out;
  bool wait = false;
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--wait") wait = true;
    else if (out.empty() && args[i][0] != '-') out = args[i];
    else {
      std::fputs(kUsageText, stderr);
      return kUsage;
    }
  }
  if (out.empty()) {
    std::fputs(kUsageText, stderr);
    return kUsage;
  }
  Submission s;
  s.slurm_dir = absolute(out) + "/slurm";
  ordered_json j;
  try {
    std::ifstream f(s.slurm_dir + "/submit.json");
    j = ordered_json::parse(f);
    s.shards = j.at("shards");
    s.sbatch_args = j.at("sbatch_args").get<std::vector<std::string>>();
    s.ranges = j.value("ingest_ranges", false);
    s.clusters = j.value("cluster_shares", false);
    s.grades = j.value("grade_shares", false);
    s.prepare_job = j.value("prepare_job", true);
    s.prepares = j.value("prepare_array", false);
  } catch (const std::exception&) {
    std::fprintf(stderr, "lodstream slurm: %s/submit.json: no submission to resubmit (run `lodstream slurm simplify` first)\n",
                 s.slurm_dir.c_str());
    return kNoInput;
  }
  std::string old;
  for (const char* job : {"ingest", "grade", "cluster", "prepare", "tasks", "merge"})
    if (const std::string id = j["jobs"].value(job, ""); !id.empty()) old += (old.empty() ? "" : ",") + id;
  int status = 0;
  const std::string queued = run("squeue -h -o %i -j " + old + " 2>/dev/null", &status);
  if (status == 0 && !queued.empty()) {
    std::fprintf(stderr, "lodstream slurm: jobs of the last submission are still queued or running (%s): wait for them or scancel them first\n",
                 queued.c_str());
    return kUsage;
  }
  const std::string st = s.slurm_dir + "/status/";
  // From the start when the shared stages did not finish: the prepare job failed, or, where the tasks run
  // them, no task finished.
  bool from_start = s.prepare_job ? prepare_failure(s).first != 0 : true;
  for (unsigned t = 0; t < s.shards && !s.prepare_job; ++t)
    if (read_rc(st + fmt::format("task-{}.rc", t)) == 0) from_start = false;
  std::vector<unsigned> tasks;
  std::string array;
  for (unsigned t = 0; t < s.shards; ++t)
    if (from_start || read_rc(st + fmt::format("task-{}.rc", t)) != 0) {
      tasks.push_back(t);
      array += (array.empty() ? "" : ",") + std::to_string(t);
      std::error_code ec;
      fs::remove(st + fmt::format("task-{}.rc", t), ec);
    }
  // The ingest ranges that did not finish run again first (those that did left their segments, or the
  // next step joined them already).
  std::vector<unsigned> ranges;
  std::string ingest_array;
  for (unsigned r = 0; r < s.shards && s.ranges && from_start; ++r)
    if (read_rc(st + fmt::format("ingest-{}.rc", r)) != 0) {
      ranges.push_back(r);
      ingest_array += (ingest_array.empty() ? "" : ",") + std::to_string(r);
      std::error_code ec;
      fs::remove(st + fmt::format("ingest-{}.rc", r), ec);
    }
  std::error_code ec;
  fs::remove(st + "merge.rc", ec);
  if (from_start) fs::remove(st + "prepare.rc", ec);
  for (unsigned t = 0; t < s.shards && from_start; ++t)
    fs::remove(st + fmt::format("cluster-{}.rc", t), ec), fs::remove(st + fmt::format("grade-{}.rc", t), ec),
        fs::remove(st + fmt::format("prepare-{}.rc", t), ec);
  if (tasks.empty()) {
    std::printf("every task finished; resubmitting the merge\n");
    s.prepare.clear();
    s.tasks.clear();
    s.merge = submit("", s.slurm_dir + "/merge.sbatch");
    if (s.merge.empty()) return kIoError;
    save(s);
    std::printf("merge   job %s\n", s.merge.c_str());
    std::fflush(stdout);
    if (!wait) return 0;
    return wait_chain(s, {}, {});
  }
  if (!from_start) s.prepare.clear();
  if (const int rc = submit_chain(s, from_start, array, ingest_array)) return rc;
  if (!wait) return 0;
  return wait_chain(s, tasks, ranges);
}

}  // namespace

int run_slurm(const std::string& self, const std::vector<std::string>& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kUsageText, args.empty() ? stderr : stdout);
    return args.empty() ? kUsage : 0;
  }
  const std::vector<std::string> rest(args.begin() + 1, args.end());
  if (args[0] == "simplify" || args[0] == "report") return submit_sharded(self, rest, args[0]);
  if (args[0] == "resubmit") return resubmit(rest);
  std::fputs(kUsageText, stderr);
  return kUsage;
}

}  // namespace lodstream::cli
