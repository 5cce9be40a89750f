// Host depth input: a host publishes distances and its camera with the C SDK; fogbeam reads
// them as a camera and a distance buffer.
#include <fogbeam/fogbeam_host.h>
#include <fogbeam/plugin/host_depth.hpp>
#include <fogbeam/render/pixel_pack.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace fogbeam::plugin {
namespace {

TEST(HostDepth, CameraAndDistancesArriveAsPublished) {
  const std::string ch = "test-depth-" + std::to_string(::getpid());
  fogbeam_depth_writer* w = nullptr;
  ASSERT_EQ(fogbeam_depth_create(ch.c_str(), 40, 20, &w), FOGBEAM_OK) << fogbeam_last_error();
  auto in = HostDepthInput::attach(ch);
  ASSERT_TRUE(in) << in.error().message;
  HostView view;
  SurfaceBuffers surf;
  EXPECT_EQ((*in)->latest(view, surf), HostDepthStatus::NoFrame);
  std::vector<float> d(40 * 20);
  for (std::size_t i = 0; i < d.size(); ++i) d[i] = 1.0f + static_cast<float>(i);
  d[0] = std::numeric_limits<float>::infinity();
  fogbeam_camera cam{};
  cam.frame = 9;
  cam.sim_time_s = 1.5;
  cam.position_m[0] = 10.0;
  cam.position_m[2] = 1.2;
  cam.yaw_deg = 90.0f;
  cam.fov_x_deg = 60.0f;
  ASSERT_EQ(fogbeam_depth_publish(w, d.data(), &cam), FOGBEAM_OK);
  ASSERT_EQ((*in)->latest(view, surf), HostDepthStatus::Ok) << (*in)->lastError();
  EXPECT_EQ(view.frame, 9u);
  EXPECT_EQ(view.camera.width, 40);
  EXPECT_NEAR(view.camera.fov_x, radians(60.0), 1e-12);
  EXPECT_EQ(view.camera.position_m.x, 10.0);
  // Yaw 90°: the camera looks along the world's +y.
  const Vec3 fwd = view.camera.worldFromCamera * Vec3(1, 0, 0);
  EXPECT_NEAR(fwd.y, 1.0, 1e-6);
  EXPECT_EQ(surf.distance, d);
  cam.fov_y_deg = 50.0f;  // not square pixels for 40x20 at 60° horizontal
  ASSERT_EQ(fogbeam_depth_publish(w, d.data(), &cam), FOGBEAM_OK);
  EXPECT_EQ((*in)->latest(view, surf), HostDepthStatus::Refused);
  EXPECT_NE((*in)->lastError().find("does not match square pixels"), std::string::npos) << (*in)->lastError();
  fogbeam_depth_destroy(w);
}

TEST(HostDepth, AnOffAxisHostViewBecomesThePrincipalPointOfItsFrustum) {
  const std::string ch = "test-depth-offaxis-" + std::to_string(::getpid());
  // A right-hand screen of a three-screen cab: 10° left, 50° right, 20° up and down, 300 px wide.
  const FrustumAngles fa{radians(10.0), radians(50.0), radians(20.0), radians(20.0)};
  const Camera expect = Camera::fromFrustum(fa, 300, 0).value();
  fogbeam_depth_writer* w = nullptr;
  ASSERT_EQ(fogbeam_depth_create(ch.c_str(), 300, static_cast<std::uint32_t>(expect.height), &w), FOGBEAM_OK);
  auto in = HostDepthInput::attach(ch);
  ASSERT_TRUE(in) << in.error().message;
  std::vector<float> d(static_cast<std::size_t>(300 * expect.height), 25.0f);
  fogbeam_camera cam{};
  cam.frame = 1;
  cam.frustum_deg[0] = 10.0f;
  cam.frustum_deg[1] = 50.0f;
  cam.frustum_deg[2] = 20.0f;
  cam.frustum_deg[3] = 20.0f;
  ASSERT_EQ(fogbeam_depth_publish(w, d.data(), &cam), FOGBEAM_OK);
  HostView view;
  SurfaceBuffers surf;
  ASSERT_EQ((*in)->latest(view, surf), HostDepthStatus::Ok) << (*in)->lastError();
  ASSERT_TRUE(view.camera.principal_px.has_value());
  EXPECT_NEAR(view.camera.principal_px->x, expect.principal_px->x, 1e-3);
  EXPECT_NEAR(view.camera.principal_px->y, expect.principal_px->y, 1e-3);
  EXPECT_NEAR(view.fov_x_deg, 60.0f, 1e-3f);
  EXPECT_EQ(view.frustum_deg[1], 50.0f);
  // A frustum whose height does not give square pixels for this channel is refused.
  cam.frame = 2;
  cam.frustum_deg[2] = 35.0f;
  ASSERT_EQ(fogbeam_depth_publish(w, d.data(), &cam), FOGBEAM_OK);
  EXPECT_EQ((*in)->latest(view, surf), HostDepthStatus::Refused);
  EXPECT_NE((*in)->lastError().find("square pixels"), std::string::npos) << (*in)->lastError();
  EXPECT_EQ(view.frame, 1u);  // the refused frame left the view alone
  fogbeam_depth_destroy(w);
}

TEST(HostDepth, ThePythonDepthWriterIsReadAsTheCSdksIs) {
  const std::string ch = "test-depth-py-" + std::to_string(::getpid());
  // The Python host publishes frame 3 (distance = 1 + column) and keeps the channel for 3 s.
  const std::string script =
      "import sys, time, numpy as np; sys.path.insert(0, sys.argv[1]); from fogbeam_reader import FogbeamDepthWriter; "
      "w = FogbeamDepthWriter(sys.argv[2], 8, 4); d = np.tile(np.arange(8, dtype=np.float32) + 1, (4, 1)); "
      "d[0, 0] = np.inf; w.publish(d, frame=3, sim_time_s=2.5, position_m=(1, 2, 3), yaw_deg=45, fov_x_deg=70); "
      "print('published', flush=True); time.sleep(3); w.close()";
  const std::string dir = std::string(FOGBEAM_PYTHON_READER).substr(0, std::string(FOGBEAM_PYTHON_READER).rfind('/'));
  const std::string cmd = std::string(FOGBEAM_PYTHON) + " -c \"" + script + "\" " + dir + " " + ch;
  FILE* p = ::popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  char line[256] = {};
  ASSERT_NE(std::fgets(line, sizeof line, p), nullptr) << cmd;
  auto in = HostDepthInput::attach(ch);
  ASSERT_TRUE(in) << in.error().message;
  HostView view;
  SurfaceBuffers surf;
  ASSERT_EQ((*in)->latest(view, surf), HostDepthStatus::Ok) << (*in)->lastError();
  EXPECT_EQ(view.frame, 3u);
  EXPECT_EQ(view.sim_time_s, 2.5);
  EXPECT_EQ(view.camera.position_m, Vec3(1, 2, 3));
  EXPECT_EQ(view.yaw_deg, 45.0f);
  EXPECT_NEAR(view.camera.fov_x, radians(70.0), 1e-6);
  EXPECT_TRUE(std::isinf(surf.distance[0]));
  EXPECT_EQ(surf.distance[1], 2.0f);
  EXPECT_EQ(surf.distance[31], 8.0f);
  EXPECT_EQ(::pclose(p), 0);
}

TEST(HostDepth, AnRgba8HostColourRoundTripsThroughFogbeamsToneCurve) {
  // Decoded at the channel's exposure and packed again by packRgba8Srgb at the same exposure,
  // every code but 255 (capped) comes back: a fog-free composite shows the host's image as it was.
  const std::string ch = "test-depth-rgba8-" + std::to_string(::getpid());
  fogbeam_depth_writer* w = nullptr;
  ASSERT_EQ(fogbeam_depth_create_colour(ch.c_str(), 64, 4, FOGBEAM_FORMAT_RGBA8_SRGB, &w), FOGBEAM_OK)
      << fogbeam_last_error();
  const double ev = 1.5;
  auto in = HostDepthInput::attach(ch, ev);
  ASSERT_TRUE(in) << in.error().message;
  EXPECT_TRUE((*in)->hasColour());
  std::vector<std::uint8_t> px(64 * 4 * 4);
  for (std::size_t i = 0; i < 64 * 4; ++i)
    for (std::size_t c = 0; c < 4; ++c) px[4 * i + c] = static_cast<std::uint8_t>((i + 85 * c) % 255);
  std::vector<float> d(64 * 4, 7.0f);
  fogbeam_camera cam{};
  cam.frame = 1;
  cam.fov_x_deg = 60.0f;
  EXPECT_EQ(fogbeam_depth_publish(w, d.data(), &cam), FOGBEAM_ERROR);  // a colour channel takes both
  ASSERT_EQ(fogbeam_depth_publish_colour(w, d.data(), px.data(), &cam), FOGBEAM_OK) << fogbeam_last_error();
  HostView view;
  SurfaceBuffers surf;
  ASSERT_EQ((*in)->latest(view, surf), HostDepthStatus::Ok) << (*in)->lastError();
  EXPECT_TRUE(view.colour);
  EXPECT_EQ(surf.distance, d);
  std::vector<std::uint8_t> back(px.size());
  packRgba8Srgb(surf.rgb.data(), 64 * 4, ev, back.data());
  for (std::size_t i = 0; i < 64 * 4; ++i)
    for (std::size_t c = 0; c < 3; ++c) ASSERT_EQ(back[4 * i + c], px[4 * i + c]) << "pixel " << i << " channel " << c;
  fogbeam_depth_destroy(w);
}

TEST(HostDepth, AFrameChannelIsNotADepthChannel) {
  const std::string ch = "test-notdepth-" + std::to_string(::getpid());
  ipc::ShmChannelOptions o;
  o.channel = ch;
  o.width = 8;
  o.height = 8;
  auto w = ipc::ShmWriter::create(o);
  ASSERT_TRUE(w);
  auto in = HostDepthInput::attach(ch);
  ASSERT_FALSE(in);
  EXPECT_NE(in.error().message.find("is not a host depth channel"), std::string::npos);
}

}  // namespace
}  // namespace fogbeam::plugin
