// `lodstream serve`: a job server in the shape of OGC API - Processes - Part 1 (OGC 18-062r2). A layer
// above the library like the CLI: every job runs the lodstream CLI binary itself as a child process, so a
// crash or a kill of a job never takes the server down, and the CLI's work-directory resume is what makes
// jobs survive a restart of the server.
#pragma once

#include <cstdint>
#include <string>

namespace lodstream::serve {

struct ServeOptions {
  std::string bind = "127.0.0.1:8080";  // HOST:PORT; port 0 picks a free port (printed on stdout)
  std::string data_root;                // job inputs are files under it (realpath, symlinks followed)
  std::string jobs_dir;                 // job state, work directories, outputs and uploads
  std::string token_file;               // when set, every request needs "Authorization: Bearer <token>"
  std::string cli;                      // the lodstream binary the jobs run (normally /proc/self/exe)
  unsigned max_jobs = 1;                // jobs running at once
  uint64_t memory_bytes = 0;            // the running jobs' --memory caps add up to at most this
  unsigned job_threads = 0;             // each job's --threads (0 = all cores)
  uint64_t max_upload_bytes = 1ull << 30;
  int timeout_seconds = 10;             // read and write timeout of a connection
};

// Runs until SIGTERM or SIGINT, then drains: nothing new starts, running jobs are stopped at their next
// progress tick (their work directories keep what is done) and queued again for the next start.
// Returns the process exit status (0, or 64 for bad options, 74 when the jobs directory is unusable).
int run(const ServeOptions& options);

}  // namespace lodstream::serve
