// The job server's queue: job state on disk, admission by count and memory, and one child process per
// running job (fork + execv of the lodstream CLI with an argv; no shell).
//
// Invariants: at most max_jobs children run at once and their --memory caps add up to at most the
// server's; a job's state file (jobs-dir/<id>/job.json) is replaced atomically on every change, so a
// server killed at any point restarts from a consistent set of jobs; a job's directory is locked (flock on
// jobs-dir/<id>/lock) by the child that runs it, so a child orphaned by a killed server keeps the job to
// itself until it has exited, and the restarted server only then runs the job again.
#pragma once

#include <sys/types.h>

#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "server/processes.h"

namespace lodstream::serve {

struct Job {
  std::string id, process;
  nlohmann::json inputs;
  std::vector<std::vector<std::string>> steps;
  std::vector<std::string> step_names;
  uint64_t memory_bytes = 0;
  uint64_t seq = 0;                      // submission order: the queue is first in, first out
  std::string status = "accepted";       // accepted, running, successful, failed, dismissed
  std::string stage, message;
  int progress = 0;                      // percent over all steps
  size_t step = 0;                       // the step running or to run next
  unsigned runs = 0;                     // child processes started for this job (more than its steps: resumed)
  double created = 0, started = 0, finished = 0, updated = 0;  // Unix seconds; 0 = not yet
  // While a child runs (not saved):
  pid_t pid = -1;
  int pipe_fd = -1;                      // the child's stderr (NDJSON progress, then its error line)
  int lock_fd = -1;
  std::string pending;                   // a partial stderr line
  std::string error_line;                // the child's last non-progress line
  bool dismiss_requested = false;
  double term_sent = 0;                  // when the server sent SIGTERM (drain or dismiss)
};

class JobManager {
 public:
  JobManager(std::string jobs_dir, std::string cli, unsigned max_jobs, uint64_t memory_bytes);
  ~JobManager();
  // Locks the jobs directory against a second server and loads its jobs: those that were running are
  // queued again (their work directories make them resume). False with *error when unusable.
  bool open(std::string* error);
  void start();  // the monitor thread: starts queued jobs, reads progress, reaps children
  // Stops starting jobs, sends SIGTERM to the running ones, waits until every child has exited (queued
  // again, to resume at the next start), and stops the monitor thread.
  void drain();

  std::string new_id() const;  // 128 random bits from getrandom, as 32 hex digits
  // Saves and queues a planned job under `id` (its directory made by the caller's plan context).
  bool submit(const std::string& id, const std::string& process, const nlohmann::json& inputs, const JobPlan& plan,
              std::string* error);
  bool accepting() const;
  // The job's OGC statusInfo; false for an unknown id.
  bool status(const std::string& id, ojson* out);
  ojson list();
  // Cancels (a running job's child gets SIGTERM) and dismisses: the job's work and output directories are
  // removed. False for an unknown id.
  bool dismiss(const std::string& id, ojson* out);
  // The output directory of a successful job; empty otherwise.
  std::string output_dir(const std::string& id);
  std::string job_dir(const std::string& id) const { return jobs_dir_ + "/" + id; }

 private:
  void monitor();
  void start_ready(double now);      // with mutex_ held
  bool spawn(Job& job, std::string* error);
  void read_output(Job& job);
  void on_line(Job& job, const std::string& line);
  void reap(Job& job, int wait_status, double now);
  void save(const Job& job);
  ojson status_info(const Job& job) const;
  void remove_outputs(const Job& job);

  std::string jobs_dir_, cli_;
  unsigned max_jobs_;
  uint64_t memory_bytes_;
  int dir_lock_fd_ = -1;
  mutable std::mutex mutex_;
  std::map<std::string, std::unique_ptr<Job>> jobs_;
  uint64_t next_seq_ = 1;
  bool draining_ = false, stop_ = false;
  std::thread thread_;
  int wake_[2] = {-1, -1};  // a pipe that wakes the monitor's poll()
};

}  // namespace lodstream::serve
