// fogbeam — lighting a rasterised frame's surfaces on the CPU (fogbeam/render/surface_shading.hpp):
// the frame's lamps and profiles in float, and the rows spread over threads. The SIMD kernel is in
// surface_shading_simd.cpp.
#include <fogbeam/render/surface_shading.hpp>

#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/util/overloaded.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
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

void SurfaceShader::prepareFogLight(const Scene& scene, FogLightFrame& f, ThreadPool* pool) {
  f.table = nullptr;
  f.table_owner.reset();
  f.lamps.clear();
  const GlowOptions& glow = scene.effects.glow;
  if (!glow.enabled || !glow.surfaces || !(scene.fog.albedo > 0.0) || !(scene.fog.extinction_per_m > 0.0)) return;
  // No shipped multiple-scattering table for this phase function: no fog light (docs/airlight.md).
  auto table = FogLightTable::shipped(scene.fog.phase, scene.fog.albedo, pool, cacheDir_, &cacheError_);
  if (!table) return;
  // Another table (phase function or albedo) may have other emission bins: the maps are asked
  // for again (AnnulusMeanMap::shared hands back those alive with the same edges).
  if (table->get() != fogTable_.get()) fogMaps_.clear();
  fogTable_ = std::move(table).value();
  f.table = fogTable_.get();
  f.table_owner = fogTable_;
  f.extinction = scene.fog.extinction_per_m;
  const Camera& cam = scene.camera;
  f.lamps.resize(scene.lamps.size());
  for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
    const Lamp& l = scene.lamps[i].lamp;
    FogLightFrame::Lamp& k = f.lamps[i];
    k.pos = l.position_m - cam.position_m;
    k.lampFromWorld = glm::transpose(l.worldFromLamp);
    k.map = nullptr;
    k.map_owner.reset();
    k.i0 = 0.0;
    if (const auto* iso = std::get_if<IsotropicProfile>(&l.profile->model())) {
      k.i0 = iso->intensity_cd;
      continue;
    }
    // The driver's own lamps light the fog forward of the car only (as their glow).
    const bool front = scene.lamps[i].mount == LampMount::Vehicle;
    auto it = std::find_if(fogMaps_.begin(), fogMaps_.end(),
                           [&](const FogMap& m) { return m.profile == l.profile && m.frontOnly == front; });
    if (it == fogMaps_.end()) {
      fogMaps_.push_back(FogMap{l.profile, front, AnnulusMeanMap::shared(l.profile, fogTable_->edges(), front, pool, cacheDir_, &cacheError_)});
      it = std::prev(fogMaps_.end());
    }
    k.map = it->map.get();
    k.map_owner = it->map;
  }
}

void SurfaceShader::prepare(const Scene& scene, kernels::ShadeFrame& frame, ThreadPool* pool) {
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
  prepareFogLight(scene, frame.fog_light, pool);
}

namespace {

// The fog light (render/fog_light.hpp) over a band of kFogTile rows: an adaptive grid (one for
// all lamps) of nodes where the lamps' coefficients are evaluated (fogLightCoefficients at the
// surface point the pixel sees), blended in between. Cells start at kFogTile pixels and are
// halved down to 2 px until
//   * the cell's pixels are on one surface: their inverse distances the corners' bilinear blend
//     within kFogSameSurface (on a plane 1/depth is linear over the image; a silhouette breaks
//     that), and
//   * at the centre and the middles of the edges, evaluated, the corners' blend (as blend()
//     weighs them) gives the lamps' irradiance facing each (μ = 1) and edge-on to it (μ = 0, the
//     dipole's D0 included) within kFogTolerance of itself, or within the floor the eye cannot
//     see there.
// Beyond kFogFar mean free paths the blend is not judged (the eye sees less than e^{−7} of it).
// A cell of at most kFogLayeredMax px whose only fault is a silhouette (two surfaces, a post or a
// tree before the road) is filled layer by layer, as the airlight's subsampling does
// (airlight_image.cpp, "Layered"): the coefficients are a function of the 3D point alone, so a
// pixel takes the blend of the corners whose distance is its own (1/d within kFogLayer; beyond
// kFogFar mean free paths all alike), weights renormalised over them, when the probes above
// pass that test in their own layers; a pixel with no corner in its layer, or in a layer no probe
// fell in, is evaluated. Without it every silhouette (trees, posts, the horizon, the bonnet's
// edge) was refined to 2 px cells and their pixels evaluated one by one: the bench scene at
// 1280×720 (GL geometry) took 65.9 k nodes a frame, 52.6 k with it. Up to 8 px: 47.2 k, but a
// pixel of FogLight.TheGridKeepsItsToleranceAcrossSilhouettes 5.8 % off, beyond the grid's 5 %.
// A 2 px cell that still fails is evaluated pixel by pixel. Rows of the band's coefficients are
// laid out as shadeRow reads them.
constexpr int kFogTile = 16;
constexpr std::size_t kFogColumns = 128;  // a band's columns per pass (a multiple of kFogTile)

// The camera-relative point at distance d along pixel (i, j)'s ray (Camera::rayDirection).
Vec3 pixelPoint(const kernels::ShadeFrame& f, double i, double j, double d) {
  const double lx = f.cx - (i + 0.5), ly = f.cy - (j + 0.5);
  const double* R = f.world_from_camera;
  const Vec3 o{R[0] * f.focal + R[3] * lx + R[6] * ly, R[1] * f.focal + R[4] * lx + R[7] * ly,
               R[2] * f.focal + R[5] * lx + R[8] * ly};
  return glm::normalize(o) * d;
}

constexpr float kFogSameSurface = 0.02f, kFogFar = 7.0f, kFogTolerance = 0.01f;
constexpr float kFogLayer = 0.1f;  // 1/d of a pixel and a corner of its layer: within 10 % of the larger
constexpr int kFogLayeredMax = 4;  // px: larger cells across a silhouette split

// A thread's storage for its tiles (kept between frames: a steady frame allocates nothing).
struct FogTileScratch {
  std::vector<float> d;              // the band's pixel distances (m)
  std::vector<float> s, nd;          // per node: the lamp's 4 coefficients; its distance
  std::vector<std::uint32_t> stamp;  // per pixel: the (lamp, band) its node index belongs to
  std::vector<std::int32_t> nodeAt;  // per pixel: its node (valid where stamp matches)
  std::vector<float> w;              // a cell row's blend weights
  std::uint32_t current = 0;
};

class FogTile {
 public:
  // `floor`: the fog light's error the eye cannot see, lux as seen through the fog (shade()).
  FogTile(const kernels::ShadeFrame& frame, const SurfaceGBufferView& g, std::size_t stride, float floor,
          FogTileScratch& scratch)
      : f_(frame), g_(g), w_(g.width), h_(g.height), nq_(frame.fog_light.floats()), stride_(stride),
        mfp_(1.0f / static_cast<float>(frame.fog_light.extinction)), floor_(floor), sc_(scratch) {
    // The symmetric functions facing the lamp (μ = 1) and edge-on (μ = 0), for predicts().
    fogLightBasis(1.0f, b1_, static_cast<float*>(nullptr));
    fogLightBasis(0.0f, b0_, static_cast<float*>(nullptr));
  }

  // Rows j0 … j0 + kFogTile − 1 (fewer at the bottom) of columns [x0, x1) (x0 a multiple of
  // kFogTile): their planes (for shadeRow, row y's at planeT[(y − j0) · width()]) and distances,
  // with the next band's first row and the next part's first column (nodes of the last cells);
  // then columns() gives their fog light.
  void begin(int j0, int x0, int x1, std::vector<float>& planeT, std::vector<std::int32_t>& planeIndex) {
    j0_ = j0;
    yEnd_ = std::min(j0 + kFogTile, h_ - 1);  // the band's last node row (the next band's first)
    xs_ = x0;
    xe_ = x1;
    cw_ = std::min(x1, w_ - 1) - x0 + 1;  // up to the last node column (the next part's first)
    const int nRows = yEnd_ - j0 + 1;
    const auto W = static_cast<std::size_t>(cw_), G = static_cast<std::size_t>(w_);
    planeT.resize(static_cast<std::size_t>(nRows) * W);
    planeIndex.resize(planeT.size());
    sc_.d.resize(planeT.size());
    if (sc_.stamp.size() < planeT.size()) {
      sc_.stamp.assign(planeT.size(), 0);
      sc_.nodeAt.resize(planeT.size());
      sc_.current = 0;
    }
    for (int y = j0; y <= yEnd_; ++y) {
      const std::size_t r = static_cast<std::size_t>(y - j0) * W;
      kernels::castPlanesRow(f_, y, cw_, planeT.data() + r, planeIndex.data() + r, x0);
      const std::size_t src = g_.bottom_up ? static_cast<std::size_t>(h_ - 1 - y) : static_cast<std::size_t>(y);
      const std::size_t g0 = G * src + static_cast<std::size_t>(x0);
      for (std::size_t x = 0; x < W; ++x) {
        const float gd = g_.distance != nullptr ? g_.distance[g0 + x] : std::numeric_limits<float>::infinity();
        sc_.d[r + x] = std::min(gd, planeT[r + x]);
      }
    }
    // One grid for all lamps (a node's cost is mostly its look-ups; grids per lamp repeat the
    // silhouettes' refinement for each lamp and cost more on the bench scene).
    if (++sc_.current == 0) {  // the stamps wrapped: start them again
      std::fill(sc_.stamp.begin(), sc_.stamp.end(), 0u);
      sc_.current = 1;
    }
    sc_.s.clear();
    sc_.nd.clear();
  }

  // Pixels a row of begin()'s planes and distances holds.
  [[nodiscard]] std::size_t width() const { return static_cast<std::size_t>(cw_); }

  // The fog light of begin()'s columns [x0, x1) of the band's rows into `rows` (row y's
  // coefficient q at rows[((y − j0) · nq + q) · stride + x − x0]).
  void columns(std::vector<float>& rows) {
    rows.resize(static_cast<std::size_t>(kFogTile) * nq_ * stride_);
    rows_ = rows.data();
    if (f_.fog_light_exact) {
      for (int y = j0_; y < std::min(j0_ + kFogTile, h_); ++y)
        for (int x = xs_; x < xe_; ++x) put(x, y, node(x, y));
      return;
    }
    for (int xa = xs_; xa < xe_; xa += kFogTile) cell(xa, std::min(xa + kFogTile, w_ - 1), j0_, yEnd_);
  }

 private:
  const kernels::ShadeFrame& f_;
  const SurfaceGBufferView& g_;
  int w_, h_;
  std::size_t nq_, stride_;
  float mfp_, floor_;
  FogTileScratch& sc_;
  float b1_[4], b0_[4];  // fogLightBasis's symmetric functions at μ = 1 and μ = 0
  int j0_ = 0, yEnd_ = 0;
  int xs_ = 0, xe_ = 0, cw_ = 0;  // the part's columns [xs_, xe_), and how many begin() read (one more but at the image's edge)
  float* rows_ = nullptr;
  [[nodiscard]] std::size_t nc() const { return nq_; }  // floats per node: every lamp's block

  [[nodiscard]] std::size_t pixel(int x, int y) const {
    return static_cast<std::size_t>(y - j0_) * static_cast<std::size_t>(cw_) + static_cast<std::size_t>(x - xs_);
  }
  [[nodiscard]] float dist(int x, int y) const { return sc_.d[pixel(x, y)]; }
  // The node at pixel (x, y) of the current lamp: its index (evaluated on first use).
  std::size_t node(int x, int y) {
    const std::size_t p = pixel(x, y);
    if (sc_.stamp[p] == sc_.current) return static_cast<std::size_t>(sc_.nodeAt[p]);
    sc_.stamp[p] = sc_.current;
    const std::size_t n = sc_.nd.size();
    sc_.nodeAt[p] = static_cast<std::int32_t>(n);
    sc_.s.resize(nc() * (n + 1));
    const float d = dist(x, y);
    float* c = sc_.s.data() + nc() * n;
    if (std::isfinite(d)) {
      fogLightCoefficients(f_.fog_light, pixelPoint(f_, x, y, static_cast<double>(d)), c);
    } else {
      std::fill(c, c + nc(), 0.0f);
    }
    sc_.nd.push_back(d);
    return n;
  }
  [[nodiscard]] const float* coef(std::size_t n) const { return sc_.s.data() + nc() * n; }
  [[nodiscard]] float nodeDistance(std::size_t n) const { return sc_.nd[n]; }
  float* out(int x, int y, std::size_t q) {
    return rows_ + (static_cast<std::size_t>(y - j0_) * nq_ + q) * stride_ + static_cast<std::size_t>(x - xs_);
  }
  void put(int x, int y, std::size_t n) {
    const float* c = coef(n);
    for (std::size_t q = 0; q < nc(); ++q) *out(x, y, q) = c[q];
  }

  void cell(int xa, int xb, int ya, int yb) {
    const bool lastX = xb == w_ - 1, lastY = yb == h_ - 1;
    const int xEnd = lastX ? xb + 1 : xb, yStop = std::min(lastY ? yb + 1 : yb, j0_ + kFogTile);
    if (xEnd <= xa || yStop <= ya) return;
    if (xb == xa || yb == ya) {  // a one-pixel-wide strip at the image's edge
      pixels(xa, xEnd, ya, yStop);
      return;
    }
    bool anySurface = false;  // a cell of sky only: nothing to light
    for (int y = ya; y <= yb && !anySurface; ++y)
      for (int x = xa; x <= xb && !anySurface; ++x) anySurface = std::isfinite(dist(x, y));
    if (!anySurface) return;  // shadeRow lights no sky pixel: its coefficients are never read
    const std::size_t k[4] = {node(xa, ya), node(xb, ya), node(xa, yb), node(xb, yb)};
    bool clean = std::isfinite(nodeDistance(k[0])) && std::isfinite(nodeDistance(k[1])) &&
                 std::isfinite(nodeDistance(k[2])) && std::isfinite(nodeDistance(k[3]));
    if (clean) {  // one surface
      const float i0 = 1.0f / nodeDistance(k[0]), i1 = 1.0f / nodeDistance(k[1]), i2 = 1.0f / nodeDistance(k[2]),
                  i3 = 1.0f / nodeDistance(k[3]);
      const float invX = 1.0f / static_cast<float>(xb - xa), invY = 1.0f / static_cast<float>(yb - ya);
      for (int y = ya; y <= yb && clean; ++y) {
        const float t = static_cast<float>(y - ya) * invY;
        const float a = i0 + t * (i2 - i0), b = i1 + t * (i3 - i1);
        for (int x = xa; x <= xb && clean; ++x) {
          const float d = dist(x, y);
          const float want = a + static_cast<float>(x - xa) * invX * (b - a);
          clean = !std::isfinite(d) || std::abs(want * d - 1.0f) <= kFogSameSurface;
        }
      }
    }
    if (!clean && xb - xa <= kFogLayeredMax && yb - ya <= kFogLayeredMax && layered(xa, xb, ya, yb, xEnd, yStop, k))
      return;
    const float nearest =
        std::min(std::min(nodeDistance(k[0]), nodeDistance(k[1])), std::min(nodeDistance(k[2]), nodeDistance(k[3])));
    if (clean && nearest < kFogFar * mfp_) {
      // The centre and the middles of the edges (the children's corners if the cell splits; a
      // smallest cell's own pixels).
      const int xc = (xa + xb) / 2, yc = (ya + yb) / 2;
      const int probe[5][2] = {{xc, yc}, {xc, ya}, {xc, yb}, {xa, yc}, {xb, yc}};
      for (const auto& p : probe) {
        if (!clean) break;
        if (std::isfinite(dist(p[0], p[1]))) clean = predicts(k, xa, xb, ya, yb, p[0], p[1]);
      }
    }
    if (clean) {
      blend(xa, xb, ya, yb, xEnd, yStop, k);
      return;
    }
    if (xb - xa <= 2 && yb - ya <= 2) {
      pixels(xa, xEnd, ya, yStop);
      return;
    }
    const int xm = xb - xa > 2 ? (xa + xb) / 2 : xb, ym = yb - ya > 2 ? (ya + yb) / 2 : yb;
    cell(xa, xm, ya, ym);
    if (xm < xb) cell(xm, xb, ya, ym);
    if (ym < yb) {
      cell(xa, xm, ym, yb);
      if (xm < xb) cell(xm, xb, ym, yb);
    }
  }

  // The corners' perspective-correct bilinear weights at (x, y) (blend()).
  void weights(const std::size_t (&k)[4], int xa, int xb, int ya, int yb, int x, int y, float (&wt)[4]) const {
    const float u = static_cast<float>(x - xa) / static_cast<float>(xb - xa);
    const float t = static_cast<float>(y - ya) / static_cast<float>(yb - ya);
    wt[0] = (1 - u) * (1 - t) / nodeDistance(k[0]);
    wt[1] = u * (1 - t) / nodeDistance(k[1]);
    wt[2] = (1 - u) * t / nodeDistance(k[2]);
    wt[3] = u * t / nodeDistance(k[3]);
    const float norm = 1.0f / (wt[0] + wt[1] + wt[2] + wt[3]);
    for (float& v : wt) v *= norm;
  }

  // Whether the corners' blend gives the node at (x, y) within the tolerance (class comment),
  // summed over the grid's lamps.
  bool predicts(const std::size_t (&k)[4], int xa, int xb, int ya, int yb, int x, int y) {
    float wt[4];
    weights(k, xa, xb, ya, yb, x, y, wt);
    return predictsWith(k, wt, node(x, y));
  }

  // Whether the corners blended with the weights `wt` (summing to 1) give node c's
  // coefficients within the tolerance.
  bool predictsWith(const std::size_t (&k)[4], const float (&wt)[4], std::size_t c) {
    float miss1 = 0.0f, total1 = 0.0f, miss0 = 0.0f, total0 = 0.0f;
    // The symmetric functions facing the lamp (μ = 1, b1_) and edge-on (μ = 0, b0_); edge-on the
    // dipole is D0 · n (its other functions vanish at μ = 0), facing the lamp D · n = 0.
    const float* b1 = b1_;
    const float* b0 = b0_;
    std::size_t l = 0;
    for (const FogLightFrame::Lamp& lamp : f_.fog_light.lamps) {
      const std::size_t n = fogLightFloats(lamp);
      float pred[kFogLightFloats] = {};
      for (std::size_t q = 0; q < n; ++q)
        for (int i = 0; i < 4; ++i) pred[q] += wt[i] * coef(k[i])[l + q];
      const float* v = coef(c) + l;
      float e1 = 0.0f, p1 = 0.0f, e0 = 0.0f, p0 = 0.0f;
      for (std::size_t q = 0; q < 4; ++q) {
        e1 += b1[q] * v[q];
        p1 += b1[q] * pred[q];
        e0 += b0[q] * v[q];
        p0 += b0[q] * pred[q];
      }
      miss1 += std::abs(p1 - e1);
      total1 += std::abs(e1);
      miss0 += std::abs(p0 - e0);
      total0 += std::abs(e0);
      if (n > FogLightTable::kSymmetric) {
        // The dipole edge-on: the vector D0, its miss and its length.
        float dm = 0.0f, dv = 0.0f;
        for (std::size_t e = 0; e < 3; ++e) {
          const float want = v[4 + e], got = pred[4 + e];
          dm += (got - want) * (got - want);
          dv += want * want;
        }
        miss0 += std::sqrt(dm);
        total0 += std::sqrt(dv);
      }
      l += n;
    }
    // What the eye sees of a miss at distance d is e^{−K_t d} of it: the floor, seen there.
    const float floor = floor_ * std::exp(std::min(nodeDistance(c) / mfp_, 80.0f));
    return miss1 <= kFogTolerance * total1 + floor && miss0 <= kFogTolerance * total0 + floor;
  }

  // Whether distances a and b (finite, m) are one layer for the fog light (the class comment).
  [[nodiscard]] bool sameLayer(float a, float b) const {
    const float farD = kFogFar * mfp_;
    if (a >= farD && b >= farD) return true;
    const float qa = 1.0f / a, qb = 1.0f / b;
    return std::abs(qa - qb) <= kFogLayer * std::max(qa, qb);
  }

  // The perspective-correct weights at (x, y) of the corners in the layer of distance d (sky
  // corners never), renormalised; false when none has weight (the pixel lies on the far side
  // of those it has, or it has none).
  bool layerWeights(const std::size_t (&k)[4], int xa, int xb, int ya, int yb, int x, int y, float d,
                    float (&wt)[4]) const {
    const float u = static_cast<float>(x - xa) / static_cast<float>(xb - xa);
    const float t = static_cast<float>(y - ya) / static_cast<float>(yb - ya);
    const float bil[4] = {(1 - u) * (1 - t), u * (1 - t), (1 - u) * t, u * t};
    float sum = 0.0f;
    for (int i = 0; i < 4; ++i) {
      const float dc = nodeDistance(k[i]);
      wt[i] = std::isfinite(dc) && sameLayer(dc, d) ? bil[i] / dc : 0.0f;
      sum += wt[i];
    }
    if (!(sum > 0.0f)) return false;
    const float norm = 1.0f / sum;
    for (float& v : wt) v *= norm;
    return true;
  }

  // A cell across a silhouette filled layer by layer (the class comment): false, and nothing
  // written, when a probe's layer has no corner to predict it from or misses the tolerance.
  bool layered(int xa, int xb, int ya, int yb, int xEnd, int yStop, const std::size_t (&k)[4]) {
    const int xc = (xa + xb) / 2, yc = (ya + yb) / 2;
    const int probe[5][2] = {{xc, yc}, {xc, ya}, {xc, yb}, {xa, yc}, {xb, yc}};
    float wt[4];
    float judged[5];  // the distances of the probes that passed: the layers shown to blend well
    int nJudged = 0;
    for (const auto& p : probe) {
      const float d = dist(p[0], p[1]);
      if (!std::isfinite(d) || d >= kFogFar * mfp_) continue;  // sky; far: not judged (cell())
      if (!layerWeights(k, xa, xb, ya, yb, p[0], p[1], d, wt) || !predictsWith(k, wt, node(p[0], p[1])))
        return false;
      judged[nJudged++] = d;
    }
    for (int y = ya; y < yStop; ++y)
      for (int x = xa; x < xEnd; ++x) {
        const float d = dist(x, y);
        if (!std::isfinite(d)) continue;  // sky: never read
        bool shown = d >= kFogFar * mfp_;
        for (int i = 0; i < nJudged && !shown; ++i) shown = sameLayer(judged[i], d);
        // No corner in its layer (a post thinner than the cell), or a layer no probe fell in.
        if (!shown || !layerWeights(k, xa, xb, ya, yb, x, y, d, wt)) {
          put(x, y, node(x, y));
          continue;
        }
        for (std::size_t q = 0; q < nc(); ++q)
          *out(x, y, q) = wt[0] * coef(k[0])[q] + wt[1] * coef(k[1])[q] + wt[2] * coef(k[2])[q] + wt[3] * coef(k[3])[q];
      }
    return true;
  }

  // Bilinear over [xa, xEnd) × [ya, yStop), perspective-correct: the weights of the corners
  // divided by their distances and renormalised (on a plane 1/depth is linear over the image, so
  // this is linear interpolation over the surface, as a rasteriser interpolates attributes; near
  // the horizon a cell spans tens of metres of road, most of them in its top rows).
  void blend(int xa, int xb, int ya, int yb, int xEnd, int yStop, const std::size_t (&k)[4]) {
    // Σ w_i s_i / d_i over Σ w_i / d_i, both bilinear (separable): per pixel one lerp and one
    // product per coefficient, and one division per pixel.
    const float invX = 1.0f / static_cast<float>(xb - xa), invY = 1.0f / static_cast<float>(yb - ya);
    float id[4];
    for (int i = 0; i < 4; ++i) id[i] = 1.0f / nodeDistance(k[i]);
    const int n = xEnd - xa;
    sc_.w.resize(static_cast<std::size_t>(n));
    float* R = sc_.w.data();
    for (int y = ya; y < yStop; ++y) {
      const float t = static_cast<float>(y - ya) * invY;
      const float ia = id[0] + t * (id[2] - id[0]), ib = id[1] + t * (id[3] - id[1]);
      const float di = (ib - ia) * invX;
      for (int x = 0; x < n; ++x) R[x] = 1.0f / (ia + static_cast<float>(x) * di);
      for (std::size_t q = 0; q < nc(); ++q) {
        const float a0 = coef(k[0])[q] * id[0], a1 = coef(k[1])[q] * id[1], a2 = coef(k[2])[q] * id[2],
                    a3 = coef(k[3])[q] * id[3];
        const float A = a0 + t * (a2 - a0), B = a1 + t * (a3 - a1), dq = (B - A) * invX;
        float* o = out(xa, y, q);
        for (int x = 0; x < n; ++x) o[x] = (A + static_cast<float>(x) * dq) * R[x];
      }
    }
  }

  // Pixel by pixel: each pixel's own coefficients (a smallest cell across a silhouette, or where
  // the light bends too fast for the blend).
  void pixels(int xa, int xEnd, int ya, int yStop) {
    for (int y = ya; y < yStop; ++y)
      for (int x = xa; x < xEnd; ++x) {
        if (std::isfinite(dist(x, y))) put(x, y, node(x, y));  // sky pixels: never read
      }
  }
};

// The fog light's error the eye cannot see (lux, as seen through the fog: E e^{−K_t d}): 1e-3 of
// the largest the frame shows (Σ over lamps of E facing them, estimated on a sparse grid, every
// 64th pixel). Cells whose error stays below it are not refined: near the horizon, where a
// pixel row spans metres of road, the surfaces' light is a vanishing part of the image.
float fogLightFloor(const kernels::ShadeFrame& frame, const SurfaceGBufferView& g) {
  constexpr int kSparse = 64;
  thread_local std::vector<float> planeT, coef;
  thread_local std::vector<std::int32_t> planeIndex;
  const auto W = static_cast<std::size_t>(g.width);
  planeT.resize(W);
  planeIndex.resize(W);
  coef.resize(frame.fog_light.floats());
  const float kt = static_cast<float>(frame.fog_light.extinction);
  float b1[4];
  fogLightBasis(1.0f, b1, static_cast<float*>(nullptr));
  float largest = 0.0f;
  for (int y = kSparse / 2; y < g.height; y += kSparse) {
    kernels::castPlanesRow(frame, y, g.width, planeT.data(), planeIndex.data());
    const std::size_t src = g.bottom_up ? static_cast<std::size_t>(g.height - 1 - y) : static_cast<std::size_t>(y);
    for (int x = kSparse / 2; x < g.width; x += kSparse) {
      const auto xi = static_cast<std::size_t>(x);
      const float gd = g.distance != nullptr ? g.distance[W * src + xi] : std::numeric_limits<float>::infinity();
      const float d = std::min(gd, planeT[xi]);
      if (!std::isfinite(d)) continue;
      fogLightCoefficients(frame.fog_light, pixelPoint(frame, x, y, static_cast<double>(d)), coef.data());
      float e = 0.0f;  // Σ over lamps of E facing them (where D · n = 0)
      std::size_t l = 0;
      for (const FogLightFrame::Lamp& lamp : frame.fog_light.lamps) {
        for (std::size_t q = 0; q < FogLightTable::kSymmetric; ++q) e += b1[q] * coef[l + q];
        l += fogLightFloats(lamp);
      }
      largest = std::max(largest, e * std::exp(-kt * d));
    }
  }
  return 1e-3f * largest;
}

}  // namespace

void SurfaceShader::shade(const kernels::ShadeFrame& frame, const SurfaceGBufferView& g, SurfaceBuffers& out,
                          ThreadPool* pool) const {
  const auto w = static_cast<std::size_t>(g.width), h = static_cast<std::size_t>(g.height);
  out.width = g.width;
  out.height = g.height;
  out.rgb.resize(3 * w * h);
  out.distance.resize(w * h);
  const bool mesh = g.normal_rho_r != nullptr && g.rho_gb != nullptr && g.distance != nullptr;
  const bool fog = frame.fog_light.table != nullptr && !frame.fog_light.lamps.empty() && w > 0 && h > 0;
  // Rows in bands of 8, a band per task: few enough tasks to hand out cheaply, enough of them
  // (90 at 720 rows) to balance two to sixteen threads. With the fog light a task is a part of
  // kFogColumns columns of a band of kFogTile rows (its tiles): the part's coefficient rows (up to
  // 16 per lamp and pixel) stay in the core's cache between the grid that writes them and the
  // kernel that reads them, and the grid's cost, which gathers where silhouettes and the horizon
  // are (one band of the bench scene at 1280×720 held 13 % of it), spreads over many tasks.
  const std::size_t nq = frame.fog_light.floats();
  if (fog) {
    const std::size_t columns = std::min<std::size_t>(w, kFogColumns), stride = columns + 64;
    const std::size_t bands = (h + kFogTile - 1) / kFogTile, parts = (w + columns - 1) / columns;
    const float floor = frame.fog_light_exact ? 0.0f : fogLightFloor(frame, g);
    auto part = [&](std::size_t t) {
      // The part's planes, distances and fog light (sized once per thread).
      thread_local std::vector<float> planeT, rows;
      thread_local std::vector<std::int32_t> planeIndex;
      thread_local FogTileScratch scratch;
      const std::size_t j0 = (t / parts) * kFogTile, j1 = std::min(h, j0 + kFogTile);
      const std::size_t x0 = (t % parts) * columns, n = std::min(columns, w - x0);
      FogTile tile(frame, g, stride, floor, scratch);
      tile.begin(static_cast<int>(j0), static_cast<int>(x0), static_cast<int>(x0 + n), planeT, planeIndex);
      tile.columns(rows);
      const std::size_t width = tile.width();
      for (std::size_t j = j0; j < j1; ++j) {
        const std::size_t src = g.bottom_up ? h - 1 - j : j;  // the G-buffer's row of image row j
        const std::size_t p = w * src + x0, r = (j - j0) * width;
        kernels::shadeRow(frame, static_cast<int>(j), static_cast<int>(n), mesh ? g.normal_rho_r + 4 * p : nullptr,
                          mesh ? g.rho_gb + 2 * p : nullptr, mesh ? g.distance + p : nullptr, planeT.data() + r,
                          planeIndex.data() + r, out.rgb.data() + 3 * (w * j + x0), out.distance.data() + w * j + x0,
                          rows.data() + (j - j0) * nq * stride, stride, static_cast<int>(x0));
      }
    };
    parallelFor(pool, bands * parts, part);
    return;
  }
  constexpr std::size_t kBand = 8;
  const std::size_t bands = (h + kBand - 1) / kBand;
  auto band = [&](std::size_t b) {
    // The planes' distances and indices of the band's rows (sized once per thread).
    thread_local std::vector<float> planeT;
    thread_local std::vector<std::int32_t> planeIndex;
    const std::size_t j0 = b * kBand, j1 = std::min(h, (b + 1) * kBand);
    if (planeT.size() < w) {
      planeT.resize(w);
      planeIndex.resize(w);
    }
    for (std::size_t j = j0; j < j1; ++j) {
      const std::size_t src = g.bottom_up ? h - 1 - j : j;  // the G-buffer's row of image row j
      kernels::castPlanesRow(frame, static_cast<int>(j), static_cast<int>(w), planeT.data(), planeIndex.data());
      kernels::shadeRow(frame, static_cast<int>(j), static_cast<int>(w), mesh ? g.normal_rho_r + 4 * w * src : nullptr,
                        mesh ? g.rho_gb + 2 * w * src : nullptr, mesh ? g.distance + w * src : nullptr, planeT.data(),
                        planeIndex.data(), out.rgb.data() + 3 * w * j, out.distance.data() + w * j);
    }
  };
  parallelFor(pool, bands, band);
}

void SurfaceShader::render(const Scene& scene, kernels::ShadeFrame& frame, SurfaceBuffers& out, ThreadPool* pool) {
  prepare(scene, frame, pool);
  SurfaceGBufferView none;
  none.width = scene.camera.width;
  none.height = scene.camera.height;
  shade(frame, none, out, pool);
}

}  // namespace fogbeam
