// `lodstream slurm ...` (tools/slurm_cli.cpp): writes and submits the sbatch scripts of a sharded run.
#pragma once

#include <string>
#include <vector>

namespace lodstream::cli {

// args: what follows `lodstream slurm`; self: the lodstream binary the jobs run. Returns the exit code.
int run_slurm(const std::string& self, const std::vector<std::string>& args);

}  // namespace lodstream::cli
