#include <fogbeam/render/airlight_image.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>

namespace fogbeam {

Result<AirlightImageEvaluator> AirlightImageEvaluator::build(const Scene& scene, AirlightMethod method,
                                                             const AirlightOptions& options, unsigned threads) {
  AirlightImageEvaluator e;
  for (const SceneLamp& sl : scene.lamps) {
    auto ev = AirlightEvaluator::build(sl.lamp, scene.fog, method, options);
    if (!ev) return Error{sl.name + ": " + ev.error().message};
    e.lamps_.push_back(std::move(ev).value());
  }
  e.pool_ = std::make_shared<ThreadPool>(threads);
  return e;
}

void AirlightImageEvaluator::evaluateRay(const Ray& ray, float rgb[3]) const noexcept {
  double acc[3] = {0.0, 0.0, 0.0};
  for (const AirlightEvaluator& ev : lamps_) {
    const double l = ev.evaluate(ray);
    for (int c = 0; c < 3; ++c) acc[c] += l * ev.lamp().color[c];
  }
  for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(acc[c]);
}

namespace {

struct Frame {
  const Camera& cam;
  const SurfaceBuffers& surf;
  AirlightImage& out;
  std::vector<unsigned char>& done;
  const AirlightImageEvaluator& ev;
  const std::vector<std::pair<double, double>>& lampPixels;  // image positions of lamps in front
  std::atomic<std::size_t> evaluated{0};

  std::size_t idx(int i, int j) const {
    return static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
  }
  float* px(int i, int j) { return out.rgb.data() + 3 * idx(i, j); }

  void evalPixel(int i, int j, std::size_t& count) {
    const std::size_t k = idx(i, j);
    if (done[k] == 1) return;
    const Ray ray{cam.position_m, cam.rayDirection(i + 0.5, j + 0.5), static_cast<double>(surf.distance[k])};
    ev.evaluateRay(ray, px(i, j));
    done[k] = 1;
    ++count;
  }
};

float lum(const float* p) { return p[0] + p[1] + p[2]; }

// Fills the block [i0, i1] × [j0, j1] (inclusive corners, already evaluated) by subdivision.
void refine(Frame& f, const SubsamplingOptions& o, int i0, int j0, int i1, int j1, std::size_t& count) {
  const int w = i1 - i0, h = j1 - j0;
  if (w <= 1 && h <= 1) return;  // corners are all the pixels
  const float* c00 = f.px(i0, j0);
  const float* c10 = f.px(i1, j0);
  const float* c01 = f.px(i0, j1);
  const float* c11 = f.px(i1, j1);
  // Error estimate: evaluate the block's centre and compare it with the bilinear prediction
  // from the corners (the centre is needed anyway if the block is split).
  const int im = i0 + w / 2, jm = j0 + h / 2;
  f.evalPixel(im, jm, count);
  const float um = w > 0 ? static_cast<float>(im - i0) / static_cast<float>(w) : 0.0f;
  const float vm = h > 0 ? static_cast<float>(jm - j0) / static_cast<float>(h) : 0.0f;
  const float predicted = (1 - um) * (1 - vm) * lum(c00) + um * (1 - vm) * lum(c10) + (1 - um) * vm * lum(c01) +
                          um * vm * lum(c11);
  const float actual = lum(f.px(im, jm));
  bool smooth = std::abs(actual - predicted) <=
                static_cast<float>(o.rel_tolerance) * actual + static_cast<float>(o.abs_tolerance_cd_m2);
  if (smooth) {
    // Distance edges inside the block (a car's silhouette, the horizon) change θd abruptly.
    // Over a plane, 1/distance is close to affine in screen space (exactly so for 1/depth),
    // so a pixel whose 1/d departs from the bilinear blend of the corners' 1/d marks an edge;
    // sky (1/d = 0) next to a surface does so at once.
    auto inv = [&](int i, int j) {
      const float d = f.surf.distance[f.idx(i, j)];
      return std::isinf(d) ? 0.0f : 1.0f / d;
    };
    const float q00 = inv(i0, j0), q10 = inv(i1, j0), q01 = inv(i0, j1), q11 = inv(i1, j1);
    const float tol = static_cast<float>(o.depth_edge_rel);
    for (int j = j0; j <= j1 && smooth; ++j) {
      const float v = h > 0 ? static_cast<float>(j - j0) / static_cast<float>(h) : 0.0f;
      for (int i = i0; i <= i1; ++i) {
        const float u = w > 0 ? static_cast<float>(i - i0) / static_cast<float>(w) : 0.0f;
        const float blend = (1 - u) * (1 - v) * q00 + u * (1 - v) * q10 + (1 - u) * v * q01 + u * v * q11;
        const float q = inv(i, j);
        if (std::abs(q - blend) > tol * std::max(q, blend)) {
          smooth = false;
          break;
        }
      }
    }
  }
  if (smooth) {
    // A lamp imaged inside the block makes a peak that the corners cannot see.
    for (const auto& [x, y] : f.lampPixels)
      if (x >= i0 - o.lamp_guard_px && x <= i1 + 1 + o.lamp_guard_px && y >= j0 - o.lamp_guard_px &&
          y <= j1 + 1 + o.lamp_guard_px) {
        smooth = false;
        break;
      }
  }
  if (smooth) {
    for (int j = j0; j <= j1; ++j) {
      const float v = h > 0 ? static_cast<float>(j - j0) / static_cast<float>(h) : 0.0f;
      for (int i = i0; i <= i1; ++i) {
        const std::size_t k = f.idx(i, j);
        if (f.done[k] == 1) continue;
        const float u = w > 0 ? static_cast<float>(i - i0) / static_cast<float>(w) : 0.0f;
        float* p = f.px(i, j);
        for (int c = 0; c < 3; ++c)
          p[c] = (1 - u) * (1 - v) * c00[c] + u * (1 - v) * c10[c] + (1 - u) * v * c01[c] + u * v * c11[c];
        f.done[k] = 2;
      }
    }
    return;
  }
  // Split: evaluate the new corner points, then recurse into the four quadrants.
  for (int j : {j0, jm, j1})
    for (int i : {i0, im, i1}) f.evalPixel(i, j, count);
  if (w <= 1) {  // a column of pixels
    refine(f, o, i0, j0, i1, jm, count);
    refine(f, o, i0, jm, i1, j1, count);
    return;
  }
  if (h <= 1) {
    refine(f, o, i0, j0, im, j1, count);
    refine(f, o, im, j0, i1, j1, count);
    return;
  }
  refine(f, o, i0, j0, im, jm, count);
  refine(f, o, im, j0, i1, jm, count);
  refine(f, o, i0, jm, im, j1, count);
  refine(f, o, im, jm, i1, j1, count);
}

}  // namespace

void AirlightImageEvaluator::evaluate(const Scene& scene, const SurfaceBuffers& surface, const SubsamplingOptions& opt,
                                      AirlightImage& out) {
  const auto t0 = std::chrono::steady_clock::now();
  const Camera& cam = scene.camera;
  const auto n = static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height);
  if (out.width != cam.width || out.height != cam.height || out.rgb.size() != 3 * n) {
    out.width = cam.width;
    out.height = cam.height;
    out.rgb.assign(3 * n, 0.0f);
  }
  done_.assign(n, 0);  // no reallocation once sized
  // Image positions of lamps in front of the camera (capacity kept between frames).
  lampPixels_.clear();
  const Mat3 camFromWorld = glm::transpose(cam.worldFromCamera);
  const double focal = cam.focalLengthPixels();
  for (const AirlightEvaluator& ev : lamps_) {
    const Vec3 p = camFromWorld * (ev.lamp().position_m - cam.position_m);
    if (p.x <= 0.0) continue;
    lampPixels_.emplace_back(0.5 * cam.width - focal * p.y / p.x, 0.5 * cam.height - focal * p.z / p.x);
  }
  Frame f{cam, surface, out, done_, *this, lampPixels_, {}};

  if (opt.full) {
    pool_->parallelFor(static_cast<std::size_t>(cam.height), [&](std::size_t row) {
      std::size_t count = 0;
      for (int i = 0; i < cam.width; ++i) f.evalPixel(i, static_cast<int>(row), count);
      f.evaluated += count;
    });
  } else {
    const int s = std::max(2, opt.coarse_step);
    const int bx = (cam.width - 2) / s + 1, by = (cam.height - 2) / s + 1;
    // Pass 1: the coarse grid corners (rows in parallel). Pass 2: block rows in parallel;
    // neighbouring blocks share edges, which both may evaluate (idempotent writes of the
    // same value) — rows of blocks are processed in two phases so that no two threads
    // write one pixel at once.
    pool_->parallelFor(static_cast<std::size_t>(by + 1), [&](std::size_t bj) {
      std::size_t count = 0;
      const int j = std::min(static_cast<int>(bj) * s, cam.height - 1);
      for (int bi = 0; bi <= bx; ++bi) f.evalPixel(std::min(bi * s, cam.width - 1), j, count);
      f.evaluated += count;
    });
    for (int phase = 0; phase < 2; ++phase) {
      pool_->parallelFor(static_cast<std::size_t>((by + 1 - phase) / 2), [&](std::size_t k) {
        const int bj = static_cast<int>(2 * k) + phase;
        std::size_t count = 0;
        const int j0 = bj * s, j1 = std::min(j0 + s, cam.height - 1);
        if (j0 >= cam.height - 1) return;
        for (int bi = 0; bi < bx; ++bi) {
          const int i0 = bi * s, i1 = std::min(i0 + s, cam.width - 1);
          if (i0 >= cam.width - 1) break;
          refine(f, opt, i0, j0, i1, j1, count);
        }
        f.evaluated += count;
      });
    }
  }
  out.evaluated = f.evaluated.load();
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace fogbeam
