#include <fogbeam/physics/validation.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>
#include <set>

namespace fogbeam {

Result<std::vector<ValidationCase>> casesFromVectors(const std::vector<AirlightVector>& rows) {
  std::vector<ValidationCase> out;
  out.reserve(rows.size());
  for (const auto& r : rows) {
    auto lamp = r.lamp();
    if (!lamp) return lamp.error();
    auto medium = r.medium();
    if (!medium) return medium.error();
    ValidationCase c;
    c.label = "line " + std::to_string(r.line) + " " + r.profile + "/" + r.phase + " g=" + std::to_string(r.g);
    c.lamp = std::move(lamp).value();
    c.medium = std::move(medium).value();
    c.ray = r.ray;
    c.expected_cd_m2 = r.expected_cd_m2;
    out.push_back(std::move(c));
  }
  return out;
}

std::vector<ValidationCase> builtinSweep(const std::shared_ptr<const Profile>& headlamp, int raysPerSituation,
                                         std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  auto spot = makeProfile(SpotProfile{20000.0, radians(4.0), radians(14.0)}).value();

  struct Fog {
    std::string name;
    Phase phase;
  };
  std::vector<Fog> fogs;
  for (double g : {0.0, 0.3, 0.6, 0.8, 0.85, 0.9}) {
    if (g == 0.0) fogs.push_back({"isotropic", IsotropicPhase{}});
    else fogs.push_back({"hg" + std::to_string(g).substr(0, 4), makeHenyeyGreenstein(g).value()});
  }
  fogs.push_back({"fog-mie10um", makeFogMie(10.0).value()});

  struct Profiles {
    std::string name;
    std::shared_ptr<const Profile> profile;
  };
  std::vector<Profiles> profiles{{"spot", spot}};
  if (headlamp) profiles.push_back({"headlamp", headlamp});

  const Vec3 eye(0.0, 0.35, 1.2);  // driver's eye, right-hand traffic (x forward, y left, z up)
  std::vector<ValidationCase> cases;
  for (const auto& fog : fogs) {
    for (const auto& prof : profiles) {
      for (int situation = 0; situation < 4; ++situation) {
        // Visibility (MOR) 30–300 m, log-uniform.
        const double vis = 30.0 * std::pow(10.0, uni(rng));
        Medium m;
        m.extinction_per_m = extinctionFromVisibility(vis);
        m.albedo = 0.95;
        m.phase = fog.phase;
        Lamp lamp;
        lamp.profile = prof.profile;
        std::string where;
        if (situation == 0) {  // own right low beam, aimed 0.57° down (1 % inclination)
          where = "own-beam";
          lamp.position_m = Vec3(2.0, -0.7, 0.65);
          lamp.worldFromLamp = worldFromYawPitchRoll(0.0, radians(0.57), 0.0);
        } else {  // oncoming car in the other lane, near (15–40 m) or far (40–150 m)
          const double dist = situation == 1 ? 15.0 + 25.0 * uni(rng) : 40.0 + 110.0 * uni(rng);
          where = situation == 1 ? "oncoming-near" : "oncoming-far";
          if (situation == 3) where = "oncoming-far-side";
          lamp.position_m = Vec3(dist, 3.5 + (situation == 3 ? 0.7 : -0.7), 0.65);
          lamp.worldFromLamp = worldFromYawPitchRoll(kPi, radians(0.57), 0.0);
        }
        for (int i = 0; i < raysPerSituation; ++i) {
          Vec3 dir;
          if (situation > 0 && i % 2 == 0) {
            // Within 0.2–8° of the oncoming lamp: the halo where forward scattering dominates.
            const Vec3 toLamp = glm::normalize(lamp.position_m - eye);
            const double off = radians(0.2 + 7.8 * uni(rng) * uni(rng)), az = 2.0 * kPi * uni(rng);
            const Mat3 f = worldFromAxis(toLamp);
            dir = glm::normalize(std::cos(off) * f[0] + std::sin(off) * (std::cos(az) * f[1] + std::sin(az) * f[2]));
          } else {
            const double yaw = radians(-30.0 + 60.0 * uni(rng)), pitch = radians(-15.0 + 25.0 * uni(rng));
            dir = Vec3(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw), std::sin(pitch));
          }
          double depth = HUGE_VAL;
          if (dir.z < 0.0) depth = std::min(eye.z / -dir.z, 400.0);  // road plane z = 0
          ValidationCase c;
          c.label = where + "/" + prof.name + "/" + fog.name + "/V" + std::to_string(static_cast<int>(vis)) + "m";
          c.lamp = lamp;
          c.medium = m;
          c.ray = Ray{eye, dir, depth};
          cases.push_back(std::move(c));
        }
      }
    }
  }
  // Expected values from the reference method.
  for (auto& c : cases) {
    auto ev = AirlightEvaluator::build(c.lamp, c.medium, AirlightMethod::Reference);
    c.expected_cd_m2 = ev ? ev->evaluate(c.ray) : 0.0;
  }
  return cases;
}

namespace {
double percentile(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return 0.0;
  const auto i = static_cast<std::size_t>(std::ceil(q * static_cast<double>(sorted.size())));
  return sorted[std::min(i == 0 ? 0 : i - 1, sorted.size() - 1)];
}
}  // namespace

Result<ValidationResult> runValidation(const std::vector<ValidationCase>& cases,
                                       const std::vector<AirlightMethod>& methods, const AirlightOptions& options) {
  ValidationResult res;
  for (AirlightMethod method : methods) {
    MethodSummary s;
    s.method = method;
    // Build all evaluators first so that timing covers evaluate() only.
    std::vector<AirlightEvaluator> evs;
    evs.reserve(cases.size());
    std::set<const void*> seenTables;
    for (const auto& c : cases) {
      auto ev = AirlightEvaluator::build(c.lamp, c.medium, method, options);
      if (!ev) return ev.error();
      s.buildSeconds += ev->stats().build_seconds;
      if (ev->stats().build_seconds > 0.0) s.tableBytes += ev->stats().bytes;
      evs.push_back(std::move(ev).value());
    }
    std::vector<double> values(cases.size());
    // Repeat cheap methods so that the timing is not dominated by clock resolution.
    const int reps = method == AirlightMethod::Reference ? 1 : 5;
    const auto t0 = std::chrono::steady_clock::now();
    for (int r = 0; r < reps; ++r)
      for (std::size_t i = 0; i < cases.size(); ++i) values[i] = evs[i].evaluate(cases[i].ray);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    s.nsPerEval = cases.empty() ? 0.0 : secs * 1e9 / (static_cast<double>(cases.size()) * reps);

    std::vector<double> rel;
    double worst = -1.0;
    for (std::size_t i = 0; i < cases.size(); ++i) {
      const double e = cases[i].expected_cd_m2, v = values[i];
      double err;
      if (e > kZeroThreshold) {
        err = std::abs(v - e) / e;
        rel.push_back(err);
        if (err > worst) {
          worst = err;
          s.worstLabel = cases[i].label;
        }
      } else {
        err = std::abs(v);
        ++s.zeroRows;
        if (err > kZeroThreshold) ++s.zeroViolations;
      }
      res.rows.push_back({method, i, v, e, err});
    }
    std::sort(rel.begin(), rel.end());
    s.rows = rel.size();
    s.median = percentile(rel, 0.5);
    s.p95 = percentile(rel, 0.95);
    s.max = rel.empty() ? 0.0 : rel.back();
    res.summaries.push_back(s);
  }
  return res;
}

bool accurateWithinBounds(const MethodSummary& s) {
  return s.p95 <= kAccurateP95Bound && s.max <= kAccurateMaxBound && s.zeroViolations == 0;
}

}  // namespace fogbeam
