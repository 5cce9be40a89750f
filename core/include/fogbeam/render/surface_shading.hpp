// fogbeam — lighting a rasterised frame's surfaces on the CPU (SIMD, threads): deferred shading
// of the geometry buffer the GL surface pass reads back when it runs on a software rasteriser
// (docs/surface_pass.md, "Shading on the CPU").
//
// The equation is the surface pass's, per colour channel, for the surface point X = O + d·ω seen
// at distance d along the pixel's ray ω (Camera::rayDirection of the pixel centre):
//
//   L_s = L(S) e^{−K_t d} + I_a (1 − e^{−K_t d})                         [cd/m²]
//   L(S) = ρ/π · Σ_lamps colour · I(w) cos(incidence) e^{−K_t r} / r²      (Lambertian)
//
// with w = (X − S)/r the direction from the lamp, in the lamp's frame, and I(w) the profile as
// Profile::intensity defines it: isotropic, spot (linear in angle from inner to outer) or the
// tabulated grid interpolated bilinearly at the file's own angles (type A, B, C; every symmetry,
// type C wrap-around) — no resampling, so cut-offs stay where the file puts them. Sky pixels
// (d = +inf) get L_s = I_a. With the fog light on (ShadeFrame::fog_light; [glow] surfaces) each
// lamp's term also gets the fog's scattered light E_fog (fogbeam/render/fog_light.hpp), its
// coefficients (4, and 12 more for a measured lamp's dipole) evaluated on an adaptive grid per
// band of 16 rows and blended between its nodes
// (docs/physics.md, "Scattered light on surfaces").
//
// Why on the CPU: on llvmpipe a fragment shader pays ~6 ns per lamp and pixel for the lamp loop
// alone and ~30 ns for a tabulated profile (buffer-texture fetches and a binary search per lane),
// where Highway vectors over 8–16 pixels with gathers pay a fraction of that; the rasteriser is
// left with what it does well, the triangles and the planes' exact distances. Arithmetic is in
// float, as the shaders' (ray and profile angles to ~1e-7 rad).
//
// Thread-safety: SurfaceShader::prepare mutates the shader's profile cache (one thread at a
// time); shade() is const and may run while another frame is prepared only if the caller keeps
// the profiles a frame names alive (they are, while the shader lives).
#pragma once

#include <fogbeam/render/fog_light.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace fogbeam {

/// A rasterised frame's geometry buffer, as read back: per pixel the unit normal (world axes,
/// turned to face the eye), the Lambertian reflectance ρ per channel and the distance. The
/// scene's planes need not be in it: SurfaceShader casts them itself (null pointers: no mesh).
struct SurfaceGBufferView {
  int width = 0, height = 0;
  const float* normal_rho_r = nullptr;  ///< 4 floats per pixel: n.x, n.y, n.z, ρ red
  const float* rho_gb = nullptr;        ///< 2 floats per pixel: ρ green, ρ blue
  const float* distance = nullptr;      ///< 1 float per pixel: metres along the ray, +inf = sky
  bool bottom_up = true;                ///< row 0 is the image's bottom (glReadPixels order)
};

namespace kernels {

/// One axis of a tabulated profile in float, located in O(1): bucket b = (x − lo)·scale, buckets
/// no wider than half the finest cell, so at most one grid line falls inside a bucket. The cell
/// of x is bucket_cell[b], or the next one where x ≥ bucket_split[b] (that grid line; +inf where
/// the bucket holds none); the weight of the cell's far end is (x − cell_lo[i])·cell_inv[i].
struct ShadeAxis {
  float first = 0.0f, last = 0.0f;  ///< the axis's end angles [rad]
  int n = 0;                        ///< angles on the axis
  float lo = 0.0f, scale = 0.0f;
  int buckets = 0;
  const std::int32_t* bucket_cell = nullptr;
  const float* bucket_split = nullptr;
  const float* cell_lo = nullptr;   ///< n − 1 cells: their first angle [rad]
  const float* cell_inv = nullptr;  ///< 1 / the cell's width [1/rad] (0 for an empty cell)
};

/// A tabulated profile prepared for the kernel (types and symmetry codes as PhotometricType and
/// PlaneSymmetry). For type C without symmetry the first plane is repeated at +360° when the data
/// leave a gap, so the wrap-around is an ordinary cell.
struct ShadeTable {
  int type = 2;      ///< 0 A, 1 B, 2 C
  int symmetry = 0;  ///< PlaneSymmetry in declaration order
  bool single_plane = false;  ///< one horizontal angle, or rotational symmetry: I depends on v only
  ShadeAxis h, v;
  const float* candela = nullptr;  ///< [ih · v.n + iv], cd
};

/// A lamp as the kernel reads it: camera-relative position [m], the lamp axes in world
/// coordinates (w_lamp = (ax·w, ay·w, az·w)), colour, and the profile.
struct ShadeLamp {
  float pos[3];
  float ax[3], ay[3], az[3];
  float color[3];
  int kind = 0;  ///< 0 isotropic, 1 spot, 2 tabulated
  float i0 = 0.0f;  ///< isotropic intensity or spot peak [cd]
  float inner = 0.0f, outer = 0.0f;  ///< spot cone [rad]
  const ShadeTable* table = nullptr;
};

/// Everything one frame's shading needs, in float.
/// A plane: unit normal n and offset c = n·(P₀ − O) relative to the eye [m]; ρ. Bounded (a
/// Quad of the scene's body): only the points X = O + q with q = corner + s·U + t·V,
/// s, t ∈ [0, 1], where s = (q − corner)·u_dual and t = (q − corner)·v_dual (the dual basis of
/// the quad's edges U, V; corner relative to the eye).
struct ShadePlane {
  double n[3];
  double c = 0.0;
  float rho = 0.0f;
  bool bounded = false;
  double corner[3] = {0.0, 0.0, 0.0};
  double u_dual[3] = {0.0, 0.0, 0.0};
  double v_dual[3] = {0.0, 0.0, 0.0};
};

/// Everything one frame's shading needs: in float, but the planes' ray casting in double.
struct ShadeFrame {
  int width = 0, height = 0;
  double world_from_camera[9];  ///< column-major: camera +x (view axis), +y (left), +z (up) in world
  double focal = 0.0, cx = 0.0, cy = 0.0;  ///< pixels; principal point, image y down
  float extinction = 0.0f, ambient = 0.0f;  ///< K_t [1/m], I_a [cd/m²]
  std::vector<ShadeLamp> lamps;
  std::vector<ShadePlane> planes;
  /// The fog's scattered light on the surfaces (fogbeam/render/fog_light.hpp), lamp for lamp as
  /// `lamps`; on where its table is set (SurfaceShader::prepare: [glow] on with `surfaces`, and
  /// the fog's phase function has a multiple-scattering table).
  FogLightFrame fog_light;
  /// Evaluate the fog light at every pixel instead of interpolating it between adaptive nodes
  /// (the reference of the interpolation's tests; many times the cost).
  bool fog_light_exact = false;
};

/// The scene's planes and body quads along the `count` pixel rays of image row j from column x0
/// on, in double as the GL plane shader and Camera::rayDirection: the nearest t > 0 [m] (float;
/// +inf: none) and its plane's index (−1: none), pixel x0 + i at t[i]. SIMD, dispatched at run time.
void castPlanesRow(const ShadeFrame& frame, int j, int count, float* t, std::int32_t* plane, int x0 = 0);

/// Shades the `count` pixels of image row j (column 0 first): at each pixel the nearer of the
/// geometry buffer's surface (interleaved rows in SurfaceGBufferView's layouts; all three null:
/// none) and the plane castPlanesRow found, into `outRgb` (3 floats a pixel, cd/m²) and
/// `outDistance` [m]. `fogLight` (null: none): the fog's scattered light, the floats of
/// fogLightCoefficients (lamp after lamp, fogLightFloats each) of pixel i at
/// fogLight[(o_l + q) · fogStride + i], o_l the first float of lamp l's block, added to each
/// lamp's direct illuminance; fogStride ≥ count + 64 (the last vector reads past the row). `x0`:
/// the image column of the first pixel (a part of the row; every pointer starts at it).
/// SIMD, dispatched at run time; writes nothing beyond the row.
void shadeRow(const ShadeFrame& frame, int j, int count, const float* normalRhoR, const float* rhoGB,
              const float* distance, const float* planeT, const std::int32_t* planeIndex, float* outRgb,
              float* outDistance, const float* fogLight = nullptr, std::size_t fogStride = 0, int x0 = 0);

}  // namespace kernels

class SurfaceShader {
 public:
  /// This frame's camera, fog and lamps, in float (tabulated profiles are converted once and
  /// kept while the shader lives, keyed by identity). With the fog light on ([glow] enabled and
  /// `surfaces`), its table (once per phase function and albedo, ~0.2 s) and each profile's
  /// annulus map (once per profile, ~0.9–1.0 s on 2 cores) are made on first use, on `pool`
  /// when given, or loaded from the table cache (setTableCacheDir).
  void prepare(const Scene& scene, kernels::ShadeFrame& frame, ThreadPool* pool = nullptr);
  /// Where the fog light's table and annulus maps are kept between runs (FogLightTable::shipped's
  /// and AnnulusMeanMap::build's cacheDir; empty, the default: built in every run). Not to be
  /// called while prepare() runs.
  void setTableCacheDir(std::string dir) { cacheDir_ = std::move(dir); }
  /// The last failure to store a table or map there (empty: none since the last call).
  [[nodiscard]] std::string takeTableCacheError() { return std::exchange(cacheError_, {}); }
  /// The fog light's part of prepare() alone (GPU shading, where the shaders read the table and
  /// maps): `fog` emptied when it is off or the fog's phase function has no multiple-scattering
  /// table; the same thread-safety as prepare().
  void prepareFogLight(const Scene& scene, FogLightFrame& fog, ThreadPool* pool = nullptr);
  /// L_s and the distance of every pixel into `out` (resized; row 0 at the top), from the
  /// geometry buffer `g` of the frame `frame` was prepared for. Rows are spread over `pool`
  /// (null: the calling thread).
  void shade(const kernels::ShadeFrame& frame, const SurfaceGBufferView& g, SurfaceBuffers& out,
             ThreadPool* pool) const;

  /// The CPU surface pass where there is no GL (`--surface cpu`): the scene's planes and body
  /// quads cast in double and lit like a geometry buffer's pixels (prepare + shade with no
  /// mesh) into `out`. Within 1e-5 of renderSurfacesCpu (the double-precision oracle, ~5× slower),
  /// distances identical. `frame` is scratch kept by the caller (no allocation once sized).
  void render(const Scene& scene, kernels::ShadeFrame& frame, SurfaceBuffers& out, ThreadPool* pool);

  /// Storage behind a kernels::ShadeAxis (surface_shading.cpp builds it).
  struct Axis {
    std::vector<std::int32_t> cell;
    std::vector<float> split, lo, inv;
  };

 private:
  struct Table {
    std::shared_ptr<const Profile> profile;
    std::vector<float> candela;
    Axis h, v;
    kernels::ShadeTable view;
  };
  std::vector<std::unique_ptr<Table>> tables_;
  const kernels::ShadeTable* tableFor(const std::shared_ptr<const Profile>& profile);
  // The fog light's table and the annulus maps it reads (per profile and front-only flag).
  std::shared_ptr<const FogLightTable> fogTable_;
  struct FogMap {
    std::shared_ptr<const Profile> profile;
    bool frontOnly = false;
    std::shared_ptr<const AnnulusMeanMap> map;
  };
  std::vector<FogMap> fogMaps_;
  std::string cacheDir_, cacheError_;

};

}  // namespace fogbeam
