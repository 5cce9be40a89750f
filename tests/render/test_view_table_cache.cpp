// The vehicle lamps' view tables on disk (FastPathOptions::table_cache_dir): a second evaluator
// with the same lamps, view and fog loads them and renders the same bytes; anything else it
// depends on, a damaged file or another key is a miss, never a wrong table. The fog light's
// annulus maps (AnnulusMeanMap::build's cacheDir) share the directory and its checks.
#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/fog_light.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include "view_table_cache.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace fogbeam {
namespace {

namespace fs = std::filesystem;

struct TempDir {
  fs::path path;
  TempDir() : path(fs::temp_directory_path() / ("fogbeam_table_cache_" + std::to_string(::getpid()))) {
    fs::remove_all(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

Scene egoScene(double visibility) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(visibility);
  s.fog.albedo = 0.95;
  s.fog.phase = makeHenyeyGreenstein(0.85).value();
  s.camera.position_m = {0.0, 0.35, 1.2};
  s.camera.width = 96;
  s.camera.height = 54;
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  EXPECT_TRUE(low.has_value());
  for (double y : {0.7, -0.7}) {
    Lamp l;
    l.position_m = {2.0, y, 0.65};
    l.worldFromLamp = worldFromYawPitchRoll(0.0, radians(0.57), 0.0);
    l.profile = *low;
    s.lamps.push_back({"ego", l, LampMount::Vehicle});
  }
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  return s;
}

FastPathOptions cached(const std::string& cacheDir) {
  FastPathOptions f;
  f.view_table_step_deg = 1.0;  // the cache's behaviour, not the tables' accuracy
  f.view_table_distances = 16;
  f.table_cache_dir = cacheDir;
  return f;
}

AirlightImage frame(const Scene& scene, const std::string& cacheDir) {
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 2, cached(cacheDir));
  EXPECT_TRUE(ev.has_value());
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  AirlightImage img;
  ev->evaluate(scene, surf, SubsamplingOptions{}, img);
  EXPECT_TRUE(img.table_cache_error.empty()) << img.table_cache_error;
  return img;
}

std::vector<fs::path> cacheFiles(const fs::path& dir) {
  std::vector<fs::path> out;
  if (!fs::exists(dir)) return out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path());
  return out;
}

TEST(ViewTableCache, ASecondStartLoadsTheTablesAndRendersTheSameBytes) {
  TempDir dir;
  const Scene scene = egoScene(80.0);
  const AirlightImage built = frame(scene, dir.path.string());
  EXPECT_EQ(built.view_tables_loaded, 0u);
  EXPECT_EQ(cacheFiles(dir.path).size(), 2u);  // one file per lamp
  const AirlightImage loaded = frame(scene, dir.path.string());
  EXPECT_EQ(loaded.view_tables_loaded, 2u);
  EXPECT_EQ(loaded.rgb, built.rgb);
  const AirlightImage none = frame(scene, "");
  EXPECT_EQ(none.view_tables_loaded, 0u);
  EXPECT_EQ(none.rgb, built.rgb);
  std::printf("view tables: built in %.1f ms, loaded in %.1f ms\n", 1e3 * built.table_seconds, 1e3 * loaded.table_seconds);
}

TEST(ViewTableCache, AnotherFogOrRigIsAMiss) {
  TempDir dir;
  const Scene scene = egoScene(80.0);
  (void)frame(scene, dir.path.string());
  EXPECT_EQ(frame(egoScene(120.0), dir.path.string()).view_tables_loaded, 0u);
  Scene moved = scene;
  moved.lamps[0].lamp.position_m.z += 0.01;  // one lamp 1 cm higher: its own tables only
  EXPECT_EQ(frame(moved, dir.path.string()).view_tables_loaded, 1u);
  Scene phase = scene;
  phase.fog.phase = makeHenyeyGreenstein(0.8).value();
  EXPECT_EQ(frame(phase, dir.path.string()).view_tables_loaded, 0u);
  EXPECT_EQ(cacheFiles(dir.path).size(), 2u + 2u + 1u + 2u);
}

TEST(ViewTableCache, ADamagedFileIsAMissAndIsWrittenAgain) {
  TempDir dir;
  const Scene scene = egoScene(80.0);
  const AirlightImage built = frame(scene, dir.path.string());
  for (const fs::path& f : cacheFiles(dir.path)) {
    // Flip one byte in the middle of the data: the checksum refuses the file.
    std::fstream io(f, std::ios::in | std::ios::out | std::ios::binary);
    io.seekg(static_cast<std::streamoff>(fs::file_size(f) / 2));
    char c = 0;
    io.read(&c, 1);
    io.seekp(static_cast<std::streamoff>(fs::file_size(f) / 2));
    c = static_cast<char>(c ^ 0x5a);
    io.write(&c, 1);
  }
  const fs::path truncated = cacheFiles(dir.path).front();
  fs::resize_file(truncated, fs::file_size(truncated) / 3);
  const AirlightImage again = frame(scene, dir.path.string());
  EXPECT_EQ(again.view_tables_loaded, 0u);
  EXPECT_EQ(again.rgb, built.rgb);
  // Written again: the next start loads.
  EXPECT_EQ(frame(scene, dir.path.string()).view_tables_loaded, 2u);
}

TEST(ViewTableCache, AnUnwritableDirectoryIsReportedAndTheFrameIsRendered) {
  TempDir dir;
  fs::create_directories(dir.path);
  const fs::path blocker = dir.path / "file";
  std::ofstream(blocker) << "not a directory";
  const Scene scene = egoScene(80.0);
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 2, cached((blocker / "cache").string()));
  ASSERT_TRUE(ev.has_value());
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  AirlightImage img;
  ev->evaluate(scene, surf, SubsamplingOptions{}, img);
  EXPECT_NE(img.table_cache_error.find("cannot create the table cache directory"), std::string::npos)
      << img.table_cache_error;
  EXPECT_EQ(img.rgb, frame(scene, "").rgb);
}

TEST(ViewTableCache, TheOldestFilesGoWhenTheDirectoryIsFull) {
  TempDir dir;
  fs::create_directories(dir.path);
  std::vector<fs::path> files;
  const char* kinds[] = {"vt", "am", "fl", "vt", "am"};  // all three kinds count
  for (int i = 0; i < 5; ++i) {
    files.push_back(dir.path / (std::string(kinds[i]) + "-" + std::to_string(i) + ".bin"));
    std::ofstream(files.back()) << std::string(1000, 'x');
    fs::last_write_time(files.back(), fs::file_time_type::clock::now() - std::chrono::hours(5 - i));
  }
  std::ofstream(dir.path / "unrelated.txt") << std::string(5000, 'y');  // not a cache file: kept
  std::ofstream(dir.path / "xx-9.bin") << std::string(5000, 'z');      // another prefix: kept
  detail::evictOldest(dir.path, files[0], 2500);
  EXPECT_TRUE(fs::exists(files[0]));   // the one just written, however old
  EXPECT_FALSE(fs::exists(files[1]));  // the oldest others
  EXPECT_FALSE(fs::exists(files[2]));
  EXPECT_FALSE(fs::exists(files[3]));
  EXPECT_TRUE(fs::exists(files[4]));
  EXPECT_TRUE(fs::exists(dir.path / "unrelated.txt"));
  EXPECT_TRUE(fs::exists(dir.path / "xx-9.bin"));
}

TEST(ViewTableCache, AStoreOfAKindEvictionWouldNotCountIsRefused) {
  TempDir dir;
  detail::TableKey key;
  key.add(1.0);
  const Status st = detail::storeBytes(dir.path, "xx", key, "payload");
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().message.find("'xx'"), std::string::npos) << st.error().message;
  EXPECT_FALSE(fs::exists(dir.path));  // nothing written
  ASSERT_TRUE(detail::storeBytes(dir.path, "fl", key, "payload"));
  std::string back;
  ASSERT_TRUE(detail::loadBytes(dir.path, "fl", key, back));
  EXPECT_EQ(back, "payload");
  std::vector<float> floats{1.0f};
  EXPECT_FALSE(detail::loadFloats(dir.path, "fl", key, floats));  // 7 bytes: not floats
  EXPECT_EQ(floats, std::vector<float>{1.0f});                     // untouched
}

// The files of one kind ("vt", "am") in `dir`.
std::vector<fs::path> cacheFiles(const fs::path& dir, const std::string& kind) {
  std::vector<fs::path> out;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().filename().string().rfind(kind + "-", 0) == 0) out.push_back(it->path());
  return out;
}

TEST(FogLightMapCache, ASecondBuildLoadsTheSameMapAndAnotherKeyOrADamagedFileIsAMiss) {
  TempDir dir;
  const auto ms = shippedMultipleScatteringTable(makeHenyeyGreenstein(0.85).value());
  ASSERT_NE(ms, nullptr);
  const std::vector<double>& edges = ms->emissionEdges();
  const auto beam = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies").value();
  ThreadPool pool(2);
  std::string error;
  const auto built = AnnulusMeanMap::build(beam, edges, false, &pool, dir.path.string(), &error);
  EXPECT_FALSE(built->fromCache());
  EXPECT_TRUE(error.empty()) << error;
  const auto files = cacheFiles(dir.path, "am");
  ASSERT_EQ(files.size(), 1u);

  // The same profile data (another load of the file: another object), edges and flag: loaded,
  // every float as built.
  const auto again = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies").value();
  const auto loaded = AnnulusMeanMap::build(again, edges, false, &pool, dir.path.string(), &error);
  EXPECT_TRUE(loaded->fromCache());
  EXPECT_EQ(loaded->rows(), built->rows());
  EXPECT_EQ(loaded->columns(), built->columns());
  EXPECT_EQ(loaded->bins(), built->bins());
  EXPECT_TRUE(loaded->values() == built->values());

  // The driver's own lamp (front only) is another key: a miss, built and stored beside (a low
  // beam sends nothing backwards, so its floats are the same here).
  const auto front = AnnulusMeanMap::build(beam, edges, true, &pool, dir.path.string(), &error);
  EXPECT_FALSE(front->fromCache());
  EXPECT_EQ(cacheFiles(dir.path, "am").size(), 2u);

  // One byte of the stored floats changed: the checksum fails, the map is built again (the
  // same floats) and stored again.
  {
    std::fstream f(files[0], std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(static_cast<std::streamoff>(fs::file_size(files[0]) / 2));
    f.put('\x5a');
  }
  const auto rebuilt = AnnulusMeanMap::build(beam, edges, false, &pool, dir.path.string(), &error);
  EXPECT_FALSE(rebuilt->fromCache());
  EXPECT_TRUE(rebuilt->values() == built->values());
  EXPECT_TRUE(AnnulusMeanMap::build(beam, edges, false, &pool, dir.path.string(), &error)->fromCache());
  EXPECT_TRUE(error.empty()) << error;
}

TEST(FogLightMapCache, AnUnwritableDirectoryIsReportedAndTheMapIsBuilt) {
  TempDir dir;
  fs::create_directories(dir.path);
  const fs::path file = dir.path / "a-file";
  std::ofstream(file) << "not a directory";
  const auto iso = makeProfile(IsotropicProfile{250.0}).value();
  const std::vector<double> edges{0.0, kPi / 3.0, 2.0 * kPi / 3.0, kPi};
  ThreadPool pool(2);
  std::string error;
  const auto map = AnnulusMeanMap::build(iso, edges, false, &pool, (file / "cache").string(), &error);
  ASSERT_NE(map, nullptr);
  EXPECT_FALSE(map->fromCache());
  EXPECT_NE(error.find("cannot create the table cache directory"), std::string::npos) << error;
  double means[3];
  map->lookup(glm::normalize(Vec3(0.2, 0.5, -0.7)), means);
  for (double m : means) EXPECT_NEAR(m, 250.0, 1e-3);
}

TEST(FogLightTableCache, AStoredTableLoadsAsBuiltAndAnotherAlbedoOrADamagedFileIsAMiss) {
  TempDir dir;
  const Phase phase = makeHenyeyGreenstein(0.85).value();
  ThreadPool pool(2);
  EXPECT_EQ(FogLightTable::loadShipped(phase, 0.95, dir.path.string()), nullptr);  // nothing stored yet
  std::string error;
  const auto built = FogLightTable::shipped(phase, 0.95, &pool, dir.path.string(), &error);
  ASSERT_TRUE(built.has_value()) << built.error().message;
  EXPECT_TRUE(error.empty()) << error;
  const auto files = cacheFiles(dir.path, "fl");
  ASSERT_EQ(files.size(), 1u);
  const auto loaded = FogLightTable::loadShipped(phase, 0.95, dir.path.string());
  ASSERT_NE(loaded, nullptr);
  const FogLightTable& a = **built;
  EXPECT_EQ(loaded->edges(), a.edges());
  EXPECT_EQ(loaded->opticalDistances(), a.opticalDistances());
  EXPECT_EQ(loaded->albedo(), a.albedo());
  EXPECT_TRUE(loaded->dense() == a.dense());
  EXPECT_TRUE(loaded->denseSums() == a.denseSums());
  // What the frames read agrees to the bit, and what the build nodes give too.
  const std::vector<float> means(a.bins(), 100.0f), dip(3 * a.bins(), 10.0f);
  for (double T : {0.004, 0.3, 1.7, 12.0}) {
    float x[FogLightTable::kLampFloats], y[FogLightTable::kLampFloats];
    a.weighted(T, means.data(), dip.data(), 1.0f, x);
    loaded->weighted(T, means.data(), dip.data(), 1.0f, y);
    for (std::size_t q = 0; q < FogLightTable::kLampFloats; ++q) EXPECT_EQ(x[q], y[q]) << T;
    std::vector<double> dm(a.bins(), 100.0);
    EXPECT_EQ(a.irradiance(T, 0.4, dm.data()), loaded->irradiance(T, 0.4, dm.data())) << T;
  }
  EXPECT_EQ(FogLightTable::loadShipped(phase, 0.9, dir.path.string()), nullptr);                          // another albedo
  EXPECT_EQ(FogLightTable::loadShipped(makeHenyeyGreenstein(0.8).value(), 0.95, dir.path.string()), nullptr);  // phase
  {
    std::fstream f(files[0], std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(static_cast<std::streamoff>(fs::file_size(files[0]) / 2));
    f.put('\x5a');
  }
  EXPECT_EQ(FogLightTable::loadShipped(phase, 0.95, dir.path.string()), nullptr);  // damaged: a miss
}

TEST(ViewTableCache, SettingsNameTheDirectory) {
  EXPECT_EQ(tableCacheDirFor("off"), "");
  EXPECT_EQ(tableCacheDirFor("/var/cache/fb"), "/var/cache/fb");
  EXPECT_EQ(tableCacheDirFor("auto"), defaultTableCacheDir());
}

}  // namespace
}  // namespace fogbeam
