// fogbeam — the airlight layer of a frame: the in-scattered luminance of every lamp along every
// pixel's ray, up to the visible surface given by the surface pass's distance buffer.
//
// Adaptive subsampling (the paper's "coherence" idea): the image is covered by blocks of
// `coarse_step` pixels whose corners are evaluated; a block is filled by bilinear
// interpolation when its evaluated centre matches the corners' bilinear prediction within the
// tolerances, its distance buffer has no edge, and no lamp projects into it; otherwise it is
// split in four, down to single pixels.
// `full` forces per-pixel evaluation. Work is spread over a persistent thread pool; buffers
// are sized once, so frames of the same size do not allocate.
//
// Thread-safety: one evaluate() at a time per AirlightImageEvaluator.
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <cstddef>
#include <memory>
#include <utility>
#include <vector>

namespace fogbeam {

struct SubsamplingOptions {
  bool full = false;          ///< evaluate every pixel
  int coarse_step = 8;        ///< initial block size in pixels (a power of two ≥ 2)
  double rel_tolerance = 0.005; ///< centre vs bilinear prediction: |Δ| ≤ rel · L + abs (luminance sum)
  double abs_tolerance_cd_m2 = 1e-3;
  double depth_edge_rel = 0.02;  ///< edge: a pixel's 1/d departs from the corners' bilinear 1/d by more than this, relatively
  int lamp_guard_px = 2;      ///< blocks within this many pixels of a lamp's image are split
};

/// Airlight per pixel and channel (cd/m²), and how many pixels were evaluated.
struct AirlightImage {
  int width = 0, height = 0;
  std::vector<float> rgb;        ///< 3 per pixel, row 0 at the top
  std::size_t evaluated = 0;     ///< pixels whose rays were evaluated (the rest interpolated)
  double seconds = 0.0;          ///< wall time of the last evaluate()
};

class AirlightImageEvaluator {
 public:
  /// Builds one AirlightEvaluator per lamp (tables shared through the evaluators' caches).
  [[nodiscard]] static Result<AirlightImageEvaluator> build(const Scene& scene, AirlightMethod method,
                                                            const AirlightOptions& options = {},
                                                            unsigned threads = 0);

  /// Fills `out` for the scene's camera using `surface.distance` (+inf = sky).
  void evaluate(const Scene& scene, const SurfaceBuffers& surface, const SubsamplingOptions& opt, AirlightImage& out);

  /// Sum over lamps of colour × L_m for one ray (cd/m² per channel).
  void evaluateRay(const Ray& ray, float rgb[3]) const noexcept;

 private:
  AirlightImageEvaluator() = default;
  std::vector<AirlightEvaluator> lamps_;
  std::shared_ptr<ThreadPool> pool_;
  std::vector<unsigned char> done_;  // per pixel: evaluated (1) or filled (2)
  std::vector<std::pair<double, double>> lampPixels_;  // lamps' image positions this frame
};

}  // namespace fogbeam
