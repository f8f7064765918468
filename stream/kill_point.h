// Test-only crash points. With LODSTREAM_TEST_KILL_AT=NAME (or NAME,NAME,...) in the environment, the process
// kills itself (SIGKILL, as `kill -9` would) when it reaches kill_point(NAME). The points sit where the progress stream
// cannot stop a run: just before a stage's stamp (or an output directory's last file) is written, after
// every file it vouches for is in place. tests/test_crash.cpp resumes from them. Never in a hot loop: the
// environment is read once.
#pragma once

#include <signal.h>

#include <cstdlib>
#include <string_view>

namespace lodstream::stream {

inline void kill_point(std::string_view name) {
  static const char* const at = std::getenv("LODSTREAM_TEST_KILL_AT");
  if (!at) return;
  for (std::string_view rest = at; !rest.empty();) {  // NAME, or several: NAME,NAME
    const size_t comma = rest.find(',');
    if (rest.substr(0, comma) == name) ::raise(SIGKILL);
    rest = comma == std::string_view::npos ? std::string_view() : rest.substr(comma + 1);
  }
}

}  // namespace lodstream::stream
