// fogbeam — how the GL surface pass gets its EGL display and context (GlSurfacePass::create,
// gl::EglContext). Plain values, no GL or EGL type.
#pragma once

namespace fogbeam {

/// How the EGL display is chosen.
enum class GlPlatform {
  Auto,         ///< a hardware EGL device (EGL_EXT_platform_device) if one exists, else Mesa surfaceless, else any device
  Surfaceless,  ///< EGL_MESA_platform_surfaceless (Mesa; llvmpipe where no GPU is present)
  Device,       ///< EGL_EXT_platform_device with EGL_EXT_device_enumeration, device `device_index`
};

struct GlOptions {
  GlPlatform platform = GlPlatform::Auto;
  int device_index = 0;     ///< Device only: index into eglQueryDevicesEXT's list
  bool debug_context = false;  ///< request a debug context and log GL debug messages to stderr
};

}  // namespace fogbeam
