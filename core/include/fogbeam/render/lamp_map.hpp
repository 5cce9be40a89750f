// fogbeam — the airlight of one moving lamp over one frame, evaluated where that lamp needs it.
//
// A lamp that moves relative to the eye (oncoming traffic, a lamp fixed in the world) has no
// table that outlives a frame: the vehicle lamps' view tables (airlight_kernels.hpp) cost
// seconds to build. Per pixel, the pencil integrator (physics/airlight_pencil.hpp) costs a few
// µs, and the frame's adaptive subsampling asks for it at every pixel the frame's *total*
// needs, for every lamp: ~13 k pixels × 4 lamps for two oncoming cars at 320×180. But one
// lamp's airlight is smooth over most of the image; it bends around its own image, along the
// image of its cut-off and at the silhouettes of the surfaces in front of it.
//
// A LampMap is that lamp's own adaptive sampling of the frame. Nodes are pixels, evaluated by
// the pencil at the pixel's own distance (the frame's distance buffer); they sit on a quadtree
// over the image: a coarse lattice (`coarse_px`), cells split in four where the centre pixel's
// value differs from the mean of the corners' by more than `tolerance` (relative, plus a floor),
// where the cell holds a distance edge (DepthEdges: the surfaces are not one smooth sheet) or
// the lamp's image, down to cells of one pixel, whose corners are the pixels themselves. A
// pixel then reads its leaf: bilinear over the corners of L·h (h the lamp's distance from the
// ray, so that the 1/h peak at the lamp's image is divided out exactly), divided by its own h.
//
// Units: pixels (pixel (i, j) has its centre at (i + 0.5, j + 0.5)), metres, cd/m².
// Thread-safety: build() uses the pool and must not overlap lookup(); lookup() may run from any
// number of threads at once. Rebuilds allocate nothing once the buffers have grown to the
// frame's needs.
#pragma once

#include <fogbeam/physics/airlight_pencil.hpp>
#include <fogbeam/scene/camera.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace fogbeam {

struct LampMapOptions {
  int coarse_px = 16;  ///< node spacing of the coarse lattice, pixels (a power of two, 2–256)
  /// A cell is split where |centre − mean of corners| > tolerance · |centre| + floor, in
  /// luminance; floor = floor_fraction × the 90th percentile of the coarse nodes' luminance.
  /// Relative to the lamp's own values: a conservative stand-in for the pixel's total, which
  /// the map does not know.
  double tolerance = 5e-3;
  double floor_fraction = 2e-3;
  /// Cells within this many pixels of the lamp's image are split down to single pixels.
  double image_guard_px = 2.0;
};

/// One byte per cell of a quadtree over the image, level by level: nx0 × ny0 cells at level 0,
/// each level twice as fine in x and y. What DepthEdges and LampMap keep per cell.
class CellLevels {
 public:
  /// `levels` levels over nx0 × ny0 coarse cells, every byte 0 (no allocation once grown).
  void reset(int levels, int nx0, int ny0);
  [[nodiscard]] std::uint8_t& at(int level, int cx, int cy) noexcept { return bytes_[index(level, cx, cy)]; }
  [[nodiscard]] std::uint8_t at(int level, int cx, int cy) const noexcept { return bytes_[index(level, cx, cy)]; }
  /// Cells across at `level`.
  [[nodiscard]] std::size_t across(int level) const noexcept { return static_cast<std::size_t>(nx0_) << level; }
  [[nodiscard]] std::size_t down(int level) const noexcept { return static_cast<std::size_t>(ny0_) << level; }

 private:
  [[nodiscard]] std::size_t index(int level, int cx, int cy) const noexcept {
    return offset_[static_cast<std::size_t>(level)] + static_cast<std::size_t>(cy) * across(level) +
           static_cast<std::size_t>(cx);
  }
  int nx0_ = 0, ny0_ = 0;
  std::vector<std::size_t> offset_;  // per level, into bytes_
  std::vector<std::uint8_t> bytes_;
};

/// Where a frame's distances are not one smooth surface, per quadtree cell: shared by the maps
/// of one frame. A pixel is an edge where the second difference of 1/d across it (along x or
/// y) exceeds `rel` × the largest 1/d involved, unless all three lie beyond `far_m` (the
/// adaptive subsampling's rule, docs/airlight.md).
class DepthEdges {
 public:
  /// `distance`: width × height metres, row-major, +inf = sky. Cells of `coarse_px` (a power
  /// of two) down to one pixel. Runs on `pool`.
  void build(const float* distance, int width, int height, int coarse_px, double rel, double far_m, ThreadPool& pool);
  /// True when some pixel of the closed cell [cx·s, cx·s + s] × [cy·s, cy·s + s] (pixel
  /// indices, s = coarse_px >> level) is an edge.
  [[nodiscard]] bool cell(int level, int cx, int cy) const noexcept { return cells_.at(level, cx, cy) != 0; }
  [[nodiscard]] int levels() const noexcept { return levels_; }
  [[nodiscard]] int coarse() const noexcept { return coarse_; }
  [[nodiscard]] int width() const noexcept { return width_; }
  [[nodiscard]] int height() const noexcept { return height_; }
  [[nodiscard]] const float* distance() const noexcept { return distance_; }

 private:
  const float* distance_ = nullptr;
  int width_ = 0, height_ = 0, coarse_ = 0, levels_ = 0, nx0_ = 0, ny0_ = 0;
  CellLevels cells_;                 // 1 where the cell holds an edge pixel
  std::vector<std::uint8_t> pixel_;  // per pixel of the lattice (nx0·s + 1) × (ny0·s + 1)
};

/// What one build did (for `fogbeam bench` and the image evaluator's figures).
struct LampMapStats {
  std::size_t nodes = 0;   ///< pixels evaluated by the pencil
  std::size_t leaves = 0;  ///< cells read by interpolation
  double build_seconds = 0.0;
};

class LampMap {
 public:
  [[nodiscard]] static Status validate(const LampMapOptions& options);

  /// Rebuilds the map for one frame. `pencil` must be reset to `camera`'s eye and the lamp's
  /// current pose; `edges` built for this frame's distances with options.coarse_px; both must
  /// outlive the lookups. `options` must pass validate(). Runs on `pool`.
  void build(const PencilAirlight& pencil, const Camera& camera, const DepthEdges& edges,
             const LampMapOptions& options, ThreadPool& pool);

  /// L_m (white light, cd/m²) at pixel (i, j) of the frame (0 ≤ i < width, 0 ≤ j < height).
  [[nodiscard]] double lookup(int i, int j) const;

  /// The side (pixels) of the leaf cell that holds pixel (i, j): where the map refined.
  [[nodiscard]] int leafSide(int i, int j) const;

  [[nodiscard]] const LampMapStats& stats() const noexcept { return stats_; }
  [[nodiscard]] bool built() const noexcept { return pencil_ != nullptr; }

 private:
  [[nodiscard]] int nodeAt(int X, int Y) const noexcept;
  int addNode(int X, int Y);
  void evaluatePending(ThreadPool& pool);
  void evaluateNode(std::size_t node);
  [[nodiscard]] double hOf(double x, double y) const noexcept;
  /// The leaf cell holding pixel (i, j): its corner (X0, Y0) and side s, pixels.
  struct Leaf {
    int X0, Y0, s;
  };
  [[nodiscard]] Leaf leafOf(int i, int j) const noexcept;

  const PencilAirlight* pencil_ = nullptr;
  const DepthEdges* edges_ = nullptr;
  Camera camera_;
  LampMapOptions options_;
  Vec3 lampRel_{0.0};  // lamp position − eye, world
  int levels_ = 0, nx0_ = 0, ny0_ = 0;  // levels; coarse cells across, down
  int latticeW_ = 0, latticeH_ = 0;     // lattice nodes across, down (one per pixel)
  Vec2 image_{0.0};                     // the lamp's image (pixels), if imageInFront_
  bool imageInFront_ = false;
  std::vector<int> nodeIndex_;          // per lattice point: node index or −1
  std::vector<std::int32_t> nodeX_, nodeY_;
  std::vector<float> value_;            // per node: log(L · h + ε), L · h in cd/m² · m (lamp_map.cpp)
  std::vector<float> nodeH_;            // per node: h, metres
  std::vector<std::size_t> pending_;
  CellLevels split_;                     // per cell: 0 leaf, 1 split
  std::vector<std::int32_t> cells_, nextCells_;  // (cx, cy) pairs of the level being tested
  std::vector<double> scratch_;                  // the coarse nodes' luminance (the floor)
  LampMapStats stats_;
};

}  // namespace fogbeam
