// fogbeam — OpenEXR output of a frame's layers (32-bit float, linear), named as
// `fogbeam render` documents: R,G,B (composite), airlight.R/G/B, surface.R/G/B,
// overlay.R/G/B, transmittance.Y, distance.Z (metres, +inf for sky).
#pragma once

#include <fogbeam/render/frame.hpp>
#include <fogbeam/util/result.hpp>

#include <string>

namespace fogbeam::exr {

[[nodiscard]] Status writeFrameLayers(const FrameLayers& layers, const std::string& path);

}  // namespace fogbeam::exr
