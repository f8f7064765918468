// scan_cylindrical: scans a mesh into a cylindrical range grid the way a Cyberware cylindrical scanner
// does (DeHaemer 1989, ch. II.B: radius values at uniformly spaced latitudes and longitudes), as test data
// for `lodstream grid --cylindrical` from real models.
//
//   scan_cylindrical MODEL OUT [--width 512] [--height 512] [--axis x|y|z] [--margin 0.05]
//                    [--radius-scale S]
//
// The axis is parallel to --axis and passes through the centre of the model's bounding box. Row j lies at
// height (height - 1 - j) · step above the bottom row, the rows spanning the box along the axis widened by
// --margin of its length at each end (the scanned volume is taller than the subject, so the first and last
// rows see nothing: the rows `grid` trims). Column i looks along longitude i · 360 / width, by the right-hand
// rule about the axis from its cyclic successor (+Z for y, +X for z, +Y for x): the frame of
// core::CylinderFrame, so that `grid --cylindrical --axis A` puts the surface back where the scan found it,
// up to the translation printed.
//
// What a scanner outside the subject sees is the outermost surface along each ray from the axis. The scan
// casts the equivalent ray inwards: from the point at distance R (the box diagonal, farther than any
// surface) on the ray, towards the axis, stopping at the axis; the first hit (either side of a triangle) is
// the outermost one, radius = R - t. No hit: no return (0).
//
// Writes OUT.pgm (16-bit binary PGM, radius = value · S, 0 = no return; S = the largest radius / 65535
// unless --radius-scale is given, printed and stored in a comment) and OUT.asc (ESRI ASCII grid, radii in
// model units, NODATA_value -9999 for no return, cellsize = the height step, lower-left centre at 0 0).
// Prints the options `grid` needs: --z-scale S (PGM), --height-step, --axis.
#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/lod_reader.h"

namespace {

struct Options {
  std::string model, out;
  uint32_t width = 512, height = 512;
  std::string axis = "y";
  double margin = 0.05;
  double radius_scale = 0;
};

int run(const Options& o) {
  const lodstream::core::LodMesh mesh = lodstream::io::read_lod_mesh(o.model);
  if (mesh.triangles.empty()) {
    std::fprintf(stderr, "%s: no triangles\n", o.model.c_str());
    return 65;
  }
  const int a = o.axis == "x" ? 0 : o.axis == "y" ? 1 : 2;
  const int ec = (a + 1) % 3, es = (a + 2) % 3;  // the local frame (c, s, axis), right-handed
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (size_t v = 0; v < mesh.positions.size(); v += 3)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], double(mesh.positions[v + size_t(k)]));
      hi[k] = std::max(hi[k], double(mesh.positions[v + size_t(k)]));
    }
  double centre[3], diag2 = 0;
  for (int k = 0; k < 3; ++k) {
    centre[k] = (lo[k] + hi[k]) / 2;
    diag2 += (hi[k] - lo[k]) * (hi[k] - lo[k]);
  }
  const double R = 1.01 * std::sqrt(diag2) + 1e-6;
  const double length = hi[a] - lo[a];
  const double bottom = lo[a] - o.margin * length, top = hi[a] + o.margin * length;
  const double step = (top - bottom) / double(o.height - 1);

  RTCDevice device = rtcNewDevice(nullptr);
  RTCScene scene = rtcNewScene(device);
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  // 16 readable bytes past the last vertex (Embree's requirement): one spare float3.
  float* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                          3 * sizeof(float), mesh.positions.size() / 3 + 1));
  std::copy(mesh.positions.begin(), mesh.positions.end(), vb);
  uint32_t* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                3 * sizeof(uint32_t), mesh.triangles.size() / 3));
  std::copy(mesh.triangles.begin(), mesh.triangles.end(), ib);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene);

  std::vector<double> radius(uint64_t(o.width) * o.height, 0);
  double rmax = 0;
  uint64_t returns = 0;
  RTCIntersectContext context;
  for (uint32_t i = 0; i < o.width; ++i) {
    const double theta = 2 * std::numbers::pi * double(i) / double(o.width);
    double d[3] = {0, 0, 0};
    d[ec] = std::cos(theta);
    d[es] = std::sin(theta);
    for (uint32_t j = 0; j < o.height; ++j) {
      double origin[3] = {centre[0], centre[1], centre[2]};
      origin[a] = top - double(j) * step;
      RTCRayHit rh{};
      rh.ray.org_x = float(origin[0] + R * d[0]);
      rh.ray.org_y = float(origin[1] + R * d[1]);
      rh.ray.org_z = float(origin[2] + R * d[2]);
      rh.ray.dir_x = float(-d[0]);
      rh.ray.dir_y = float(-d[1]);
      rh.ray.dir_z = float(-d[2]);
      rh.ray.tnear = 0;
      rh.ray.tfar = float(R);
      rh.ray.mask = 0xFFFFFFFFu;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcInitIntersectContext(&context);
      rtcIntersect1(scene, &context, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
      const double r = R - double(rh.ray.tfar);
      if (!(r > 0)) continue;  // a hit on the axis itself: nothing outside it
      radius[uint64_t(j) * o.width + i] = r;
      rmax = std::max(rmax, r);
      ++returns;
    }
  }
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);
  if (returns == 0) {
    std::fprintf(stderr, "%s: no ray hit the model\n", o.model.c_str());
    return 65;
  }

  const double scale = o.radius_scale > 0 ? o.radius_scale : rmax / 65535;
  const char* axis_name = o.axis.c_str();
  std::string pgm = fmt::format(
      "P5\n# scan_cylindrical {}: radius = value x {:.9g} (0 = no return); height step {:.9g}; {} columns over 360 degrees; axis {}\n"
      "{} {}\n65535\n",
      std::filesystem::path(o.model).filename().string(), scale, step, o.width, axis_name, o.width, o.height);
  uint64_t clamped = 0;
  for (double r : radius) {
    long v = r > 0 ? std::lround(r / scale) : 0;
    if (r > 0 && v < 1) v = 1;  // a return stays a return
    if (v > 65535) v = 65535, ++clamped;
    pgm.push_back(char(uint8_t(v >> 8)));
    pgm.push_back(char(uint8_t(v & 0xff)));
  }
  std::string asc = fmt::format("ncols {}\nnrows {}\nxllcenter 0\nyllcenter 0\ncellsize {:.9g}\nNODATA_value -9999\n", o.width,
                                o.height, step);
  for (uint32_t j = 0; j < o.height; ++j) {
    for (uint32_t i = 0; i < o.width; ++i) {
      const double r = radius[uint64_t(j) * o.width + i];
      asc += r > 0 ? fmt::format("{:.9g}", r) : std::string("-9999");
      asc.push_back(i + 1 < o.width ? ' ' : '\n');
    }
  }
  lodstream::io::write_file_atomic(o.out + ".pgm", pgm, lodstream::io::Sync::durable);
  lodstream::io::write_file_atomic(o.out + ".asc", asc, lodstream::io::Sync::durable);
  double shift[3] = {centre[0], centre[1], centre[2]};
  shift[a] = bottom;
  std::printf("scanned      %s: %u x %u, %llu returns (%.1f%%), largest radius %.9g\n", o.model.c_str(), o.width, o.height,
              static_cast<unsigned long long>(returns), 100.0 * double(returns) / double(radius.size()), rmax);
  std::printf("wrote        %s.pgm (radius = value x %.9g%s) and %s.asc\n", o.out.c_str(), scale,
              clamped ? fmt::format(", {} radii clamped to 65535", clamped).c_str() : "", o.out.c_str());
  std::printf("grid options --cylindrical --axis %s --height-step %.9g (PGM: --z-scale %.9g)\n", axis_name, step, scale);
  std::printf("placement    the grid's axis through the origin, its bottom row at height 0: translate by %.9g %.9g %.9g\n",
              shift[0], shift[1], shift[2]);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Scan a mesh into a cylindrical range grid (16-bit PGM and ESRI ASCII), rays from outside towards the axis"};
  Options o;
  app.add_option("MODEL", o.model, "Mesh (PLY or OBJ)")->required();
  app.add_option("OUT", o.out, "Output path without extension: OUT.pgm and OUT.asc")->required();
  app.add_option("--width", o.width, "Columns (longitudes over a full turn), default 512")->check(CLI::Range(3u, 65536u));
  app.add_option("--height", o.height, "Rows (heights), default 512")->check(CLI::Range(2u, 65536u));
  app.add_option("--axis", o.axis, "Axis direction x, y (default) or z")->check(CLI::IsMember({"x", "y", "z"}));
  app.add_option("--margin", o.margin, "Extra scan height beyond the model at each end, as a fraction of its length (default 0.05)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--radius-scale", o.radius_scale, "PGM radius units per count (default: largest radius / 65535)")
      ->check(CLI::PositiveNumber);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 64;
  }
  try {
    return run(o);
  } catch (const lodstream::Failure& f) {
    std::fprintf(stderr, "%s\n", f.what());
    return static_cast<int>(f.status());
  }
}
