// Host depth input: a host publishes distances and its camera with the C SDK; fogbeam reads
// them as a camera and a distance buffer.
#include <fogbeam/fogbeam_host.h>
#include <fogbeam/plugin/host_depth.hpp>

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
  EXPECT_EQ((*in)->latest(view, surf), ipc::ReadStatus::NoFrame);
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
  ASSERT_EQ((*in)->latest(view, surf), ipc::ReadStatus::Ok) << (*in)->lastError();
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
  EXPECT_EQ((*in)->latest(view, surf), ipc::ReadStatus::WriterGone);
  EXPECT_NE((*in)->lastError().find("does not match square pixels"), std::string::npos) << (*in)->lastError();
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
