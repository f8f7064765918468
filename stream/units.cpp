// Stamps; see units.h.
#include "stream/units.h"

#include <unistd.h>

namespace lodstream::stream {

std::string unit_runner() {
  char host[256] = {};
  ::gethostname(host, sizeof host - 1);
  return fmt::format("{}:{}", host, ::getpid());
}

nlohmann::ordered_json unit_figures(const std::vector<nlohmann::ordered_json>& values) {
  nlohmann::ordered_json seconds = nlohmann::ordered_json::array(), by = nlohmann::ordered_json::array();
  for (const auto& v : values) seconds.push_back(v.at("seconds")), by.push_back(v.at("by"));
  return {{"seconds", seconds}, {"by", by}};
}

bool stamp_matches(const std::string& path, const nlohmann::ordered_json& key, nlohmann::ordered_json* value) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return false;
  try {
    nlohmann::ordered_json j = nlohmann::ordered_json::parse(io::read_small_file(path));
    if (j.at("key") != key) return false;
    for (const auto& f : j.at("files"))
      if (!std::filesystem::exists(f.get<std::string>(), ec)) return false;
    *value = j.at("value");
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

void write_stamp(const std::string& path, const nlohmann::ordered_json& key, const std::vector<std::string>& files,
                 const nlohmann::ordered_json& value) {
  kill_point(std::filesystem::path(path).filename().string());
  io::write_file_atomic(path, nlohmann::ordered_json{{"key", key}, {"files", files}, {"value", value}}.dump(1) + "\n");
}

}  // namespace lodstream::stream
