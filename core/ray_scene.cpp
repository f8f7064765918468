// Embree 3 scenes for the error report; see ray_scene.h.
//
// Closest point on a triangle: Ericson, "Real-Time Collision Detection" (2005), §5.1.5, evaluated in
// double so that large scene coordinates keep their precision.
#include "core/ray_scene.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/nearest_hit.h"
#include "core/status.h"

namespace lodstream::core {
namespace {

struct Vec {
  double x, y, z;
};
inline Vec sub(Vec a, Vec b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec add(Vec a, Vec b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec mul(Vec a, double s) { return {a.x * s, a.y * s, a.z * s}; }
inline double dot(Vec a, Vec b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec load(const float* p) { return {p[0], p[1], p[2]}; }

// Ericson §5.1.5: the Voronoi region of p among the triangle's vertices, edges and face.
Vec closest_on_triangle(Vec p, Vec a, Vec b, Vec c) {
  const Vec ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec bp = sub(p, b);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return add(a, mul(ab, d1 / (d1 - d3)));
  const Vec cp = sub(p, c);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return add(a, mul(ac, d2 / (d2 - d6)));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return add(b, mul(sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))));
  const double denom = va + vb + vc;
  if (!(denom > 0)) {  // degenerate (zero-area) triangle: the nearest of its three sides
    Vec best = a;
    double best_d = std::numeric_limits<double>::infinity();
    const Vec ends[3][2] = {{a, b}, {b, c}, {c, a}};
    for (const auto& e : ends) {
      const Vec d = sub(e[1], e[0]);
      const double len2 = dot(d, d);
      const double t = len2 > 0 ? std::clamp(dot(sub(p, e[0]), d) / len2, 0.0, 1.0) : 0.0;
      const Vec q = add(e[0], mul(d, t));
      const double dq = dot(sub(p, q), sub(p, q));
      if (dq < best_d) best_d = dq, best = q;
    }
    return best;
  }
  const double v = vb / denom, w = vc / denom;
  return add(a, add(mul(ab, v), mul(ac, w)));
}

Vec closest_on_segment(Vec p, Vec a, Vec b) {
  const Vec d = sub(b, a);
  const double len2 = dot(d, d);
  const double t = len2 > 0 ? std::clamp(dot(sub(p, a), d) / len2, 0.0, 1.0) : 0.0;
  return add(a, mul(d, t));
}

struct Geom {
  PrimitiveKind kind = PrimitiveKind::none;
  const float* vertices = nullptr;    // triangles: xyz stride 3; segments and points: xyzr stride 4
  const uint32_t* indices = nullptr;  // triangles: 3 per primitive; segments: first vertex per primitive
  std::vector<uint8_t> colors;        // RGB per primitive, or empty
};

// A new geometry's reference, released unless attach() hands it to a scene first: a check that throws
// between rtcNewGeometry and the attachment (memory over --memory, say) leaks nothing.
struct GeometryRelease {
  void operator()(RTCGeometryTy* g) const { rtcReleaseGeometry(g); }
};
using GeometryHandle = std::unique_ptr<RTCGeometryTy, GeometryRelease>;

}  // namespace

struct RayScene::Impl {

  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  // Embree's point queries visit triangles but not curves or points, so segments and points are also
  // user geometries (bounds only) of a second scene that serves closest-point queries.
  RTCScene query_scene = nullptr;
  uint64_t limit = 0;
  std::atomic<int64_t> bytes{0};
  std::atomic<int64_t> peak{0};
  std::atomic<bool> over{false};
  std::mutex error_mutex;
  std::string error;
  std::vector<Geom> geoms;        // by geometry id of `scene`
  std::deque<Geom> query_geoms;   // by geometry id of `query_scene` (a deque: user data points into it)
  bool has_query_primitives = false;
  bool committed = false;
  bool has_primitives = false;

  static bool monitor(void* user, ssize_t delta, bool post) {
    auto* self = static_cast<Impl*>(user);
    const int64_t now = self->bytes.fetch_add(delta) + delta;
    if (delta > 0 && !post && self->limit > 0 && now > static_cast<int64_t>(self->limit)) {
      self->bytes.fetch_sub(delta);  // the allocation is refused, so it never happens (nor counts to peak)
      self->over = true;
      return false;
    }
    int64_t seen = self->peak.load();
    while (now > seen && !self->peak.compare_exchange_weak(seen, now)) {
    }
    return true;
  }
  static void on_error(void* user, RTCError code, const char* message) {
    auto* self = static_cast<Impl*>(user);
    std::lock_guard<std::mutex> lock(self->error_mutex);
    if (self->error.empty()) self->error = std::string("Embree error ") + std::to_string(static_cast<int>(code)) + ": " + (message ? message : "");
  }

  void check(const char* what) {
    const RTCError code = rtcGetDeviceError(device);
    if (over) {
      fail(Status::usage, std::string("the ray-casting scene needs more memory than --memory allows (") +
                              std::to_string(limit >> 20) + " MiB for Embree; " + what + ")");
    }
    if (code != RTC_ERROR_NONE) {
      std::lock_guard<std::mutex> lock(error_mutex);
      fail(Status::internal,
           error.empty() ? std::string("Embree failed: ") + what : error + " (" + what + ")");
    }
  }

  GeometryHandle attach(RTCGeometryType type, PrimitiveKind kind) {
    GeometryHandle g(rtcNewGeometry(device, type));
    check("new geometry");
    geoms.emplace_back().kind = kind;
    return g;
  }
  // Commits `g`, attaches it to `s` (which then holds the only reference) and checks that it got the id
  // `expected`: ids index geoms / query_geoms.
  void attach(RTCScene s, GeometryHandle g, size_t expected, const char* what) {
    rtcCommitGeometry(g.get());
    const unsigned id = rtcAttachGeometry(s, g.get());
    g.reset();
    check(what);
    if (id != expected) fail(Status::internal, std::string("Embree ids out of order: ") + what);
  }
  void finish(GeometryHandle g) {
    attach(scene, std::move(g), geoms.size() - 1, "attach geometry");
    has_primitives = true;
  }

  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* g = static_cast<const Geom*>(args->geometryUserPtr);
    const float* a;
    const float* b;
    if (g->kind == PrimitiveKind::edge) {
      a = g->vertices + 4ull * g->indices[args->primID];
      b = a + 4;
    } else {
      a = b = g->vertices + 4ull * args->primID;
    }
    args->bounds_o->lower_x = std::min(a[0], b[0]), args->bounds_o->upper_x = std::max(a[0], b[0]);
    args->bounds_o->lower_y = std::min(a[1], b[1]), args->bounds_o->upper_y = std::max(a[1], b[1]);
    args->bounds_o->lower_z = std::min(a[2], b[2]), args->bounds_o->upper_z = std::max(a[2], b[2]);
  }

  // The query twin of the last geometry added (a segment or point set of `primitives` primitives).
  void add_query_twin(uint64_t primitives) {
    if (!query_scene) {
      query_scene = rtcNewScene(device);
      rtcSetSceneFlags(query_scene, RTC_SCENE_FLAG_COMPACT);
      check("new query scene");
    }
    query_geoms.push_back(geoms.back());
    GeometryHandle g(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER));
    check("new query geometry");
    rtcSetGeometryUserPrimitiveCount(g.get(), static_cast<unsigned>(primitives));
    rtcSetGeometryUserData(g.get(), &query_geoms.back());
    rtcSetGeometryBoundsFunction(g.get(), &Impl::bounds, nullptr);
    attach(query_scene, std::move(g), query_geoms.size() - 1, "attach query geometry");
    has_query_primitives = true;
  }
};

RayScene::RayScene(uint64_t memory_limit) : impl_(std::make_unique<Impl>()) {
  impl_->limit = memory_limit;
  impl_->device = rtcNewDevice("verbose=0");
  if (!impl_->device) fail(Status::internal, "cannot create an Embree device");
  rtcSetDeviceErrorFunction(impl_->device, &Impl::on_error, impl_.get());
  rtcSetDeviceMemoryMonitorFunction(impl_->device, &Impl::monitor, impl_.get());
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_COMPACT | RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_MEDIUM);
  impl_->check("new scene");
}

RayScene::~RayScene() {
  if (impl_->query_scene) rtcReleaseScene(impl_->query_scene);
  if (impl_->scene) rtcReleaseScene(impl_->scene);
  if (impl_->device) rtcReleaseDevice(impl_->device);
}

RayScene::TriangleBuffers RayScene::add_triangles(uint64_t vertex_count, uint64_t triangle_count) {
  if (vertex_count > UINT32_MAX || triangle_count > UINT32_MAX)
    fail(Status::usage, "more than 2^32 vertices or triangles in one ray-casting scene");
  if (triangle_count == 0) return {};
  Impl& s = *impl_;
  GeometryHandle g = s.attach(RTC_GEOMETRY_TYPE_TRIANGLE, PrimitiveKind::triangle);
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                        3 * sizeof(float), vertex_count));
  s.check("triangle vertices");
  auto* i = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g.get(), RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                           3 * sizeof(uint32_t), triangle_count));
  s.check("triangle indices");
  s.geoms.back().vertices = v;
  s.geoms.back().indices = i;
  s.finish(std::move(g));
  return {std::span<float>(v, 3 * vertex_count), std::span<uint32_t>(i, 3 * triangle_count)};
}

void RayScene::add_triangles(std::span<const float> xyz, std::span<const uint32_t> triangles) {
  const TriangleBuffers b = add_triangles(xyz.size() / 3, triangles.size() / 3);
  if (b.indices.empty()) return;
  std::memcpy(b.xyz.data(), xyz.data(), xyz.size_bytes());
  std::memcpy(b.indices.data(), triangles.data(), triangles.size_bytes());
}

void RayScene::add_segments(std::span<const float> xyz, std::span<const uint32_t> edges,
                            std::span<const float> radius) {
  const uint64_t n = edges.size() / 2;
  if (n == 0) return;
  if (2 * n > UINT32_MAX) fail(Status::usage, "more than 2^31 edges in one ray-casting scene");
  Impl& s = *impl_;
  GeometryHandle g = s.attach(RTC_GEOMETRY_TYPE_FLAT_LINEAR_CURVE, PrimitiveKind::edge);
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4,
                                                        4 * sizeof(float), 2 * n));
  s.check("edge vertices");
  auto* i = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g.get(), RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT,
                                                           sizeof(uint32_t), n));
  s.check("edge indices");
  for (uint64_t e = 0; e < n; ++e) {
    for (int end = 0; end < 2; ++end) {
      const float* p = xyz.data() + 3 * static_cast<uint64_t>(edges[2 * e + end]);
      float* o = v + 4 * (2 * e + end);
      o[0] = p[0], o[1] = p[1], o[2] = p[2], o[3] = radius[e];
    }
    i[e] = static_cast<uint32_t>(2 * e);
  }
  s.geoms.back().vertices = v;
  s.geoms.back().indices = i;
  s.finish(std::move(g));
  s.add_query_twin(n);
}

void RayScene::add_points(std::span<const float> xyz, std::span<const uint32_t> ids, float radius) {
  add_discs(xyz, ids, [radius](uint64_t) { return radius; });
}

void RayScene::add_points(std::span<const float> xyz, std::span<const uint32_t> ids, std::span<const float> radius) {
  add_discs(xyz, ids, [radius](uint64_t k) { return radius[k]; });
}

template <class Radius>
void RayScene::add_discs(std::span<const float> xyz, std::span<const uint32_t> ids, Radius&& radius) {
  const uint64_t n = ids.size();
  if (n == 0) return;
  if (n > UINT32_MAX) fail(Status::usage, "more than 2^32 points in one ray-casting scene");
  Impl& s = *impl_;
  GeometryHandle g = s.attach(RTC_GEOMETRY_TYPE_DISC_POINT, PrimitiveKind::point);
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4,
                                                        4 * sizeof(float), n));
  s.check("point vertices");
  for (uint64_t k = 0; k < n; ++k) {
    const float* p = xyz.data() + 3 * static_cast<uint64_t>(ids[k]);
    float* o = v + 4 * k;
    o[0] = p[0], o[1] = p[1], o[2] = p[2], o[3] = radius(k);
  }
  s.geoms.back().vertices = v;
  s.finish(std::move(g));
  s.add_query_twin(n);
}

void RayScene::commit() {
  rtcCommitScene(impl_->scene);
  impl_->check("scene build");
  if (impl_->query_scene) {
    rtcCommitScene(impl_->query_scene);
    impl_->check("query scene build");
  }
  impl_->committed = true;
}

namespace {
struct QueryState {
  const std::vector<Geom>* geoms;        // the triangle scene's geometries, or
  const std::deque<Geom>* query_geoms;   // the query scene's
  Vec p;
  double best_d2;
  Vec best;
};
}  // namespace

static bool closest_callback(RTCPointQueryFunctionArguments* args) {
  auto* q = static_cast<QueryState*>(args->userPtr);
  const Geom& g = q->geoms ? (*q->geoms)[args->geomID] : (*q->query_geoms)[args->geomID];
  const uint64_t prim = args->primID;
  Vec c;
  switch (g.kind) {
    case PrimitiveKind::triangle: {
      const uint32_t* t = g.indices + 3 * prim;
      c = closest_on_triangle(q->p, load(g.vertices + 3ull * t[0]), load(g.vertices + 3ull * t[1]),
                              load(g.vertices + 3ull * t[2]));
      break;
    }
    case PrimitiveKind::edge: {
      const uint64_t first = g.indices[prim];
      c = closest_on_segment(q->p, load(g.vertices + 4 * first), load(g.vertices + 4 * (first + 1)));
      break;
    }
    case PrimitiveKind::point:
      c = load(g.vertices + 4 * prim);
      break;
    default:
      return false;
  }
  const Vec d = sub(q->p, c);
  const double d2 = dot(d, d);
  if (d2 < q->best_d2) {
    q->best_d2 = d2;
    q->best = c;
    // Rounded up, so that no primitive nearer than the best is culled: the distance is then the minimum
    // over every primitive, whatever the BVH (and the chunk the primitive is traced in).
    args->query->radius = std::nextafter(static_cast<float>(std::sqrt(d2)), std::numeric_limits<float>::infinity());
    return true;
  }
  return false;
}

float RayScene::closest_distance(const float p[3], float* closest, float within) const {
  QueryState state{&impl_->geoms, nullptr, load(p), std::numeric_limits<double>::infinity(), {0, 0, 0}};
  RTCPointQuery query;
  query.x = p[0], query.y = p[1], query.z = p[2];
  // Rounded up like the callback's radius: nothing nearer than `within` is culled.
  query.radius = std::nextafter(within, std::numeric_limits<float>::infinity());
  query.time = 0;
  RTCPointQueryContext context;
  if (impl_->has_primitives) {
    rtcInitPointQueryContext(&context);
    rtcPointQuery(impl_->scene, &query, &context, closest_callback, &state);
  }
  if (impl_->has_query_primitives) {
    state.geoms = nullptr;
    state.query_geoms = &impl_->query_geoms;
    query.radius = std::isfinite(state.best_d2) ? static_cast<float>(std::sqrt(state.best_d2)) * 1.0001f + 1e-30f
                                                : std::nextafter(within, std::numeric_limits<float>::infinity());
    rtcInitPointQueryContext(&context);
    rtcPointQuery(impl_->query_scene, &query, &context, closest_callback, &state);
  }
  if (closest) closest[0] = float(state.best.x), closest[1] = float(state.best.y), closest[2] = float(state.best.z);
  return static_cast<float>(std::sqrt(state.best_d2));
}

void nearest_hit_filter(const RTCFilterFunctionNArguments* args) {
  auto* c = reinterpret_cast<NearestHitContext*>(const_cast<RTCIntersectContext*>(args->context));
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (!args->valid[i]) continue;
    const unsigned id = RTCRayN_id(args->ray, n, i);
    const unsigned geom = RTCHitN_geomID(args->hit, n, i), prim = RTCHitN_primID(args->hit, n, i);
    float t = RTCRayN_tfar(args->ray, n, i);
    if (c->ray_scene) {
      const float org[3] = {RTCRayN_org_x(args->ray, n, i), RTCRayN_org_y(args->ray, n, i), RTCRayN_org_z(args->ray, n, i)};
      const float dir[3] = {RTCRayN_dir_x(args->ray, n, i), RTCRayN_dir_y(args->ray, n, i), RTCRayN_dir_z(args->ray, n, i)};
      float canonical;
      if (c->ray_scene->canonical_t(geom, prim, org, dir, &canonical)) t = canonical;
    }
    const uint64_t key = hit_key(c->scene, geom, prim);
    if (t < c->best_t[id] || (t == c->best_t[id] && key < c->best_key[id])) {
      c->best_t[id] = t, c->best_key[id] = key, c->best_scene[id] = static_cast<int>(c->scene);
      // Embree keeps this tfar (it restores its own only for a rejected hit).
      RTCRayN_tfar(args->ray, n, i) = enlarged_tfar(t);
    } else {
      args->valid[i] = 0;
    }
  }
}

bool RayScene::triangle_hit(unsigned geom, unsigned prim, const float org[3], const float dir[3], float* t,
                            double normal[3]) const {
  if (geom >= impl_->geoms.size()) return false;
  const Geom& g = impl_->geoms[geom];
  if (g.kind != PrimitiveKind::triangle) return false;
  const uint32_t* tri = g.indices + 3ull * prim;
  const Vec a = load(g.vertices + 3ull * tri[0]), b = load(g.vertices + 3ull * tri[1]), c = load(g.vertices + 3ull * tri[2]);
  const Vec e1 = sub(b, a), e2 = sub(c, a);
  const Vec nn = {e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x};
  const Vec d = load(dir);
  const double denom = dot(d, nn);
  if (!(denom != 0)) return false;
  *t = static_cast<float>(dot(sub(a, load(org)), nn) / denom);
  if (normal) {
    const double len = std::sqrt(dot(nn, nn));
    normal[0] = nn.x / len, normal[1] = nn.y / len, normal[2] = nn.z / len;
  }
  return true;
}

bool RayScene::canonical_t(unsigned geom, unsigned prim, const float org[3], const float dir[3], float* t) const {
  if (geom >= impl_->geoms.size()) return false;
  const Geom& g = impl_->geoms[geom];
  if (g.kind == PrimitiveKind::triangle) return triangle_hit(geom, prim, org, dir, t);
  const Vec o = load(org), d = load(dir);
  const double dd = dot(d, d);
  if (!(dd > 0)) return false;
  if (g.kind == PrimitiveKind::point) {  // a disc facing the ray: its plane through the centre
    *t = static_cast<float>(dot(sub(load(g.vertices + 4ull * prim), o), d) / dd);
    return true;
  }
  if (g.kind != PrimitiveKind::edge) return false;
  // A ribbon facing the ray: the point of the axis nearest the ray seen along it (Embree's flat linear
  // curve), at the depth there.
  const uint64_t first = g.indices[prim];
  const Vec w0 = sub(load(g.vertices + 4 * first), o), w1 = sub(load(g.vertices + 4 * first + 4), o);
  const double z0 = dot(w0, d) / dd, z1 = dot(w1, d) / dd;
  const Vec q0 = {w0.x - z0 * d.x, w0.y - z0 * d.y, w0.z - z0 * d.z};
  const Vec q1 = {w1.x - z1 * d.x, w1.y - z1 * d.y, w1.z - z1 * d.z};
  const Vec v = sub(q1, q0);
  const double vv = dot(v, v);
  const double u = vv > 0 ? std::clamp(-dot(q0, v) / vv, 0.0, 1.0) : 0.0;
  *t = static_cast<float>(z0 + u * (z1 - z0));
  return true;
}

bool RayScene::only_triangles() const {
  for (const Geom& g : impl_->geoms)
    if (g.kind != PrimitiveKind::triangle) return false;
  return true;
}

void RayScene::set_colors(std::vector<uint8_t> rgb) {
  if (impl_->geoms.empty()) return;
  impl_->geoms.back().colors = std::move(rgb);
}

const uint8_t* RayScene::color(unsigned geom, unsigned prim) const {
  if (geom >= impl_->geoms.size()) return nullptr;
  const std::vector<uint8_t>& c = impl_->geoms[geom].colors;
  return 3 * uint64_t{prim} + 3 <= c.size() ? &c[3 * uint64_t{prim}] : nullptr;
}

bool RayScene::has_colors() const {
  for (const Geom& g : impl_->geoms)
    if (!g.colors.empty()) return true;
  return false;
}

PrimitiveKind RayScene::kind_of(unsigned geom_id) const {
  return geom_id < impl_->geoms.size() ? impl_->geoms[geom_id].kind : PrimitiveKind::none;
}
uint64_t RayScene::embree_bytes() const { return static_cast<uint64_t>(std::max<int64_t>(0, impl_->bytes.load())); }
uint64_t RayScene::peak_embree_bytes() const { return static_cast<uint64_t>(std::max<int64_t>(0, impl_->peak.load())); }
bool RayScene::over_limit() const { return impl_->over; }
void* RayScene::handle() const { return impl_->scene; }
bool RayScene::empty() const { return !impl_->has_primitives; }

}  // namespace lodstream::core
