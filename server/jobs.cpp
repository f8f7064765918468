// Job queue and child processes of `lodstream serve` (see jobs.h for the invariants).
#include "server/jobs.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/status.h"
#include "io/file_writer.h"

namespace lodstream::serve {
namespace {

namespace fs = std::filesystem;

double now_seconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

std::string iso_time(double t) {
  const std::time_t s = static_cast<std::time_t>(t);
  std::tm tm {};
  gmtime_r(&s, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// Where each stage of a step lies within the step, as [begin, end) fractions: the overall percent grows
// monotonically through the stages in the order the CLI reports them. A stage not listed leaves it as is.
struct StageSpan {
  const char* name;
  double begin, end;
};
constexpr StageSpan kSimplifyStages[] = {{"ingest", 0, .15}, {"triangulate", .15, .2}, {"weld", .2, .25},
                                         {"census", .25, .3}, {"grade", .3, .45},      {"sort", .45, .55},
                                         {"cluster", .55, .75}, {"emit", .75, .95},     {"write", .95, 1}};
constexpr StageSpan kReportStages[] = {{"ingest", 0, .1}, {"triangulate", .1, .15}, {"weld", .15, .2},
                                       {"census", .2, .25}, {"load", .25, .4},       {"measure", .4, 1}};
constexpr StageSpan kGridStages[] = {{"read", 0, .1}, {"subdivide", .1, .6}, {"measure", .6, .8}, {"write", .8, 1}};

double step_fraction(const std::string& step, const std::string& stage, double fraction) {
  auto find = [&](const auto& spans) {
    for (const StageSpan& s : spans)
      if (stage == s.name) return s.begin + (s.end - s.begin) * std::clamp(fraction, 0.0, 1.0);
    return -1.0;
  };
  if (step == "simplify") return find(kSimplifyStages);
  if (step == "report") return find(kReportStages);
  return find(kGridStages);
}

const char* signal_text(int sig) {
  const char* s = ::sigdescr_np(sig);
  return s ? s : "unknown signal";
}

}  // namespace

JobManager::JobManager(std::string jobs_dir, std::string cli, unsigned max_jobs, uint64_t memory_bytes)
    : jobs_dir_(std::move(jobs_dir)), cli_(std::move(cli)), max_jobs_(max_jobs), memory_bytes_(memory_bytes) {}

JobManager::~JobManager() {
  if (thread_.joinable()) drain();
  for (int fd : wake_)
    if (fd >= 0) ::close(fd);
  if (dir_lock_fd_ >= 0) ::close(dir_lock_fd_);
}

bool JobManager::open(std::string* error) {
  dir_lock_fd_ = ::open((jobs_dir_ + "/server.lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (dir_lock_fd_ < 0) {
    *error = "cannot create " + jobs_dir_ + "/server.lock: " + std::strerror(errno);
    return false;
  }
  if (::flock(dir_lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    *error = "another lodstream serve uses the jobs directory " + jobs_dir_;
    return false;
  }
  if (::pipe2(wake_, O_CLOEXEC | O_NONBLOCK) != 0) {
    *error = std::string("pipe: ") + std::strerror(errno);
    return false;
  }
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(jobs_dir_, ec)) {
    const std::string name = entry.path().filename().string();
    std::ifstream in(entry.path() / "job.json");
    if (name.size() != 32 || !in) continue;
    try {
      const nlohmann::json j = nlohmann::json::parse(in);
      auto job = std::make_unique<Job>();
      job->id = name;
      job->process = j.at("process").get<std::string>();
      job->inputs = j.at("inputs");
      job->steps = j.at("steps").get<std::vector<std::vector<std::string>>>();
      job->step_names = j.at("step_names").get<std::vector<std::string>>();
      job->memory_bytes = j.at("memory_bytes").get<uint64_t>();
      job->seq = j.at("seq").get<uint64_t>();
      job->status = j.at("status").get<std::string>();
      job->stage = j.value("stage", "");
      job->message = j.value("message", "");
      job->progress = j.value("progress", 0);
      job->step = j.value("step", size_t{0});
      job->runs = j.value("runs", 0u);
      job->created = j.value("created", 0.0);
      job->started = j.value("started", 0.0);
      job->finished = j.value("finished", 0.0);
      job->updated = j.value("updated", 0.0);
      if (job->status == "running") {
        job->status = "accepted";
        job->message = "interrupted by a server restart; resumes from its work directory";
        save(*job);
      }
      next_seq_ = std::max(next_seq_, job->seq + 1);
      jobs_[name] = std::move(job);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "lodstream serve: skipping %s: unreadable job.json (%s)\n", name.c_str(), e.what());
    }
  }
  return true;
}

void JobManager::start() { thread_ = std::thread([this] { monitor(); }); }

void JobManager::drain() {
  {
    std::lock_guard lock(mutex_);
    draining_ = true;
    stop_ = true;
  }
  const char c = 'd';
  (void)!::write(wake_[1], &c, 1);
  if (thread_.joinable()) thread_.join();
}

bool JobManager::accepting() const {
  std::lock_guard lock(mutex_);
  return !draining_;
}

std::string JobManager::new_id() const {
  unsigned char bytes[16];
  size_t got = 0;
  while (got < sizeof bytes) {
    const ssize_t n = ::getrandom(bytes + got, sizeof bytes - got, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) std::abort();  // the kernel has no entropy source to give: ids would be guessable
    got += static_cast<size_t>(n);
  }
  static const char hex[] = "0123456789abcdef";
  std::string id;
  for (unsigned char b : bytes) {
    id += hex[b >> 4];
    id += hex[b & 15];
  }
  return id;
}

bool JobManager::submit(const std::string& id, const std::string& process, const nlohmann::json& inputs,
                        const JobPlan& plan, std::string* error) {
  auto job = std::make_unique<Job>();
  job->id = id;
  job->process = process;
  job->inputs = inputs;
  job->steps = plan.steps;
  job->step_names = plan.step_names;
  job->memory_bytes = plan.memory_bytes;
  job->created = job->updated = now_seconds();
  job->message = "queued";
  std::lock_guard lock(mutex_);
  if (draining_) {
    *error = "the server is shutting down";
    return false;
  }
  job->seq = next_seq_++;
  save(*job);
  jobs_[id] = std::move(job);
  const char c = 's';
  (void)!::write(wake_[1], &c, 1);
  return true;
}

void JobManager::save(const Job& job) {
  const nlohmann::json j = {{"process", job.process},   {"inputs", job.inputs},         {"steps", job.steps},
                            {"step_names", job.step_names}, {"memory_bytes", job.memory_bytes}, {"seq", job.seq},
                            {"status", job.status},     {"stage", job.stage},           {"message", job.message},
                            {"progress", job.progress}, {"step", job.step},             {"runs", job.runs},
                            {"created", job.created},   {"started", job.started},       {"finished", job.finished},
                            {"updated", job.updated}};
  // Durable: a server killed now (or the machine) finds either the old state or the new one.
  try {
    io::write_file_atomic(job_dir(job.id) + "/job.json", j.dump(), io::Sync::durable);
  } catch (const Failure& e) {
    std::fprintf(stderr, "lodstream serve: %s\n", e.what());
  }
}

ojson JobManager::status_info(const Job& job) const {
  ojson s = {{"jobID", job.id},      {"processID", job.process}, {"type", "process"},
             {"status", job.status}, {"message", job.message},   {"progress", job.progress}};
  if (!job.stage.empty()) s["stage"] = job.stage;
  if (job.steps.size() > 1 && job.step < job.step_names.size()) s["step"] = job.step_names[job.step];
  s["created"] = iso_time(job.created);
  if (job.started > 0) s["started"] = iso_time(job.started);
  if (job.finished > 0) s["finished"] = iso_time(job.finished);
  s["updated"] = iso_time(job.updated);
  s["memory_bytes"] = job.memory_bytes;
  s["runs"] = job.runs;
  s["inputs"] = job.inputs;
  ojson links = ojson::array({{{"href", "/jobs/" + job.id}, {"rel", "self"}, {"type", "application/json"}, {"title", "status"}}});
  if (job.status == "successful")
    links.push_back({{"href", "/jobs/" + job.id + "/results"},
                     {"rel", "http://www.opengis.net/def/rel/ogc/1.0/results"},
                     {"type", "application/json"},
                     {"title", "results"}});
  s["links"] = links;
  return s;
}

bool JobManager::status(const std::string& id, ojson* out) {
  std::lock_guard lock(mutex_);
  const auto it = jobs_.find(id);
  if (it == jobs_.end()) return false;
  *out = status_info(*it->second);
  return true;
}

ojson JobManager::list() {
  std::lock_guard lock(mutex_);
  std::vector<const Job*> all;
  for (const auto& [id, job] : jobs_) all.push_back(job.get());
  std::sort(all.begin(), all.end(), [](const Job* a, const Job* b) { return a->seq > b->seq; });
  ojson jobs = ojson::array();
  for (const Job* j : all) jobs.push_back(status_info(*j));
  return jobs;
}

std::string JobManager::output_dir(const std::string& id) {
  std::lock_guard lock(mutex_);
  const auto it = jobs_.find(id);
  if (it == jobs_.end() || it->second->status != "successful") return {};
  return job_dir(id) + "/out";
}

void JobManager::remove_outputs(const Job& job) {
  std::error_code ec;
  fs::remove_all(job_dir(job.id) + "/out", ec);
  fs::remove_all(job_dir(job.id) + "/work", ec);
}

bool JobManager::dismiss(const std::string& id, ojson* out) {
  std::lock_guard lock(mutex_);
  const auto it = jobs_.find(id);
  if (it == jobs_.end()) return false;
  Job& job = *it->second;
  if (job.status != "dismissed") {
    if (job.pid > 0) {
      // The child stops at its next progress tick; reap() then removes what it leaves.
      job.dismiss_requested = true;
      job.term_sent = now_seconds();
      ::kill(job.pid, SIGTERM);
    } else {
      remove_outputs(job);
    }
    job.status = "dismissed";
    job.message = "dismissed by a client";
    job.updated = now_seconds();
    if (job.finished == 0) job.finished = job.updated;
    save(job);
  }
  *out = status_info(job);
  return true;
}

bool JobManager::spawn(Job& job, std::string* error) {
  const std::string dir = job_dir(job.id);
  std::vector<std::string> argv_s = {cli_};
  argv_s.insert(argv_s.end(), job.steps[job.step].begin(), job.steps[job.step].end());
  std::vector<char*> argv;
  for (auto& s : argv_s) argv.push_back(s.data());
  argv.push_back(nullptr);

  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0) {
    *error = std::string("pipe: ") + std::strerror(errno);
    return false;
  }
  const int log_fd = ::open((dir + "/log.txt").c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  const int null_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  if (log_fd < 0 || null_fd < 0) {
    *error = "cannot open " + dir + "/log.txt: " + std::strerror(errno);
    for (int fd : {pipe_fds[0], pipe_fds[1], log_fd, null_fd})
      if (fd >= 0) ::close(fd);
    return false;
  }
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Only async-signal-safe calls from here to execv: the server has other threads.
    ::setpgid(0, 0);  // a Ctrl-C at the server's terminal reaches the server, which drains
    // A server that dies (even by kill -9) stops its children too: SIGTERM lets them cancel at the next
    // progress tick, with their work directories resumable.
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(130);
    ::dup2(null_fd, 0);
    ::dup2(log_fd, 1);
    ::dup2(pipe_fds[1], 2);
    // The child holds the job's lock for as long as it lives (dup2 clears CLOEXEC; a lock already at 3
    // needs it cleared by hand).
    if (job.lock_fd == 3) ::fcntl(3, F_SETFD, 0);
    else ::dup2(job.lock_fd, 3);
    ::closefrom(4);
    sigset_t none;
    sigemptyset(&none);
    ::sigprocmask(SIG_SETMASK, &none, nullptr);
    ::signal(SIGPIPE, SIG_DFL);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  ::close(pipe_fds[1]);
  ::close(log_fd);
  ::close(null_fd);
  if (pid < 0) {
    ::close(pipe_fds[0]);
    *error = std::string("fork: ") + std::strerror(errno);
    return false;
  }
  ::fcntl(pipe_fds[0], F_SETFL, O_NONBLOCK);
  job.pid = pid;
  job.pipe_fd = pipe_fds[0];
  job.pending.clear();
  job.error_line.clear();
  ++job.runs;
  return true;
}

void JobManager::start_ready(double now) {
  unsigned running = 0;
  uint64_t memory = 0;
  std::vector<Job*> queue;
  for (auto& [id, job] : jobs_) {
    if (job->pid > 0) {
      ++running;
      memory += job->memory_bytes;
    } else if (job->status == "accepted") {
      queue.push_back(job.get());
    }
  }
  std::sort(queue.begin(), queue.end(), [](const Job* a, const Job* b) { return a->seq < b->seq; });
  for (Job* job : queue) {
    if (job->memory_bytes > memory_bytes_) {
      // Possible after a restart with a smaller --memory: such a job would hold the queue forever.
      job->status = "failed";
      job->message = "needs --memory " + std::to_string(job->memory_bytes >> 20) + "M, more than the server's " +
                     std::to_string(memory_bytes_ >> 20) + "M";
      job->finished = job->updated = now;
      save(*job);
      continue;
    }
    // First in, first out: a job that does not fit yet holds back those behind it, so a large job is
    // never starved by small ones.
    if (running >= max_jobs_ || memory + job->memory_bytes > memory_bytes_) break;
    const std::string lock_path = job_dir(job->id) + "/lock";
    job->lock_fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (job->lock_fd < 0 || ::flock(job->lock_fd, LOCK_EX | LOCK_NB) != 0) {
      // A child of a previous server still runs this job (it stops on its parent's death): wait for it.
      if (job->lock_fd >= 0) ::close(job->lock_fd);
      job->lock_fd = -1;
      job->message = "waiting for the previous server's process of this job to exit";
      continue;
    }
    std::string error;
    if (!spawn(*job, &error)) {
      ::close(job->lock_fd);
      job->lock_fd = -1;
      job->status = "failed";
      job->message = "cannot start the job: " + error;
      job->finished = job->updated = now;
      save(*job);
      continue;
    }
    ++running;
    memory += job->memory_bytes;
    job->status = "running";
    if (job->started == 0) job->started = now;
    job->message = job->runs > job->step + 1 ? "resumed from its work directory" : "running " + job->step_names[job->step];
    job->updated = now;
    save(*job);
  }
}

void JobManager::on_line(Job& job, const std::string& line) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(line);
  } catch (const std::exception&) {
    j = nullptr;
  }
  if (j.is_object() && j.contains("stage") && j.contains("fraction") && j["stage"].is_string() && j["fraction"].is_number()) {
    const std::string stage = j["stage"].get<std::string>();
    const double f = step_fraction(job.step_names[job.step], stage, j["fraction"].get<double>());
    const bool new_stage = stage != job.stage;
    job.stage = stage;
    if (f >= 0) {
      const int percent = static_cast<int>(100.0 * (static_cast<double>(job.step) + f) / static_cast<double>(job.steps.size()));
      job.progress = std::clamp(std::max(job.progress, percent), 0, 99);
    }
    job.updated = now_seconds();
    // GET answers from memory; the state file needs the stage only (a restart resumes from the work
    // directory whatever the percent was), and every save costs an fsync.
    if (new_stage) save(job);
    return;
  }
  if (line.empty()) return;
  job.error_line = line;
  std::ofstream(job_dir(job.id) + "/log.txt", std::ios::app) << line << '\n';
}

void JobManager::read_output(Job& job) {
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(job.pipe_fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    job.pending.append(buf, static_cast<size_t>(n));
    size_t nl;
    while ((nl = job.pending.find('\n')) != std::string::npos) {
      on_line(job, job.pending.substr(0, nl));
      job.pending.erase(0, nl + 1);
    }
    // A child that writes an endless line is not allowed to grow the server's memory.
    if (job.pending.size() > 65536) job.pending.clear();
  }
}

void JobManager::reap(Job& job, int wait_status, double now) {
  read_output(job);
  if (!job.pending.empty()) on_line(job, job.pending);
  ::close(job.pipe_fd);
  ::close(job.lock_fd);
  job.pipe_fd = job.lock_fd = -1;
  job.pid = -1;
  const bool exited = WIFEXITED(wait_status);
  const int code = exited ? WEXITSTATUS(wait_status) : -1;
  job.updated = now;
  if (job.dismiss_requested) {
    job.dismiss_requested = false;
    remove_outputs(job);
    job.status = "dismissed";
  } else if (exited && code == 0) {
    if (++job.step < job.steps.size()) {
      job.status = "accepted";  // the next step starts at once if the job still fits, as it did
      job.message = "starting " + job.step_names[job.step];
    } else {
      job.status = "successful";
      job.progress = 100;
      job.stage.clear();
      job.message = "done";
      job.finished = now;
    }
  } else if (draining_ && job.term_sent > 0) {
    job.status = "accepted";
    job.message = "interrupted by a server shutdown; resumes from its work directory at the next start";
  } else {
    job.status = "failed";
    job.finished = now;
    if (exited) {
      std::string line = job.error_line;
      if (line.rfind("lodstream: ", 0) == 0) line.erase(0, 11);
      job.message = "exit status " + std::to_string(code) + (line.empty() ? std::string() : ": " + line);
    } else {
      job.message = std::string("the job's process was killed by signal ") + std::to_string(WTERMSIG(wait_status)) + " (" +
                    signal_text(WTERMSIG(wait_status)) + ")";
    }
  }
  job.term_sent = 0;
  save(job);
}

void JobManager::monitor() {
  for (;;) {
    std::vector<pollfd> fds;
    std::vector<Job*> polled;
    {
      std::lock_guard lock(mutex_);
      const double now = now_seconds();
      bool any_running = false;
      for (auto& [id, job] : jobs_) {
        if (job->pid <= 0) continue;
        any_running = true;
        if (draining_ && job->term_sent == 0) {
          job->term_sent = now;
          ::kill(job->pid, SIGTERM);
        } else if (job->term_sent > 0 && now - job->term_sent > 30) {
          ::kill(job->pid, SIGKILL);  // a stage that ticks too rarely; the work directory still resumes
        }
      }
      if (stop_ && !any_running) return;
      if (!draining_) start_ready(now);
      fds.push_back({wake_[0], POLLIN, 0});
      for (auto& [id, job] : jobs_)
        if (job->pid > 0) {
          fds.push_back({job->pipe_fd, POLLIN, 0});
          polled.push_back(job.get());
        }
    }
    ::poll(fds.data(), fds.size(), 200);
    std::lock_guard lock(mutex_);
    char drainbuf[64];
    while (::read(wake_[0], drainbuf, sizeof drainbuf) > 0) {
    }
    const double now = now_seconds();
    for (Job* job : polled) {
      if (job->pid <= 0) continue;
      read_output(*job);
      int st = 0;
      const pid_t r = ::waitpid(job->pid, &st, WNOHANG);
      if (r == job->pid) reap(*job, st, now);
    }
  }
}

}  // namespace lodstream::serve
