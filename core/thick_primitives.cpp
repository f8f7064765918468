// Edges as crossed quads and points as octahedra (see core/thick_primitives.h for the layout and why).
#include "core/thick_primitives.h"

#include <algorithm>
#include <cmath>

#include "core/status.h"

namespace lodstream::core {

namespace {

struct V3 {
  double x, y, z;
};
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }
V3 cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double norm(V3 a) { return std::sqrt(a.x * a.x + a.y * a.y + a.z * a.z); }

V3 position(const LodMesh& m, uint32_t id) {
  const float* p = &m.positions[3 * uint64_t{id}];
  return {p[0], p[1], p[2]};
}

// New vertices take the colour `rgba` (when the mesh has colours), new triangles the material `material`
// (when it has materials): the primitive's, set before it is expanded.
class Out {
 public:
  Out(LodMesh& mesh, bool normals) : mesh_(mesh), normals_(normals) {}
  uint32_t vertex(V3 p, V3 n) {
    const uint32_t id = static_cast<uint32_t>(mesh_.vertex_count());
    mesh_.positions.insert(mesh_.positions.end(), {static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z)});
    if (normals_)
      mesh_.normals.insert(mesh_.normals.end(), {static_cast<float>(n.x), static_cast<float>(n.y), static_cast<float>(n.z)});
    if (rgba) mesh_.colors.insert(mesh_.colors.end(), rgba, rgba + 4);
    return id;
  }
  void triangle(uint32_t a, uint32_t b, uint32_t c) {
    mesh_.triangles.insert(mesh_.triangles.end(), {a, b, c});
    if (!mesh_.materials.empty()) mesh_.triangle_materials.push_back(material);
  }
  const uint8_t* rgba = nullptr;
  uint32_t material = 0;

 private:
  LodMesh& mesh_;
  bool normals_;
};

// Octahedron of radius r around p; counter-clockwise seen from outside.
void octahedron(Out& out, V3 p, double r) {
  static constexpr V3 axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  uint32_t v[6];
  for (int i = 0; i < 6; ++i) v[i] = out.vertex(p + r * axes[i], axes[i]);
  // Faces (±x, ±y, ±z): the octant's three vertices, ordered so that the normal points outwards.
  for (int sx = 0; sx < 2; ++sx)
    for (int sy = 0; sy < 2; ++sy)
      for (int sz = 0; sz < 2; ++sz) {
        const uint32_t a = v[sx], b = v[2 + sy], c = v[4 + sz];
        // (x, y, z) is counter-clockwise for the (+,+,+) octant; each sign flip mirrors the orientation.
        if ((sx + sy + sz) % 2 == 0) out.triangle(a, b, c);
        else out.triangle(a, c, b);
      }
}

// The quad a ± h·side, b ± h·side, facing `normal` (= d × side up to sign); counter-clockwise seen from it.
// Its vertices at a take colour `ca`, at b `cb` (null without colours).
void quad(Out& out, V3 a, V3 b, V3 side, double h, V3 normal, const uint8_t* ca, const uint8_t* cb) {
  out.rgba = ca;
  const uint32_t a0 = out.vertex(a - h * side, normal), a1 = out.vertex(a + h * side, normal);
  out.rgba = cb;
  const uint32_t b0 = out.vertex(b - h * side, normal), b1 = out.vertex(b + h * side, normal);
  out.triangle(a0, b0, b1);
  out.triangle(a0, b1, a1);
}

}  // namespace

LodMesh expand_thick(const LodMesh& mesh, const ThickOptions& options, double* max_radius) {
  if (!mesh.points.empty() && !(options.point_radius > 0)) fail(Status::internal, "thick primitives: point radius must be positive");
  if (!(options.min_width >= 0)) fail(Status::internal, "thick primitives: negative minimum width");
  LodMesh r;
  r.positions = mesh.positions;
  r.normals = mesh.normals;
  r.triangles = mesh.triangles;
  r.colors = mesh.colors;
  r.materials = mesh.materials;
  r.triangle_materials = mesh.triangle_materials;
  const bool normals = !mesh.normals.empty();
  r.positions.reserve(r.positions.size() + 3 * (8 * mesh.edge_count() + 6 * mesh.point_count()));
  if (normals) r.normals.reserve(r.positions.capacity());
  r.triangles.reserve(r.triangles.size() + 3 * (4 * mesh.edge_count() + 8 * mesh.point_count()));
  Out out(r, normals);
  double radius = 0;
  const bool colors = !mesh.colors.empty(), materials = !mesh.materials.empty();
  auto rgba = [&](uint32_t v) { return colors ? &mesh.colors[4 * uint64_t{v}] : nullptr; };
  for (uint64_t e = 0; e < mesh.edge_count(); ++e) {
    const V3 a = position(mesh, mesh.edges[2 * e]), b = position(mesh, mesh.edges[2 * e + 1]);
    out.rgba = rgba(mesh.edges[2 * e]);
    if (materials) out.material = mesh.edge_materials[e];
    const double h = std::max(static_cast<double>(mesh.thickness[e]), options.min_width) / 2;
    const V3 ab = b - a;
    const double length = norm(ab);
    if (!(length > 0) || !(h > 0)) {
      const double pr = std::max(h, options.point_radius);
      if (!(pr > 0)) fail(Status::internal, "thick primitives: an edge of no length and no width");
      octahedron(out, a, pr);
      radius = std::max(radius, pr);
      continue;
    }
    const V3 d = (1 / length) * ab;
    // The axis least aligned with d (ties: x before y before z) gives a side direction far from parallel.
    const double ax = std::abs(d.x), ay = std::abs(d.y), az = std::abs(d.z);
    const V3 axis = ax <= ay && ax <= az ? V3{1, 0, 0} : ay <= az ? V3{0, 1, 0} : V3{0, 0, 1};
    V3 u = cross(d, axis);
    u = (1 / norm(u)) * u;
    const V3 v = cross(d, u);  // unit: d and u are orthonormal
    // Quad along u lies in the plane (d, u), whose normal is d × u = v; the other's is d × v = -u.
    quad(out, a, b, u, h, v, rgba(mesh.edges[2 * e]), rgba(mesh.edges[2 * e + 1]));
    quad(out, a, b, v, h, -1.0 * u, rgba(mesh.edges[2 * e]), rgba(mesh.edges[2 * e + 1]));
    radius = std::max(radius, h);
  }
  for (uint64_t i = 0; i < mesh.point_count(); ++i) {
    const uint32_t p = mesh.points[i];
    out.rgba = rgba(p);
    if (materials) out.material = mesh.point_materials[i];
    // A point as wide as what collapsed into it (its size, a diameter), as an edge is as wide as its
    // thickness, and like an edge never thinner than the floor.
    const double pr = mesh.point_size.empty() ? options.point_radius
                                              : std::max(static_cast<double>(mesh.point_size[i]) / 2, options.point_radius);
    octahedron(out, position(mesh, p), pr);
    radius = std::max(radius, pr);
  }
  if (max_radius) *max_radius = radius;
  return r;
}

}  // namespace lodstream::core
