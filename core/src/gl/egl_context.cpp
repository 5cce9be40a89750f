// fogbeam — headless EGL: device platform (NVIDIA and other GPUs) or Mesa surfaceless.
#include "egl_context.hpp"

#include "gl_errors.hpp"

#include <dlfcn.h>

#include <cstring>
#include <map>
#include <mutex>
#include <vector>

namespace fogbeam::gl {

namespace {

bool hasExtension(const char* list, const char* name) {
  if (list == nullptr) return false;
  const std::size_t n = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += n) {
    const bool startOk = p == list || p[-1] == ' ';
    const bool endOk = p[n] == '\0' || p[n] == ' ';
    if (startOk && endOk) return true;
  }
  return false;
}

// eglTerminate() ends a display for the whole process; count the contexts per display so that
// the last one terminates it.
std::mutex gDisplayMutex;
std::map<EGLDisplay, int> gDisplayUsers;

struct Candidate {
  EGLDisplay display;
  std::string name;
};

// Checks once per process that libEGL can be loaded: libepoxy aborts the process when it cannot
// find libEGL, so this must run before the first EGL call.
Status eglLibraryAvailable() {
  for (const char* lib : {"libEGL.so.1", "libEGL.so"}) {
    if (void* h = dlopen(lib, RTLD_LAZY | RTLD_LOCAL)) {
      dlclose(h);
      return Ok{};
    }
  }
  const char* why = dlerror();
  return Error{std::string("no EGL available: cannot load libEGL.so.1 (") + (why ? why : "not found") +
               "); install an EGL implementation (Mesa libegl1, or the NVIDIA driver)"};
}

std::vector<EGLDeviceEXT> queryDevices(const char* clientExt) {
  std::vector<EGLDeviceEXT> devices;
  if (!hasExtension(clientExt, "EGL_EXT_device_enumeration") && !hasExtension(clientExt, "EGL_EXT_device_base"))
    return devices;
  EGLint n = 0;
  if (!eglQueryDevicesEXT(0, nullptr, &n) || n <= 0) return devices;
  devices.resize(static_cast<std::size_t>(n));
  if (!eglQueryDevicesEXT(n, devices.data(), &n)) return {};
  devices.resize(static_cast<std::size_t>(n));
  return devices;
}

bool isHardwareDevice(EGLDeviceEXT dev) {
  const char* ext = eglQueryDeviceStringEXT(dev, EGL_EXTENSIONS);
  if (hasExtension(ext, "EGL_MESA_device_software")) return false;
  return hasExtension(ext, "EGL_NV_device_cuda") || hasExtension(ext, "EGL_EXT_device_drm");
}

Result<std::vector<Candidate>> candidates(const GlOptions& o) {
  const char* clientExt = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  const bool platformBase = hasExtension(clientExt, "EGL_EXT_platform_base");
  const bool devicePlatform = platformBase && hasExtension(clientExt, "EGL_EXT_platform_device");
  const bool surfaceless = platformBase && hasExtension(clientExt, "EGL_MESA_platform_surfaceless");
  std::vector<Candidate> out;
  auto deviceDisplay = [&](EGLDeviceEXT dev, int index) {
    EGLDisplay d = eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, dev, nullptr);
    if (d != EGL_NO_DISPLAY) out.push_back({d, "device " + std::to_string(index)});
  };
  auto surfacelessDisplay = [&] {
    EGLDisplay d = eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (d != EGL_NO_DISPLAY) out.push_back({d, "surfaceless"});
  };
  switch (o.platform) {
    case GlPlatform::Surfaceless:
      if (!surfaceless) return Error{"EGL platform 'surfaceless' requested but EGL_MESA_platform_surfaceless is not supported"};
      surfacelessDisplay();
      if (out.empty()) return Error{eglFailure("eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA)")};
      break;
    case GlPlatform::Device: {
      if (!devicePlatform) return Error{"EGL platform 'device' requested but EGL_EXT_platform_device is not supported"};
      const auto devices = queryDevices(clientExt);
      if (o.device_index < 0 || static_cast<std::size_t>(o.device_index) >= devices.size())
        return Error{"EGL device " + std::to_string(o.device_index) + " requested but " + std::to_string(devices.size()) +
                     " device(s) found"};
      deviceDisplay(devices[static_cast<std::size_t>(o.device_index)], o.device_index);
      if (out.empty()) return Error{eglFailure("eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT)")};
      break;
    }
    case GlPlatform::Auto: {
      const auto devices = devicePlatform ? queryDevices(clientExt) : std::vector<EGLDeviceEXT>{};
      for (std::size_t i = 0; i < devices.size(); ++i)
        if (isHardwareDevice(devices[i])) deviceDisplay(devices[i], static_cast<int>(i));
      if (surfaceless) surfacelessDisplay();
      for (std::size_t i = 0; i < devices.size(); ++i)
        if (!isHardwareDevice(devices[i])) deviceDisplay(devices[i], static_cast<int>(i));
      if (out.empty()) {
        EGLDisplay d = eglGetDisplay(EGL_DEFAULT_DISPLAY);
        if (d != EGL_NO_DISPLAY) out.push_back({d, "default"});
      }
      if (out.empty())
        return Error{"no EGL available: no EGL device, no surfaceless platform and no default display (" +
                     eglErrorName(eglGetError()) + ")"};
      break;
    }
  }
  return out;
}

}  // namespace

Result<std::unique_ptr<EglContext>> EglContext::create(const GlOptions& o) {
  if (Status s = eglLibraryAvailable(); !s) return s.error();
  auto found = candidates(o);
  if (!found) return found.error();

  std::string failures;
  for (const Candidate& c : *found) {
    std::unique_ptr<EglContext> ctx(new EglContext());
    EGLint major = 0, minor = 0;
    if (!eglInitialize(c.display, &major, &minor)) {
      failures += "\n  " + c.name + ": " + eglFailure("eglInitialize");
      continue;
    }
    {
      std::lock_guard lock(gDisplayMutex);
      ++gDisplayUsers[c.display];
    }
    ctx->display_ = c.display;  // from here the destructor releases the display
    ctx->platform_ = c.name;
    if (!eglBindAPI(EGL_OPENGL_API)) {
      failures += "\n  " + c.name + ": " + eglFailure("eglBindAPI(EGL_OPENGL_API)");
      continue;
    }
    const char* dispExt = eglQueryString(c.display, EGL_EXTENSIONS);
    const bool surfacelessCtx = hasExtension(dispExt, "EGL_KHR_surfaceless_context");
    const EGLint configAttribs[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT,
                                    EGL_RED_SIZE, 8, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint nConfigs = 0;
    if (!eglChooseConfig(c.display, configAttribs, &config, 1, &nConfigs) || nConfigs < 1) {
      // Surfaceless displays may offer configs without pbuffer support; the FBO needs none.
      const EGLint anySurface[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
      if (!eglChooseConfig(c.display, anySurface, &config, 1, &nConfigs) || nConfigs < 1) {
        failures += "\n  " + c.name + ": no EGLConfig with EGL_OPENGL_BIT (" + eglErrorName(eglGetError()) + ")";
        continue;
      }
    }
    for (const EGLint minorVersion : {5, 3}) {
      const EGLint ctxAttribs[] = {EGL_CONTEXT_MAJOR_VERSION, 4,
                                   EGL_CONTEXT_MINOR_VERSION, minorVersion,
                                   EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                   EGL_CONTEXT_OPENGL_DEBUG, o.debug_context ? EGL_TRUE : EGL_FALSE,
                                   EGL_NONE};
      ctx->context_ = eglCreateContext(c.display, config, EGL_NO_CONTEXT, ctxAttribs);
      if (ctx->context_ != EGL_NO_CONTEXT) break;
      failures += "\n  " + c.name + ": " + eglFailure("eglCreateContext(OpenGL 4." + std::to_string(minorVersion) + " core)");
    }
    if (ctx->context_ == EGL_NO_CONTEXT) continue;
    if (!surfacelessCtx) {
      const EGLint pbAttribs[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
      ctx->surface_ = eglCreatePbufferSurface(c.display, config, pbAttribs);
      if (ctx->surface_ == EGL_NO_SURFACE) {
        failures += "\n  " + c.name + ": " + eglFailure("eglCreatePbufferSurface (no EGL_KHR_surfaceless_context)");
        continue;
      }
    }
    if (Status s = ctx->makeCurrent(); !s) {
      failures += "\n  " + c.name + ": " + s.error().message;
      continue;
    }
    return ctx;
  }
  return Error{"could not create an OpenGL 4.3+ core context through EGL:" + failures};
}

Status EglContext::makeCurrent() {
  if (eglGetCurrentContext() == context_) return Ok{};
  if (!eglMakeCurrent(display_, surface_, surface_, context_)) return Error{eglFailure("eglMakeCurrent")};
  return Ok{};
}

EglContext::~EglContext() {
  if (display_ == EGL_NO_DISPLAY) return;
  if (eglGetCurrentContext() == context_) eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  if (surface_ != EGL_NO_SURFACE) eglDestroySurface(display_, surface_);
  if (context_ != EGL_NO_CONTEXT) eglDestroyContext(display_, context_);
  std::lock_guard lock(gDisplayMutex);
  if (--gDisplayUsers[display_] == 0) {
    gDisplayUsers.erase(display_);
    eglTerminate(display_);
  }
}

}  // namespace fogbeam::gl
