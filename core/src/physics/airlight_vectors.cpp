#include <fogbeam/physics/airlight_vectors.hpp>
#include <fogbeam/util/files.hpp>

#include <charconv>
#include <cmath>
#include <map>

namespace fogbeam {

namespace {

std::vector<std::string_view> splitCsv(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    std::string_view cell = line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start);
    while (!cell.empty() && (cell.front() == ' ' || cell.front() == '\t')) cell.remove_prefix(1);
    while (!cell.empty() && (cell.back() == ' ' || cell.back() == '\t' || cell.back() == '\r')) cell.remove_suffix(1);
    out.push_back(cell);
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return out;
}

bool parseNumber(std::string_view s, double& out) {
  if (s == "inf" || s == "Inf" || s == "+inf") {
    out = HUGE_VAL;
    return true;
  }
  const char* end = s.data() + s.size();
  auto [ptr, ec] = std::from_chars(s.data(), end, out);
  return ec == std::errc() && ptr == end;
}

}  // namespace

Result<Lamp> AirlightVector::lamp() const {
  Profile::Model model = IsotropicProfile{intensity_cd};
  if (profile == "spot") {
    model = SpotProfile{intensity_cd, radians(inner_deg), radians(outer_deg)};
  } else if (profile != "isotropic") {
    return Error{"line " + std::to_string(line) + ": unknown profile '" + profile + "'"};
  }
  auto p = makeProfile(std::move(model));
  if (!p) return Error{"line " + std::to_string(line) + ": " + p.error().message};
  Lamp l;
  l.position_m = lamp_m;
  l.worldFromLamp = worldFromAxis(axis);
  l.profile = std::move(p).value();
  return l;
}

Result<Medium> AirlightVector::medium() const {
  Medium m;
  m.extinction_per_m = extinction_per_m;
  m.albedo = albedo;
  if (phase == "hg") {
    auto ph = makeHenyeyGreenstein(g);
    if (!ph) return Error{"line " + std::to_string(line) + ": " + ph.error().message};
    m.phase = ph.value();
  } else if (phase != "isotropic") {
    return Error{"line " + std::to_string(line) + ": unknown phase '" + phase + "'"};
  }
  if (Status s = m.validate(); !s) return Error{"line " + std::to_string(line) + ": " + s.error().message};
  return m;
}

Result<std::vector<AirlightVector>> parseAirlightVectors(std::string_view text, const std::string& name) {
  static const char* kNumeric[] = {"eye_x", "eye_y", "eye_z", "dir_x", "dir_y", "dir_z", "depth_m", "lamp_x",
                                   "lamp_y", "lamp_z", "axis_x", "axis_y", "axis_z", "intensity_cd", "inner_deg",
                                   "outer_deg", "extinction_per_m", "albedo", "g", "airlight_cd_m2"};
  std::vector<AirlightVector> rows;
  std::map<std::string, std::size_t, std::less<>> col;
  std::size_t lineNo = 0, pos = 0;
  while (pos < text.size()) {
    const std::size_t nl = text.find('\n', pos);
    std::string_view line = text.substr(pos, nl == std::string_view::npos ? std::string_view::npos : nl - pos);
    pos = nl == std::string_view::npos ? text.size() : nl + 1;
    ++lineNo;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.empty() || line.front() == '#') continue;
    const auto cells = splitCsv(line);
    if (col.empty()) {
      for (std::size_t i = 0; i < cells.size(); ++i) col[std::string(cells[i])] = i;
      for (const char* c : kNumeric)
        if (!col.count(c)) return fileError(name, lineNo, std::string("header lacks column '") + c + "'");
      for (const char* c : {"profile", "phase"})
        if (!col.count(c)) return fileError(name, lineNo, std::string("header lacks column '") + c + "'");
      continue;
    }
    if (cells.size() < col.size()) {
      return fileError(name, lineNo, "expected " + std::to_string(col.size()) + " cells, found " + std::to_string(cells.size()));
    }
    std::map<std::string_view, double> v;
    for (const char* c : kNumeric) {
      double x = 0.0;
      const std::string_view cell = cells[col.find(c)->second];
      if (!parseNumber(cell, x)) return fileError(name, lineNo, std::string("column ") + c + ": expected a number, found '" + std::string(cell) + "'");
      v[c] = x;
    }
    AirlightVector r;
    r.line = lineNo;
    r.ray.origin = Vec3(v["eye_x"], v["eye_y"], v["eye_z"]);
    const Vec3 d(v["dir_x"], v["dir_y"], v["dir_z"]);
    if (!(glm::length(d) > 0.0)) return fileError(name, lineNo, "dir is zero");
    r.ray.direction = glm::normalize(d);
    r.ray.distance_m = v["depth_m"];
    if (!(r.ray.distance_m >= 0.0)) return fileError(name, lineNo, "depth_m: expected >= 0 or inf");
    r.lamp_m = Vec3(v["lamp_x"], v["lamp_y"], v["lamp_z"]);
    r.axis = Vec3(v["axis_x"], v["axis_y"], v["axis_z"]);
    if (!(glm::length(r.axis) > 0.0)) return fileError(name, lineNo, "axis is zero");
    r.profile = std::string(cells[col.find("profile")->second]);
    r.intensity_cd = v["intensity_cd"];
    r.inner_deg = v["inner_deg"];
    r.outer_deg = v["outer_deg"];
    r.extinction_per_m = v["extinction_per_m"];
    r.albedo = v["albedo"];
    r.phase = std::string(cells[col.find("phase")->second]);
    r.g = v["g"];
    r.expected_cd_m2 = v["airlight_cd_m2"];
    rows.push_back(std::move(r));
  }
  if (col.empty()) return fileError(name, 0, "empty file: expected a header line");
  return rows;
}

Result<std::vector<AirlightVector>> loadAirlightVectors(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return text.error();
  return parseAirlightVectors(text.value(), path);
}

}  // namespace fogbeam
