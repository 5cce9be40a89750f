// fogbeam — how the GL surface pass gets its EGL display and context (GlSurfacePass::create,
// gl::EglContext). Plain values, no GL or EGL type.
#pragma once

#include <string>

namespace fogbeam {

/// How the EGL display is chosen.
enum class GlPlatform {
  Auto,         ///< a hardware EGL device (EGL_EXT_platform_device) if one exists, else Mesa surfaceless, else any device
  Surfaceless,  ///< EGL_MESA_platform_surfaceless (Mesa; llvmpipe where no GPU is present)
  Device,       ///< EGL_EXT_platform_device with EGL_EXT_device_enumeration, device `device_index`
};

/// Where the surface pass lights its pixels (docs/surface_pass.md, "Shading in GL" and "Shading
/// on the CPU"). Either way the draws write a geometry buffer (normal, ρ, distance) and each
/// visible pixel is lit once.
enum class SurfaceShading {
  Auto,  ///< Cpu on a software rasteriser (llvmpipe, softpipe, swrast), else Gpu
  Gpu,   ///< a full-screen fragment shader lights the geometry buffer (surface_deferred.frag)
  Cpu,   ///< SIMD threads light the geometry buffer after its readback (SurfaceShader)
};

struct GlOptions {
  GlPlatform platform = GlPlatform::Auto;
  SurfaceShading shading = SurfaceShading::Auto;
  unsigned shading_threads = 0;  ///< threads lighting the geometry buffer (Cpu shading); 0: every core
  int device_index = 0;     ///< Device only: index into eglQueryDevicesEXT's list
  bool debug_context = false;  ///< request a debug context and log GL debug messages to stderr
  /// Where the fog light's table and annulus maps are kept between runs (SurfaceShader::setTableCacheDir;
  /// the view tables' cache directory, tableCacheDirFor); empty: built in every run.
  std::string table_cache_dir;
};

}  // namespace fogbeam
