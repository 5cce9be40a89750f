// fogbeam — one moving lamp's adaptive sampling of a frame (lamp_map.hpp).
#include <fogbeam/render/lamp_map.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

namespace fogbeam {

namespace {
bool powerOfTwo(int v) { return v > 0 && (v & (v - 1)) == 0; }
// Values are interpolated as log(L·h + ε): the airlight over a surface falls off roughly
// exponentially with the distance, which bilinear interpolation of L itself follows only on
// cells a few pixels wide. ε keeps log finite where the lamp is dark (1e-12 cd/m² at h = 1 m).
constexpr double kEps = 1e-12;
int levelsFor(int coarse) {
  int l = 1;
  while ((coarse >> (l - 1)) > 1) ++l;
  return l;
}
}  // namespace

// ---------------------------------------------------------------------------------------------
void CellLevels::reset(int levels, int nx0, int ny0) {
  nx0_ = nx0;
  ny0_ = ny0;
  offset_.resize(static_cast<std::size_t>(levels));
  std::size_t total = 0;
  for (int l = 0; l < levels; ++l) {
    offset_[static_cast<std::size_t>(l)] = total;
    total += across(l) * down(l);
  }
  bytes_.assign(total, 0);
}

// ---------------------------------------------------------------------------------------------
void DepthEdges::build(const float* distance, int width, int height, int coarse_px, double rel, double far_m,
                       ThreadPool& pool) {
  distance_ = distance;
  width_ = width;
  height_ = height;
  coarse_ = coarse_px;
  levels_ = levelsFor(coarse_px);
  nx0_ = (width + coarse_px - 1) / coarse_px;
  ny0_ = (height + coarse_px - 1) / coarse_px;
  const int lw = nx0_ * coarse_px + 1, lh = ny0_ * coarse_px + 1;
  pixel_.assign(static_cast<std::size_t>(lw) * static_cast<std::size_t>(lh), 0);
  // Per pixel (rows in parallel; the lattice's points beyond the image repeat the edge pixels).
  // The rows' closure holds one pointer, so that std::function keeps it without allocating.
  struct Rows {
    const float* distance;
    int width, height, lw;
    double rel, floorQ;
    std::uint8_t* out;
    double q(int i, int j) const {
      i = std::clamp(i, 0, width - 1);
      j = std::clamp(j, 0, height - 1);
      const float d = distance[static_cast<std::size_t>(j) * static_cast<std::size_t>(width) + static_cast<std::size_t>(i)];
      return std::isinf(d) || !(d > 0.0f) ? 0.0 : 1.0 / static_cast<double>(d);
    }
    void row(int j) const {
      for (int i = 0; i < lw; ++i) {
        const double c = q(i, j);
        bool edge = false;
        for (int axis = 0; axis < 2 && !edge; ++axis) {
          const double a = axis == 0 ? q(i - 1, j) : q(i, j - 1);
          const double b = axis == 0 ? q(i + 1, j) : q(i, j + 1);
          const double big = std::max({a, b, c});
          edge = big > floorQ && std::abs(a - 2.0 * c + b) > rel * big;
        }
        out[static_cast<std::size_t>(j) * static_cast<std::size_t>(lw) + static_cast<std::size_t>(i)] = edge ? 1 : 0;
      }
    }
  };
  const Rows rows{distance, width, height, lw, rel, far_m > 0.0 ? 1.0 / far_m : 0.0, pixel_.data()};
  const Rows* r = &rows;
  pool.parallelFor(static_cast<std::size_t>(lh), [r](std::size_t j) { r->row(static_cast<int>(j)); });
  // Cells: the finest (one pixel: its four corner pixels) from the pixels, each coarser level
  // from its four children (their closed areas cover the parent's).
  cells_.reset(levels_, nx0_, ny0_);
  {
    const int l = levels_ - 1;
    for (std::size_t cy = 0; cy < cells_.down(l); ++cy)
      for (std::size_t cx = 0; cx < cells_.across(l); ++cx) {
        const std::uint8_t* p = pixel_.data() + cy * static_cast<std::size_t>(lw) + cx;
        cells_.at(l, static_cast<int>(cx), static_cast<int>(cy)) = static_cast<std::uint8_t>(p[0] | p[1] | p[lw] | p[lw + 1]);
      }
  }
  for (int l = levels_ - 2; l >= 0; --l)
    for (int cy = 0; cy < static_cast<int>(cells_.down(l)); ++cy)
      for (int cx = 0; cx < static_cast<int>(cells_.across(l)); ++cx)
        cells_.at(l, cx, cy) = static_cast<std::uint8_t>(cells_.at(l + 1, 2 * cx, 2 * cy) | cells_.at(l + 1, 2 * cx + 1, 2 * cy) |
                                                         cells_.at(l + 1, 2 * cx, 2 * cy + 1) |
                                                         cells_.at(l + 1, 2 * cx + 1, 2 * cy + 1));
}

// ---------------------------------------------------------------------------------------------
Status LampMap::validate(const LampMapOptions& o) {
  if (!powerOfTwo(o.coarse_px) || o.coarse_px < 2 || o.coarse_px > 256)
    return Error{"lamp map: coarse_px must be a power of two in [2, 256]"};
  if (!(o.tolerance > 0.0 && o.tolerance < 1.0) || !(o.floor_fraction >= 0.0 && o.floor_fraction < 1.0) ||
      !(o.image_guard_px >= 0.0 && o.image_guard_px <= 64.0))
    return Error{"lamp map: need 0 < tolerance < 1, 0 <= floor_fraction < 1 and 0 <= image_guard_px <= 64"};
  return Ok{};
}

int LampMap::nodeAt(int X, int Y) const noexcept {
  return nodeIndex_[static_cast<std::size_t>(Y) * static_cast<std::size_t>(latticeW_) + static_cast<std::size_t>(X)];
}

int LampMap::addNode(int X, int Y) {
  int& slot = nodeIndex_[static_cast<std::size_t>(Y) * static_cast<std::size_t>(latticeW_) + static_cast<std::size_t>(X)];
  if (slot >= 0) return slot;
  slot = static_cast<int>(nodeX_.size());
  nodeX_.push_back(X);
  nodeY_.push_back(Y);
  pending_.push_back(static_cast<std::size_t>(slot));
  return slot;
}

double LampMap::hOf(double x, double y) const noexcept {
  return glm::length(glm::cross(camera_.rayDirection(x, y), lampRel_));
}

void LampMap::evaluateNode(std::size_t node) {
  // Lattice points beyond the image (the last cells' far corners) take the edge pixel's
  // distance along their own ray.
  const int X = nodeX_[node], Y = nodeY_[node];
  const int i = std::min(X, edges_->width() - 1), j = std::min(Y, edges_->height() - 1);
  const double d = static_cast<double>(
      edges_->distance()[static_cast<std::size_t>(j) * static_cast<std::size_t>(edges_->width()) + static_cast<std::size_t>(i)]);
  const double x = X + 0.5, y = Y + 0.5;
  const double h = hOf(x, y);
  const double l = pencil_->evaluate(camera_.rayDirection(x, y), d);
  value_[node] = static_cast<float>(std::log(l * h + kEps));
  nodeH_[node] = static_cast<float>(h);
}

void LampMap::evaluatePending(ThreadPool& pool) {
  if (pending_.empty()) return;
  // The node arrays grow here, on the calling thread, before the workers write into them.
  value_.resize(nodeX_.size());
  nodeH_.resize(nodeX_.size());
  // Chunks of 16 nodes: a node costs a few µs, a pool hand-out ~1 µs.
  constexpr std::size_t kChunk = 16;
  const std::size_t chunks = (pending_.size() + kChunk - 1) / kChunk;
  // A closure of one pointer: std::function keeps it without allocating.
  pool.parallelFor(chunks, [this](std::size_t c) {
    const std::size_t end = std::min(pending_.size(), (c + 1) * kChunk);
    for (std::size_t k = c * kChunk; k < end; ++k) evaluateNode(pending_[k]);
  });
  stats_.nodes += pending_.size();
  pending_.clear();
}

void LampMap::build(const PencilAirlight& pencil, const Camera& camera, const DepthEdges& edges,
                    const LampMapOptions& options, ThreadPool& pool) {
  const auto t0 = std::chrono::steady_clock::now();
  pencil_ = &pencil;
  edges_ = &edges;
  camera_ = camera;
  options_ = options;
  stats_ = {};
  lampRel_ = pencil.lamp().lamp().position_m - camera.position_m;

  const int s0 = options.coarse_px;
  levels_ = levelsFor(s0);
  nx0_ = (camera.width + s0 - 1) / s0;
  ny0_ = (camera.height + s0 - 1) / s0;
  latticeW_ = nx0_ * s0 + 1;
  latticeH_ = ny0_ * s0 + 1;

  // Reset only the lattice points the last build wrote (the lattice has a point per pixel).
  const std::size_t latticeSize = static_cast<std::size_t>(latticeW_) * static_cast<std::size_t>(latticeH_);
  if (nodeIndex_.size() != latticeSize) {
    nodeIndex_.assign(latticeSize, -1);
  } else {
    for (std::size_t n = 0; n < nodeX_.size(); ++n)
      nodeIndex_[static_cast<std::size_t>(nodeY_[n]) * static_cast<std::size_t>(latticeW_) +
                 static_cast<std::size_t>(nodeX_[n])] = -1;
  }
  nodeX_.clear();
  nodeY_.clear();
  pending_.clear();
  split_.reset(levels_, nx0_, ny0_);

  // The lamp's image (pixels), for the cells forced to split around it.
  const Vec3 c = glm::transpose(camera.worldFromCamera) * lampRel_;
  imageInFront_ = c.x > 1e-9;
  if (imageInFront_) {
    const double fp = camera.focalLengthPixels();
    const Vec2 pp = camera.principalPoint();
    image_ = Vec2(pp.x - fp * c.y / c.x, pp.y - fp * c.z / c.x);
  }

  // Level 0: the coarse lattice.
  for (int j = 0; j <= ny0_; ++j)
    for (int i = 0; i <= nx0_; ++i) addNode(i * s0, j * s0);
  evaluatePending(pool);

  // The floor: a fraction of the 90th percentile of the coarse nodes' luminance.
  double floorL = 0.0;
  scratch_.clear();
  for (std::size_t n = 0; n < nodeX_.size(); ++n)
    if (nodeH_[n] > 0.0f) scratch_.push_back((std::exp(static_cast<double>(value_[n])) - kEps) / static_cast<double>(nodeH_[n]));
  if (!scratch_.empty()) {
    const std::size_t q = scratch_.size() * 9 / 10;
    std::nth_element(scratch_.begin(), scratch_.begin() + static_cast<std::ptrdiff_t>(q), scratch_.end());
    floorL = options.floor_fraction * scratch_[q];
  }

  // Levels: test every cell's centre against its corners; split the failures.
  cells_.clear();
  for (int j = 0; j < ny0_; ++j)
    for (int i = 0; i < nx0_; ++i) {
      cells_.push_back(i);
      cells_.push_back(j);
    }
  const double guard = options.image_guard_px;
  for (int l = 0; l + 1 < levels_ && !cells_.empty(); ++l) {
    const int s = s0 >> l, half = s / 2;
    for (std::size_t q = 0; q < cells_.size(); q += 2) addNode(cells_[q] * s + half, cells_[q + 1] * s + half);
    evaluatePending(pool);
    nextCells_.clear();
    for (std::size_t q = 0; q < cells_.size(); q += 2) {
      const int cx = cells_[q], cy = cells_[q + 1];
      const int X0 = cx * s, Y0 = cy * s;
      bool ok = !edges.cell(l, cx, cy);
      // The lamp's image in or next to the cell (pixel centres at +0.5): always split.
      if (ok && imageInFront_ && image_.x > X0 + 0.5 - guard - 1 && image_.x < X0 + s + 0.5 + guard + 1 &&
          image_.y > Y0 + 0.5 - guard - 1 && image_.y < Y0 + s + 0.5 + guard + 1)
        ok = false;
      if (ok) {
        const auto cn = static_cast<std::size_t>(nodeAt(X0 + half, Y0 + half));
        const double mean = std::exp(0.25 * (static_cast<double>(value_[static_cast<std::size_t>(nodeAt(X0, Y0))]) +
                                              static_cast<double>(value_[static_cast<std::size_t>(nodeAt(X0 + s, Y0))]) +
                                              static_cast<double>(value_[static_cast<std::size_t>(nodeAt(X0, Y0 + s))]) +
                                              static_cast<double>(value_[static_cast<std::size_t>(nodeAt(X0 + s, Y0 + s))])));
        const double centre = std::exp(static_cast<double>(value_[cn]));
        const double h = static_cast<double>(nodeH_[cn]);
        ok = std::abs(centre - mean) <= options.tolerance * std::abs(centre) + floorL * h;
      }
      if (ok) {
        ++stats_.leaves;
        continue;
      }
      split_.at(l, cx, cy) = 1;
      // Children at level l + 1: their corners are this cell's corners, centre and edge midpoints.
      addNode(X0 + half, Y0);
      addNode(X0, Y0 + half);
      addNode(X0 + s, Y0 + half);
      addNode(X0 + half, Y0 + s);
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          nextCells_.push_back(2 * cx + dx);
          nextCells_.push_back(2 * cy + dy);
        }
    }
    evaluatePending(pool);
    cells_.swap(nextCells_);
  }
  // Cells of the last level have one pixel's side: their corners are evaluated pixels.
  stats_.leaves += cells_.size() / 2;
  stats_.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

LampMap::Leaf LampMap::leafOf(int i, int j) const noexcept {
  int s = options_.coarse_px;
  int cx = std::min(i / s, nx0_ - 1), cy = std::min(j / s, ny0_ - 1);
  for (int l = 0; l + 1 < levels_ && split_.at(l, cx, cy) != 0; ++l) {
    s /= 2;
    cx = std::clamp(i / s, 2 * cx, 2 * cx + 1);
    cy = std::clamp(j / s, 2 * cy, 2 * cy + 1);
  }
  return {cx * s, cy * s, s};
}

int LampMap::leafSide(int i, int j) const { return leafOf(i, j).s; }

double LampMap::lookup(int i, int j) const {
  const auto [X0, Y0, s] = leafOf(i, j);
  const int n00 = nodeAt(X0, Y0);
  if (i == X0 && j == Y0) {
    const double h = static_cast<double>(nodeH_[static_cast<std::size_t>(n00)]);
    return h > 0.0 ? std::max(0.0, (std::exp(static_cast<double>(value_[static_cast<std::size_t>(n00)])) - kEps) / h) : 0.0;
  }
  const double h = hOf(i + 0.5, j + 0.5);
  if (!(h > 0.0)) return pencil_->evaluate(camera_.rayDirection(i + 0.5, j + 0.5),
                                           static_cast<double>(edges_->distance()[static_cast<std::size_t>(j) *
                                                                                      static_cast<std::size_t>(edges_->width()) +
                                                                                  static_cast<std::size_t>(i)]));
  const auto v = [&](int X, int Y) { return static_cast<double>(value_[static_cast<std::size_t>(nodeAt(X, Y))]); };
  const double tx = static_cast<double>(i - X0) / s, ty = static_cast<double>(j - Y0) / s;
  const double a = v(X0, Y0) + tx * (v(X0 + s, Y0) - v(X0, Y0));
  const double b = v(X0, Y0 + s) + tx * (v(X0 + s, Y0 + s) - v(X0, Y0 + s));
  return std::max(0.0, (std::exp(a + ty * (b - a)) - kEps) / h);
}

}  // namespace fogbeam
