// The processes the job server offers (simplify, report, grid): their OGC API - Processes descriptions,
// with inputs and outputs as JSON Schema, the validation of an execute request against them, and the
// command lines (argv, never a shell) a job runs.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace lodstream::serve {

using ojson = nlohmann::ordered_json;

// One process's description (GET /processes/{id}); nullptr for an unknown id.
const ojson* process_description(const std::string& id);
// Ids in the order GET /processes lists them.
const std::vector<std::string>& process_ids();

struct PlanContext {
  std::string data_root;    // canonical (realpath)
  std::string uploads_dir;  // canonical; "upload:<id>/<name>" inputs resolve under it
  std::string jobs_dir;     // canonical; the report process reads another job's outputs
  std::string job_dir;      // this job's directory (out/ and work/ go under it)
  uint64_t server_memory = 0;
  unsigned max_jobs = 1;
  unsigned job_threads = 0;
};

struct JobPlan {
  std::vector<std::vector<std::string>> steps;  // each the argv after the program name
  std::vector<std::string> step_names;
  uint64_t memory_bytes = 0;
};

struct PlanError {
  std::string field;   // "inputs.levels", "inputs.input", ... (empty for the body as a whole)
  std::string detail;  // one line, names the field
};

// Validates an execute request's body ({"inputs": {...}}) against the process's schema and builds the
// job's steps. False with *error on any problem: a type, range or enum mismatch, an unknown or missing
// input, a path outside the data root, a memory cap the server cannot give.
bool plan_job(const std::string& process, const nlohmann::json& body, const PlanContext& ctx, JobPlan* plan,
              PlanError* error);

// A job or upload id as the server makes them: 32 lowercase hex digits.
bool is_job_id(const std::string& s);

// realpath(3) of `path`; empty when it does not resolve.
std::string canonical(const std::string& path);

// The canonical path of `path` when it names an existing regular file under `root` (both canonical);
// empty otherwise. Symlinks are followed, so a link under the root that points outside is refused.
std::string resolve_under(const std::string& root, const std::string& path);

}  // namespace lodstream::serve
