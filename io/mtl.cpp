// MTL material libraries: see io/mtl.h.
#include "io/mtl.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <utility>
#include <vector>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/texture_mean.h"

namespace lodstream::io {

namespace {

constexpr uintmax_t kMaxLibraryBytes = 64 << 20;

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// Up to `n` numbers from `s`; returns how many were read.
int numbers(std::string_view s, float* out, int n) {
  int k = 0;
  const char* p = s.data();
  const char* end = p + s.size();
  while (k < n) {
    while (p < end && (*p == ' ' || *p == '\t')) ++p;
    if (p == end) break;
    float v;
    const auto [q, ec] = std::from_chars(p, end, v);
    if (ec != std::errc() || !std::isfinite(v)) break;
    out[k++] = v, p = q;
  }
  return k;
}

float unit(float v) { return v < 0 ? 0 : v > 1 ? 1 : v; }

}  // namespace

void MtlLibraries::parse(std::string_view text, const std::string& dir) {
  core::Material* m = nullptr;
  core::Material ignored;
  std::vector<std::pair<core::Material*, std::string>> textures;  // map_Kd, applied once Kd is known
  while (!text.empty()) {
    const size_t eol = text.find('\n');
    std::string_view line = trim(text.substr(0, eol));
    text.remove_prefix(eol == std::string_view::npos ? text.size() : eol + 1);
    if (const size_t hash = line.find('#'); hash != std::string_view::npos) line = trim(line.substr(0, hash));
    const size_t sp = line.find_first_of(" \t");
    const std::string_view key = line.substr(0, sp);
    const std::string_view rest = sp == std::string_view::npos ? std::string_view() : trim(line.substr(sp));
    if (key == "newmtl") {
      const std::string name(rest);
      auto [it, inserted] = materials_.try_emplace(name);
      if (inserted) it->second.name = name;
      m = inserted ? &it->second : &ignored;  // the first definition wins
      continue;
    }
    if (!m) continue;
    float v[3];
    if (key == "Kd") {
      const int n = numbers(rest, v, 3);
      if (n == 1) v[1] = v[2] = v[0];
      if (n == 1 || n == 3)
        for (int k = 0; k < 3; ++k) m->base_color[k] = unit(v[k]);
    } else if ((key == "d" || key == "Tr") && numbers(rest, v, 1) == 1) {
      m->base_color[3] = unit(key == "d" ? v[0] : 1 - v[0]);
      m->alpha = m->base_color[3] < 1 ? core::Material::Alpha::blend : core::Material::Alpha::opaque;
    } else if (key == "Pm" && numbers(rest, v, 1) == 1) {
      m->metallic = unit(v[0]);
    } else if (key == "Pr" && numbers(rest, v, 1) == 1) {
      m->roughness = unit(v[0]);
    } else if (key == "map_Kd" && !dir.empty() && m != &ignored && !rest.empty()) {
      // Options (-s u v w, -bm b, ...) come first: the file is the last word.
      const size_t last = rest.find_last_of(" \t");
      textures.emplace_back(m, std::string(last == std::string_view::npos ? rest : rest.substr(last + 1)));
    }
  }
  std::unordered_map<std::string, std::array<float, 4>> means;  // a library often reuses one image
  for (auto& [material, file] : textures) {
    std::string f = file;
    std::replace(f.begin(), f.end(), '\\', '/');  // libraries written on Windows
    const std::string path = (std::filesystem::path(dir) / f).string();
    auto it = means.find(path);
    if (it == means.end()) {
      std::array<float, 4> rgba{};
      std::string error;
      if (!texture_file_mean_color(path, rgba.data(), &error)) rgba = {1, 1, 1, 1};
      it = means.emplace(path, rgba).first;
    }
    for (int k = 0; k < 3; ++k) material->base_color[k] *= it->second[k];
  }
}

void MtlLibraries::read(const std::string& obj_path, const std::string& names) {
  const std::filesystem::path dir = std::filesystem::path(obj_path).parent_path();
  std::istringstream list(names);
  std::string name;
  while (list >> name) {
    const std::string path = (dir / name).string();
    if (!read_.try_emplace(path, true).second) continue;
    // Regular files of sane size only: a name such as /dev/zero must not hang ingest.
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec) || std::filesystem::file_size(path, ec) > kMaxLibraryBytes || ec)
      continue;
    std::string text;
    try {
      text = read_small_file(path);
    } catch (const Failure&) {
      continue;  // an unreadable library leaves its materials at the defaults, like a missing one
    }
    parse(text, std::filesystem::path(path).parent_path().string());
  }
}

bool MtlLibraries::find(const std::string& name, core::Material* out) const {
  const auto it = materials_.find(name);
  if (it == materials_.end()) return false;
  *out = it->second;
  return true;
}

}  // namespace lodstream::io
