// thick_levels: writes a simplify output's levels with their edges and points expanded into triangles,
// exactly as `simplify --tiles` writes them into tiles (core/thick_primitives.h), so that `lodstream
// report` can measure both forms of a level side by side (tools/bench_thick.sh).
//
//   thick_levels OUTDIR DEST     (OUTDIR: a simplify output directory, read through its manifest.json)
//
// DEST receives lodN.ply per level (triangles only) and prints, per level, its triangles before and after.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "core/status.h"
#include "core/thick_primitives.h"
#include "io/file_writer.h"
#include "io/lod_reader.h"
#include "io/ply_writer.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: thick_levels OUTDIR DEST\n");
    return 64;
  }
  const std::string out = argv[1], dest = argv[2];
  try {
    const auto m = nlohmann::json::parse(lodstream::io::read_small_file(out + "/manifest.json"));
    const double x = m["options"]["pixels_per_cell"].get<double>();
    std::filesystem::create_directories(dest);
    for (const auto& level : m["levels"]) {
      const size_t l = level["level"].get<size_t>();
      const double c = level["cell_size"].get<double>();
      const std::string name = "lod" + std::to_string(l) + ".ply";
      const lodstream::core::LodMesh mesh = lodstream::io::read_lod_mesh(out + "/" + name);
      double radius = 0;
      const lodstream::core::LodMesh thick = lodstream::core::expand_thick(mesh, {c / x, c / x / 2}, &radius);
      lodstream::io::write_ply(dest + "/" + name, thick, {"thick edges and points of " + out + "/" + name});
      std::printf("level %zu: %llu triangles, %llu edges, %llu points -> %llu triangles (+%.1f %%), max radius %g (%.3f cells)\n", l,
                  static_cast<unsigned long long>(mesh.triangle_count()), static_cast<unsigned long long>(mesh.edge_count()),
                  static_cast<unsigned long long>(mesh.point_count()), static_cast<unsigned long long>(thick.triangle_count()),
                  100.0 * (static_cast<double>(thick.triangle_count()) / static_cast<double>(std::max<uint64_t>(mesh.triangle_count(), 1)) - 1),
                  radius, radius / c);
    }
  } catch (const lodstream::Failure& f) {
    std::fprintf(stderr, "thick_levels: %s\n", f.what());
    return static_cast<int>(f.status());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "thick_levels: %s\n", e.what());
    return 70;
  }
  return 0;
}
