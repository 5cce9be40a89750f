// fogbeam — lighting a rasterised frame's surfaces on the CPU (fogbeam/render/surface_shading.hpp):
// the frame's lamps and profiles in float, and the rows spread over threads. The SIMD kernel is in
// surface_shading_simd.cpp.
#include <fogbeam/render/surface_shading.hpp>
#include <fogbeam/util/overloaded.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <variant>

namespace fogbeam {

namespace {


// The O(1) location of a float axis (kernels::ShadeAxis): buckets no wider than half the
// finest cell (at most 65 536; a single bucket for fewer than 3 angles), each bucket's cell at
// its start and the one grid line it may hold. Built on the float angles the kernel compares.
void makeAxis(const std::vector<float>& g, SurfaceShader::Axis& a, kernels::ShadeAxis& axis) {
  const std::size_t n = g.size();
  axis.first = g.front();
  axis.last = g.back();
  axis.n = static_cast<int>(n);
  axis.lo = g.front();
  a.cell.clear();
  a.split.clear();
  a.lo.clear();
  a.inv.clear();
  for (std::size_t k = 0; k + 1 < n; ++k) {
    a.lo.push_back(g[k]);
    a.inv.push_back(g[k + 1] > g[k] ? 1.0f / (g[k + 1] - g[k]) : 0.0f);
  }
  if (n < 2) {  // one angle: the kernel takes row 0 where x is on it
    a.lo.push_back(g[0]);
    a.inv.push_back(0.0f);
  }
  std::size_t buckets = 1;
  if (n >= 3) {
    double finest = static_cast<double>(g.back()) - static_cast<double>(g.front());
    for (std::size_t k = 1; k < n; ++k) finest = std::min(finest, static_cast<double>(g[k]) - static_cast<double>(g[k - 1]));
    const double range = static_cast<double>(g.back()) - static_cast<double>(g.front());
    buckets = static_cast<std::size_t>(std::min(65536.0, std::ceil(2.0 * range / finest) + 1.0));
    axis.scale = static_cast<float>(static_cast<double>(buckets - 1) / range);
  } else {
    axis.scale = 0.0f;
  }
  const std::size_t lastCell = n >= 2 ? n - 2 : 0;
  std::size_t i = 0;
  for (std::size_t b = 0; b < buckets; ++b) {
    const double start = static_cast<double>(axis.lo) + static_cast<double>(b) / static_cast<double>(axis.scale);
    const double end = b + 1 < buckets ? static_cast<double>(axis.lo) + static_cast<double>(b + 1) / static_cast<double>(axis.scale)
                                       : std::numeric_limits<double>::infinity();
    if (axis.scale == 0.0f) {  // one bucket: the search is the split below, over ≤ 2 cells
      a.cell.push_back(0);
      a.split.push_back(std::numeric_limits<float>::infinity());
      break;
    }
    while (i < lastCell && static_cast<double>(g[i + 1]) <= start) ++i;
    a.cell.push_back(static_cast<std::int32_t>(i));
    a.split.push_back(i < lastCell && static_cast<double>(g[i + 1]) < end ? g[i + 1]
                                                                          : std::numeric_limits<float>::infinity());
  }
  axis.buckets = static_cast<int>(a.cell.size());
  axis.bucket_cell = a.cell.data();
  axis.bucket_split = a.split.data();
  axis.cell_lo = a.lo.data();
  axis.cell_inv = a.inv.data();
}

void setVec(float (&dst)[3], const Vec3& v) {
  dst[0] = static_cast<float>(v.x);
  dst[1] = static_cast<float>(v.y);
  dst[2] = static_cast<float>(v.z);
}

}  // namespace

const kernels::ShadeTable* SurfaceShader::tableFor(const std::shared_ptr<const Profile>& profile) {
  for (const auto& t : tables_)
    if (t->profile == profile) return &t->view;
  const auto& m = std::get<TabulatedProfile>(profile->model());
  auto t = std::make_unique<Table>();
  t->profile = profile;
  std::vector<float> h, v;
  for (double a : m.horizontal) h.push_back(static_cast<float>(a));
  for (double a : m.vertical) v.push_back(static_cast<float>(a));
  for (double c : m.candela) t->candela.push_back(static_cast<float>(c));
  kernels::ShadeTable& view = t->view;
  view.type = static_cast<int>(m.type);
  view.symmetry = static_cast<int>(m.symmetry);
  view.single_plane = m.horizontal.size() == 1 || m.symmetry == PlaneSymmetry::Rotational;
  // Type C without symmetry: TabulatedProfile::atAngles blends the last plane with the first
  // one + 360° for C beyond the data. The same as an extra plane there (a copy of the first
  // row); the kernel moves C below the first plane up by 360°.
  const double gap = m.horizontal.front() + 2.0 * kPi - m.horizontal.back();
  if (!view.single_plane && m.type == PhotometricType::C && m.symmetry == PlaneSymmetry::None && gap > 0.0) {
    h.push_back(static_cast<float>(m.horizontal.front() + 2.0 * kPi));
    t->candela.insert(t->candela.end(), t->candela.begin(),
                      t->candela.begin() + static_cast<std::ptrdiff_t>(m.vertical.size()));
  }
  makeAxis(h, t->h, view.h);
  makeAxis(v, t->v, view.v);
  view.candela = t->candela.data();
  tables_.push_back(std::move(t));
  return &tables_.back()->view;
}

void SurfaceShader::prepare(const Scene& scene, kernels::ShadeFrame& frame) {
  const Camera& cam = scene.camera;
  frame.width = cam.width;
  frame.height = cam.height;
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) frame.world_from_camera[3 * c + r] = cam.worldFromCamera[c][r];
  frame.focal = cam.focalLengthPixels();
  const Vec2 pp = cam.principalPoint();
  frame.cx = pp.x;
  frame.cy = pp.y;
  frame.planes.resize(scene.planes.size());
  for (std::size_t i = 0; i < scene.planes.size(); ++i) {
    const Plane& p = scene.planes[i];
    const Vec3 n = glm::normalize(p.normal);
    kernels::ShadePlane& k = frame.planes[i];
    k.n[0] = n.x;
    k.n[1] = n.y;
    k.n[2] = n.z;
    k.c = glm::dot(p.point_m - cam.position_m, n);
    k.rho = static_cast<float>(p.reflectance);
  }
  // The body quads (the bonnet) as bounded planes after them.
  for (const Quad& q : scene.body) {
    kernels::ShadePlane k;
    const Vec3 U = q.edge_u_m, V = q.edge_v_m;
    const Vec3 n = glm::normalize(glm::cross(U, V));
    const Vec3 corner = q.corner_m - cam.position_m;
    const double uu = glm::dot(U, U), uv = glm::dot(U, V), vv = glm::dot(V, V), det = uu * vv - uv * uv;
    const Vec3 ud = (vv * U - uv * V) / det, vd = (uu * V - uv * U) / det;
    for (int a = 0; a < 3; ++a) {
      k.n[a] = n[a];
      k.corner[a] = corner[a];
      k.u_dual[a] = ud[a];
      k.v_dual[a] = vd[a];
    }
    k.c = glm::dot(corner, n);
    k.rho = static_cast<float>(q.reflectance);
    k.bounded = true;
    frame.planes.push_back(k);
  }
  frame.extinction = static_cast<float>(scene.fog.extinction_per_m);
  frame.ambient = static_cast<float>(scene.fog.ambient_cd_m2);
  frame.lamps.resize(scene.lamps.size());
  for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
    const Lamp& l = scene.lamps[i].lamp;
    kernels::ShadeLamp& k = frame.lamps[i];
    setVec(k.pos, l.position_m - cam.position_m);  // camera-relative: float keeps millimetres
    setVec(k.ax, l.worldFromLamp[0]);
    setVec(k.ay, l.worldFromLamp[1]);
    setVec(k.az, l.worldFromLamp[2]);
    setVec(k.color, l.color);
    k.table = nullptr;
    std::visit(Overloaded{
                   [&](const IsotropicProfile& m) {
                     k.kind = 0;
                     k.i0 = static_cast<float>(m.intensity_cd);
                   },
                   [&](const SpotProfile& m) {
                     k.kind = 1;
                     k.i0 = static_cast<float>(m.peak_cd);
                     k.inner = static_cast<float>(m.inner);
                     k.outer = static_cast<float>(m.outer);
                   },
                   [&](const TabulatedProfile&) {
                     k.kind = 2;
                     k.i0 = 1.0f;
                     k.table = tableFor(l.profile);
                   },
               },
               l.profile->model());
  }
}

void SurfaceShader::shade(const kernels::ShadeFrame& frame, const SurfaceGBufferView& g, SurfaceBuffers& out,
                          ThreadPool* pool) const {
  const auto w = static_cast<std::size_t>(g.width), h = static_cast<std::size_t>(g.height);
  out.width = g.width;
  out.height = g.height;
  out.rgb.resize(3 * w * h);
  out.distance.resize(w * h);
  // Rows in bands of 8, a band per task: few enough tasks to hand out cheaply, enough of them
  // (90 at 720 rows) to balance two to sixteen threads.
  constexpr std::size_t kBand = 8;
  const std::size_t bands = (h + kBand - 1) / kBand;
  const bool mesh = g.normal_rho_r != nullptr && g.rho_gb != nullptr && g.distance != nullptr;
  auto band = [&](std::size_t b) {
    // The planes' distances and indices of one row (sized once per thread).
    thread_local std::vector<float> planeT;
    thread_local std::vector<std::int32_t> planeIndex;
    if (planeT.size() < w) {
      planeT.resize(w);
      planeIndex.resize(w);
    }
    for (std::size_t j = b * kBand; j < std::min(h, (b + 1) * kBand); ++j) {
      const std::size_t src = g.bottom_up ? h - 1 - j : j;  // the G-buffer's row of image row j
      kernels::castPlanesRow(frame, static_cast<int>(j), static_cast<int>(w), planeT.data(), planeIndex.data());
      kernels::shadeRow(frame, static_cast<int>(j), static_cast<int>(w), mesh ? g.normal_rho_r + 4 * w * src : nullptr,
                        mesh ? g.rho_gb + 2 * w * src : nullptr, mesh ? g.distance + w * src : nullptr, planeT.data(),
                        planeIndex.data(), out.rgb.data() + 3 * w * j, out.distance.data() + w * j);
    }
  };
  if (pool != nullptr && pool->size() > 1) pool->parallelFor(bands, band);
  else
    for (std::size_t b = 0; b < bands; ++b) band(b);
}

void SurfaceShader::render(const Scene& scene, kernels::ShadeFrame& frame, SurfaceBuffers& out, ThreadPool* pool) {
  prepare(scene, frame);
  SurfaceGBufferView none;
  none.width = scene.camera.width;
  none.height = scene.camera.height;
  shade(frame, none, out, pool);
}

}  // namespace fogbeam
