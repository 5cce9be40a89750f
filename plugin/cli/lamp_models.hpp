// fogbeam — parametric lamp models behind the shipped lamp files (config/lamps/*.ies).
//
// Each model is a closed-form intensity I(H, V) in candela built from a few smooth terms
// (Gaussian lobes, a flat-topped spread, a soft cut-off) whose parameters are documented
// below with unit, default and reason. No candela table is typed by hand: the files are
// these formulas sampled on the grids given here (fogbeam_lampgen writes them, and its
// --check mode guards the shipped files against drift).
//
// Angles: IES type B (profile.hpp). H is measured inside the tilted measuring plane,
// positive to the lamp's RIGHT (−y); V tilts the plane about the lamp's y axis, positive UP;
// H = V = 0 is the photometric axis (+x). Parameters are in degrees (the interface unit of
// docs/physics.md); the TabulatedProfile holds radians.
// Traffic side: right-hand traffic (the low beam's raised cut-off is on the right).
//
// Thread-safety: pure functions.
#pragma once

#include <fogbeam/physics/profile.hpp>

#include <string>
#include <vector>

namespace fogbeam::lamps {

/// One run of a non-uniform angle grid: from_deg, from_deg + step_deg, … up to to_deg.
struct GridSegment {
  double from_deg = 0.0;
  double to_deg = 0.0;
  double step_deg = 1.0;
};

/// Ascending angles in radians covering the segments (each must be ascending with a step
/// that divides its length to 1e-9; a point shared by two segments appears once).
[[nodiscard]] std::vector<double> gridFromSegments(const std::vector<GridSegment>& segments);

/// Fixed strings written into every file's keywords. The issue date is a constant (not
/// today's date) so that regenerating gives identical bytes.
inline constexpr const char* kIssueDate = "2026-11-21";

// ---------------------------------------------------------------------------------------
/// Low (passing) beam for right-hand traffic, shaped after an ECE R112 class B headlamp:
/// a horizontal cut-off on the left, a 15° rising cut-off on the right from an elbow on
/// the V axis, a hot spot just below the cut-off and right of the axis, a broad spread and
/// a foreground, and a faint glare floor above the cut-off.
///
///   I(H, V) = env · [ T(d) · (hot + spread + wide + fore) + glare ]
///   d       = Vcut(H) − V          (degrees below the cut-off line; > 0 lit side)
///   Vcut(H) = cutoff_left_v_deg                                  for H ≤ elbow_h_deg
///           = min(cutoff_left_v_deg + tan(rise)·(H − elbow), cutoff_cap_v_deg)   beyond
///   T(d)    = Φ(d / cutoff_sigma_deg)  (Gaussian CDF: a hard edge blurred like real optics)
///   hot, spread, wide: A·exp(−½((H−H0)/σH)² − ½((V−V0)/σV)²)
///   fore    = A·exp(−½(H/σH)²)·s((V − fore_bottom)/fore_edge)·s((fore_top − V)/fore_edge),
///             s the logistic function (a plateau from fore_bottom up to fore_top)
///   glare   = glare_cd·exp(−½(H/glare_sigma_h)²)·exp(−|V − Vcut|/glare_decay_v)   (stray light
///             straddling the cut-off; below it the beam terms dominate)
///   env     = cos H · cos V        (nothing is emitted backwards)
struct LowBeamParams {
  // Cut-off line.
  double cutoff_left_v_deg = -0.57;  ///< deg; V of the horizontal cut-off (left side). 1 % down
                                     ///< (0.57°), the ECE aiming of a passing beam.
  double elbow_h_deg = 0.0;          ///< deg; H of the elbow where the right part starts to rise
                                     ///< (ECE: on the V–V line).
  double rise_deg = 15.0;            ///< deg; slope of the right-hand cut-off above horizontal
                                     ///< (ECE R112's 15° line).
  double cutoff_cap_v_deg = 1.5;     ///< deg; V where the rising cut-off levels off ("shoulder";
                                     ///< reached at H ≈ 7.7°), below the R112 zone III boundary.
  double cutoff_sigma_deg = 0.15;    ///< deg; σ of the cut-off blur: 10–90 % over 2.56σ ≈ 0.38°,
                                     ///< a sharp cut-off (R112 sharpness G ≥ 0.13 per 0.1°).
  // Hot spot.
  double hot_cd = 18000.0;           ///< cd; amplitude of the hot-spot lobe; with the other terms
                                     ///< the peak is ≈ 26 400 cd (a few 10 000 cd is typical).
  double hot_h_deg = 1.5;            ///< deg; H of the hot spot (slightly right: 50R, 75R).
  double hot_v_deg = -1.5;           ///< deg; V of the hot spot (≈ 1° below the cut-off).
  double hot_sigma_h_deg = 3.0;      ///< deg; horizontal σ of the hot spot.
  double hot_sigma_v_deg = 1.0;      ///< deg; vertical σ of the hot spot (flat, wide beam).
  // Medium spread.
  double spread_cd = 6000.0;         ///< cd; amplitude of the medium lobe (fills 25L/25R).
  double spread_h_deg = 2.0;         ///< deg; H centre (biased right like the hot spot).
  double spread_v_deg = -2.0;        ///< deg; V centre.
  double spread_sigma_h_deg = 10.0;  ///< deg; horizontal σ.
  double spread_sigma_v_deg = 2.5;   ///< deg; vertical σ.
  // Wide spread.
  double wide_cd = 2000.0;           ///< cd; amplitude of the wide lobe (≈ ±40° road edges).
  double wide_v_deg = -2.5;          ///< deg; V centre.
  double wide_sigma_h_deg = 25.0;    ///< deg; horizontal σ.
  double wide_sigma_v_deg = 5.0;     ///< deg; vertical σ.
  // Foreground (road just in front of the car).
  double fore_cd = 1200.0;           ///< cd; plateau height; lamp 0.65 m high: V = −10° meets the
                                     ///< road at 3.7 m, giving ≈ 15 lx there.
  double fore_sigma_h_deg = 35.0;    ///< deg; horizontal σ (the foreground is wide).
  double fore_top_v_deg = -3.0;      ///< deg; upper edge of the plateau (keeps it off the far field).
  double fore_bottom_v_deg = -15.0;  ///< deg; lower edge (road ≈ 2.4 m ahead of the lamp).
  double fore_edge_deg = 1.5;        ///< deg; logistic width of both plateau edges.
  // Above the cut-off.
  double glare_cd = 350.0;           ///< cd; glare floor at the cut-off (≈ 270 cd at H −3°, V +1°;
                                     ///< 285 cd at B50L; R112 allows a few hundred).
  double glare_sigma_h_deg = 20.0;   ///< deg; horizontal σ of the glare floor.
  double glare_decay_v_deg = 6.0;    ///< deg; e-folding of the floor away from the cut-off (up:
                                     ///< overhead signs still see ≈ 60 cd at V = +10°).

  std::vector<GridSegment> h_grid{{-90, -45, 5}, {-45, -15, 1}, {-15, 15, 0.25}, {15, 45, 1}, {45, 90, 5}};
  std::vector<GridSegment> v_grid{{-90, -30, 5}, {-30, -10, 1}, {-10, -3, 0.25}, {-3, 3, 0.1},
                                  {3, 10, 0.25}, {10, 30, 1}, {30, 90, 5}};
};
/// V of the cut-off line (deg) at horizontal angle h_deg.
[[nodiscard]] double lowBeamCutoffV(const LowBeamParams& p, double h_deg);
[[nodiscard]] double lowBeamIntensity(const LowBeamParams& p, double h_deg, double v_deg);
[[nodiscard]] TabulatedProfile makeLowBeam(const LowBeamParams& p = {});

// ---------------------------------------------------------------------------------------
/// High (driving) beam: a concentrated, symmetric, vertically narrow beam on the axis.
///   I(H, V) = env · Σ_k A_k·exp(−½(H/σH_k)² − ½(V/σV_k)²),  k = core, mid, wide
/// Peak = core + mid + wide = 67 500 cd on the axis (ECE: 40 000–100 000 cd typical);
/// against the R112/R149 driving-beam minima: H-3 ≈ 46 000 cd, H-12 ≈ 5 700 cd.
struct HighBeamParams {
  double core_cd = 52000.0;        ///< cd; amplitude of the core (long-range) lobe.
  double core_sigma_h_deg = 3.0;   ///< deg; horizontal σ of the core.
  double core_sigma_v_deg = 1.8;   ///< deg; vertical σ (narrower: light belongs on the road).
  double mid_cd = 14000.0;         ///< cd; amplitude of the medium lobe (H-6…H-12 points).
  double mid_sigma_h_deg = 8.0;    ///< deg; horizontal σ.
  double mid_sigma_v_deg = 3.0;    ///< deg; vertical σ.
  double wide_cd = 1500.0;         ///< cd; amplitude of the wide lobe (≈ 430 cd at ±30°).
  double wide_sigma_h_deg = 20.0;  ///< deg; horizontal σ.
  double wide_sigma_v_deg = 5.0;   ///< deg; vertical σ.
  // Total flux ≈ 1 400 lm, an LED or HID driving beam.

  std::vector<GridSegment> h_grid{{-90, -40, 5}, {-40, -15, 1}, {-15, 15, 0.25}, {15, 40, 1}, {40, 90, 5}};
  std::vector<GridSegment> v_grid{{-90, -20, 5}, {-20, -10, 1}, {-10, 10, 0.25}, {10, 20, 1}, {20, 90, 5}};
};
[[nodiscard]] double highBeamIntensity(const HighBeamParams& p, double h_deg, double v_deg);
[[nodiscard]] TabulatedProfile makeHighBeam(const HighBeamParams& p = {});

// ---------------------------------------------------------------------------------------
/// Front fog lamp (ECE R19 style): very wide and flat, with a sharp horizontal cut-off
/// below the horizon and little light above it (fog scatters it back at the driver).
///   I(H, V) = env · [ T(d) · (flat + core + fore) + glare ],  d = cutoff_v_deg − V
///   flat  = A·exp(−ln2·(H/flat_half_h)⁴)·exp(−½((V−V0)/σV)²)    (flat top, ½ at flat_half_h)
///   core, fore, glare, T, env: as for the low beam (horizontal cut-off only).
/// Peak ≈ 9 000 cd just below the cut-off; ≈ 300 cd on the horizon, < 400 cd anywhere above.
struct FogLampParams {
  double cutoff_v_deg = -1.5;        ///< deg; V of the horizontal cut-off (lamp aimed ~2.6 % down).
  double cutoff_sigma_deg = 0.2;     ///< deg; σ of the cut-off blur (sharp, R19 asks a clear line).
  double flat_cd = 6000.0;           ///< cd; height of the flat-topped wide lobe.
  double flat_half_h_deg = 32.0;     ///< deg; H where the flat lobe is at half height (≈ ±45° lit).
  double flat_v_deg = -3.5;          ///< deg; V centre of the flat lobe.
  double flat_sigma_v_deg = 2.0;     ///< deg; vertical σ of the flat lobe.
  double core_cd = 3000.0;           ///< cd; central lobe that makes the peak (≈ 9 000 cd).
  double core_v_deg = -2.5;          ///< deg; V centre of the core.
  double core_sigma_h_deg = 12.0;    ///< deg; horizontal σ of the core.
  double core_sigma_v_deg = 1.5;     ///< deg; vertical σ of the core.
  double fore_cd = 800.0;            ///< cd; foreground plateau height.
  double fore_sigma_h_deg = 40.0;    ///< deg; horizontal σ of the foreground.
  double fore_top_v_deg = -4.0;      ///< deg; upper edge of the foreground plateau.
  double fore_bottom_v_deg = -15.0;  ///< deg; lower edge of the foreground plateau.
  double fore_edge_deg = 1.5;        ///< deg; logistic width of the plateau edges.
  double glare_cd = 350.0;           ///< cd; floor just above the cut-off (R19: a few hundred cd).
  double glare_sigma_h_deg = 35.0;   ///< deg; horizontal σ of the floor.
  double glare_decay_v_deg = 8.0;    ///< deg; e-folding of the floor away from the cut-off.

  std::vector<GridSegment> h_grid{{-90, -60, 5}, {-60, 60, 1}, {60, 90, 5}};
  std::vector<GridSegment> v_grid{{-90, -30, 5}, {-30, -5, 1}, {-5, 2, 0.1}, {2, 10, 0.5}, {10, 30, 1}, {30, 90, 5}};
};
[[nodiscard]] double fogLampIntensity(const FogLampParams& p, double h_deg, double v_deg);
[[nodiscard]] TabulatedProfile makeFogLamp(const FogLampParams& p = {});

// ---------------------------------------------------------------------------------------
/// Tail (rear position) lamp, ECE R7 style: faint and very broad. The file's axis is +x like
/// every lamp file; the lamp is aimed backwards by its mounting (yaw 180°).
///   I(H, V) = env · axis_cd · exp(−½(H/σH)² − ½(V/σV)²)
/// ≈ 0.3 cd at H = ±80°, ≈ 3.5 cd at V = ±15° (R7 field of visibility ±80° H, ±15° V);
/// total flux ≈ 5 lm.
struct TailLampParams {
  double axis_cd = 8.0;          ///< cd; intensity on the axis (R7 single lamp: 4–17 cd).
  double sigma_h_deg = 45.0;     ///< deg; horizontal σ (visible from the side up to ±80°).
  double sigma_v_deg = 12.0;     ///< deg; vertical σ.

  std::vector<GridSegment> h_grid{{-90, 90, 2.5}};
  std::vector<GridSegment> v_grid{{-90, -30, 5}, {-30, 30, 1}, {30, 90, 5}};
};
[[nodiscard]] double tailLampIntensity(const TailLampParams& p, double h_deg, double v_deg);
[[nodiscard]] TabulatedProfile makeTailLamp(const TailLampParams& p = {});

// ---------------------------------------------------------------------------------------
/// A shipped file: its name in config/lamps and its content.
struct LampFile {
  std::string file_name;
  TabulatedProfile profile;
};
/// The four shipped lamps with their default parameters, in a fixed order.
[[nodiscard]] std::vector<LampFile> shippedLamps();

}  // namespace fogbeam::lamps
