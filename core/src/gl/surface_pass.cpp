// fogbeam — the GL surface pass (see fogbeam/gl/surface_pass.hpp and docs/surface_pass.md).
//
// Frame: clear (sky: L_s = I_a, distance +inf, depth 0) → planes (full-screen triangle,
// surface_plane.frag) → glTF triangles (surface_mesh.*) with depth = 1/(1 + d) and GL_GREATER →
// [GPU airlight: a full-screen triangle (airlight_accurate.frag) into a second framebuffer that
// samples the distance attachment] → glReadPixels of the attachments into one of two pixel-pack
// buffer slots + fence.
// collect() waits on the oldest slot's fence, maps its PBOs and copies rows bottom-up into
// SurfaceBuffers (row 0 = top).
#include <fogbeam/gl/surface_pass.hpp>

#include "egl_context.hpp"
#include "gl_headers.hpp"
#include <fogbeam/scene/gltf_mesh.hpp>
#include "shader_library.hpp"

#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <limits>
#include <optional>
#include <type_traits>
#include <variant>

namespace fogbeam {

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// std430 mirror of LampGpu in common_photometry.glsl.
struct LampGpu {
  float position[4];
  float axisX[4];
  float axisY[4];
  float axisZ[4];
  float color[4];
  float params[4];
  std::int32_t kind[4];
  std::int32_t table[4];
};
static_assert(sizeof(LampGpu) == 128);

// std430 mirror of PlaneGpu in surface_plane.frag.
struct PlaneGpu {
  double normalOffset[4];
  double reflectance[4];
};
static_assert(sizeof(PlaneGpu) == 64);

constexpr double kNearPlane_m = 0.05;  // mesh clipping only; planes are ray-cast

std::int32_t typeCode(PhotometricType t) {
  switch (t) {
    case PhotometricType::A: return 0;
    case PhotometricType::B: return 1;
    case PhotometricType::C: return 2;
  }
  return 2;
}

std::int32_t symmetryCode(PlaneSymmetry s) {
  switch (s) {
    case PlaneSymmetry::None: return 0;
    case PlaneSymmetry::Rotational: return 1;
    case PlaneSymmetry::Quadrant: return 2;
    case PlaneSymmetry::Half0To180: return 3;
    case PlaneSymmetry::Half90To270: return 4;
    case PlaneSymmetry::MirrorH: return 5;
  }
  return 0;
}

void setVec(float (&dst)[4], const Vec3& v, double w = 0.0) {
  dst[0] = static_cast<float>(v.x);
  dst[1] = static_cast<float>(v.y);
  dst[2] = static_cast<float>(v.z);
  dst[3] = static_cast<float>(w);
}

// Same phase function (same kind and parameters): the G-moment table depends on nothing else.
bool samePhase(const Phase& a, const Phase& b) {
  if (a.index() != b.index()) return false;
  if (const auto* x = std::get_if<HenyeyGreensteinPhase>(&a)) return x->g == std::get<HenyeyGreensteinPhase>(b).g;
  if (const auto* x = std::get_if<FogMiePhase>(&a)) return x->diameter_um == std::get<FogMiePhase>(b).diameter_um;
  return true;
}

void GLAPIENTRY debugCallback(GLenum, GLenum type, GLuint, GLenum severity, GLsizei, const GLchar* message, const void*) {
  if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) return;
  std::fprintf(stderr, "fogbeam_gl: GL debug%s: %s\n", type == GL_DEBUG_TYPE_ERROR ? " (error)" : "", message);
}

}  // namespace

struct GlSurfacePass::Impl {
  std::unique_ptr<gl::EglContext> egl;
  std::string description;
  GlSurfaceStats stats;
  bool timerQuery = false;

  GLuint planeProgram = 0, meshProgram = 0;
  GLint planeWorldFromCamera = -1, planeFocalPrincipal = -1, planePlaneCount = -1;
  GLint planeExtinction = -1, planeAmbient = -1, planeLampCount = -1;
  GLint meshAnchor = -1, meshClip = -1, meshExtinction = -1, meshAmbient = -1, meshLampCount = -1;

  GLuint emptyVao = 0, meshVao = 0, meshVbo = 0;
  GLsizei meshVertexCount = 0;
  Vec3 meshAnchor_m{0.0};
  std::optional<std::string> meshPath;  // the glTF file currently in meshVbo

  GLuint fbo = 0, colorTex = 0, distanceTex = 0, depthRb = 0;
  int fbWidth = 0, fbHeight = 0;

  // GPU airlight stage (setAirlight): its program, framebuffer and texture, and the G-moment
  // table of the phase function it was uploaded for.
  std::optional<GpuAirlightOptions> airlight;
  GLuint airlightProgram = 0, airlightFbo = 0, airlightTex = 0, gMomentTex = 0, gMomentLoTex = 0, gThetaTex = 0;
  int airlightWidth = 0, airlightHeight = 0;
  std::optional<GMomentTexels> gTable;
  Phase gTablePhase;
  bool gTableUploaded = false;

  GLuint lampSsbo = 0, planeSsbo = 0, profileBuffer = 0, profileTex = 0;
  std::vector<std::shared_ptr<const Profile>> uploadedProfiles;  // tabulated profiles in profileBuffer, in order
  std::vector<std::int32_t> profileOffsets;
  GLint maxTextureBufferSize = 0;

  struct Slot {
    GLuint pboColor = 0, pboDistance = 0, pboAirlight = 0, query = 0, airlightQuery = 0;
    bool hasAirlight = false;
    GLsync fence = nullptr;
    int width = 0, height = 0;
    double submitMs = 0.0;
    std::size_t triangles = 0;
  };
  std::array<Slot, 2> slots{};
  std::deque<std::size_t> pending;  // slot indices in submission order
  std::size_t nextSlot = 0;

  ~Impl() {
    if (!egl || !egl->makeCurrent()) return;
    for (Slot& s : slots) {
      if (s.fence) glDeleteSync(s.fence);
      glDeleteBuffers(1, &s.pboColor);
      glDeleteBuffers(1, &s.pboDistance);
      glDeleteBuffers(1, &s.pboAirlight);
      if (s.query) glDeleteQueries(1, &s.query);
      if (s.airlightQuery) glDeleteQueries(1, &s.airlightQuery);
    }
    glDeleteProgram(airlightProgram);
    glDeleteFramebuffers(1, &airlightFbo);
    glDeleteTextures(1, &airlightTex);
    glDeleteTextures(1, &gMomentTex);
    glDeleteTextures(1, &gMomentLoTex);
    glDeleteTextures(1, &gThetaTex);
    glDeleteProgram(planeProgram);
    glDeleteProgram(meshProgram);
    glDeleteVertexArrays(1, &emptyVao);
    glDeleteVertexArrays(1, &meshVao);
    glDeleteBuffers(1, &meshVbo);
    glDeleteFramebuffers(1, &fbo);
    glDeleteTextures(1, &colorTex);
    glDeleteTextures(1, &distanceTex);
    glDeleteRenderbuffers(1, &depthRb);
    glDeleteBuffers(1, &lampSsbo);
    glDeleteBuffers(1, &planeSsbo);
    glDeleteBuffers(1, &profileBuffer);
    glDeleteTextures(1, &profileTex);
  }

  Status init() {
    auto plane = gl::linkProgram("surface_fullscreen.vert", "surface_plane.frag");
    if (!plane) return plane.error();
    planeProgram = *plane;
    auto mesh = gl::linkProgram("surface_mesh.vert", "surface_mesh.frag");
    if (!mesh) return mesh.error();
    meshProgram = *mesh;
    planeWorldFromCamera = glGetUniformLocation(planeProgram, "uWorldFromCamera");
    planeFocalPrincipal = glGetUniformLocation(planeProgram, "uFocalPrincipal");
    planePlaneCount = glGetUniformLocation(planeProgram, "uPlaneCount");
    planeExtinction = glGetUniformLocation(planeProgram, "uExtinction");
    planeAmbient = glGetUniformLocation(planeProgram, "uAmbient");
    planeLampCount = glGetUniformLocation(planeProgram, "uLampCount");
    meshAnchor = glGetUniformLocation(meshProgram, "uAnchorFromCamera");
    meshClip = glGetUniformLocation(meshProgram, "uClipFromCameraRel");
    meshExtinction = glGetUniformLocation(meshProgram, "uExtinction");
    meshAmbient = glGetUniformLocation(meshProgram, "uAmbient");
    meshLampCount = glGetUniformLocation(meshProgram, "uLampCount");

    glGenVertexArrays(1, &emptyVao);
    glGenVertexArrays(1, &meshVao);
    glGenBuffers(1, &meshVbo);
    glBindVertexArray(meshVao);
    glBindBuffer(GL_ARRAY_BUFFER, meshVbo);
    constexpr auto stride = static_cast<GLsizei>(sizeof(MeshVertex));
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<const void*>(offsetof(MeshVertex, position)));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<const void*>(offsetof(MeshVertex, normal)));
    glEnableVertexAttribArray(2);
    glVertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<const void*>(offsetof(MeshVertex, reflectance)));
    glBindVertexArray(0);

    glGenBuffers(1, &lampSsbo);
    glGenBuffers(1, &planeSsbo);
    glGenBuffers(1, &profileBuffer);
    glGenTextures(1, &profileTex);
    const float zero = 0.0f;
    glBindBuffer(GL_TEXTURE_BUFFER, profileBuffer);
    glBufferData(GL_TEXTURE_BUFFER, sizeof zero, &zero, GL_DYNAMIC_DRAW);
    glBindTexture(GL_TEXTURE_BUFFER, profileTex);
    glTexBuffer(GL_TEXTURE_BUFFER, GL_R32F, profileBuffer);
    glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &maxTextureBufferSize);

    for (Slot& s : slots) {
      glGenBuffers(1, &s.pboColor);
      glGenBuffers(1, &s.pboDistance);
      glGenBuffers(1, &s.pboAirlight);
      if (timerQuery) {
        glGenQueries(1, &s.query);
        glGenQueries(1, &s.airlightQuery);
      }
    }
    glGenFramebuffers(1, &fbo);
    if (std::string e = gl::glErrors("GL surface pass set-up"); !e.empty()) return Error{e};
    return Ok{};
  }

  Status ensureFramebuffer(int w, int h) {
    if (w == fbWidth && h == fbHeight) return Ok{};
    GLint maxSize = 0;
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &maxSize);
    if (w > maxSize || h > maxSize)
      return Error{"image " + std::to_string(w) + "x" + std::to_string(h) + " exceeds GL_MAX_RENDERBUFFER_SIZE " + std::to_string(maxSize)};
    glDeleteTextures(1, &colorTex);
    glDeleteTextures(1, &distanceTex);
    glDeleteRenderbuffers(1, &depthRb);
    glGenTextures(1, &colorTex);
    glBindTexture(GL_TEXTURE_2D, colorTex);
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, w, h);
    glGenTextures(1, &distanceTex);
    glBindTexture(GL_TEXTURE_2D, distanceTex);
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_R32F, w, h);
    glGenRenderbuffers(1, &depthRb);
    glBindRenderbuffer(GL_RENDERBUFFER, depthRb);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, w, h);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, colorTex, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, distanceTex, 0);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depthRb);
    const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
    if (status != GL_FRAMEBUFFER_COMPLETE) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "0x%04X", status);
      return Error{std::string("framebuffer (RGBA32F + R32F + DEPTH32F) incomplete: ") +
                   (status == GL_FRAMEBUFFER_UNSUPPORTED ? "GL_FRAMEBUFFER_UNSUPPORTED" : buf)};
    }
    fbWidth = w;
    fbHeight = h;
    return Ok{};
  }

  Status ensureMesh(const Scene& scene) {
    if (meshPath == scene.gltf_path) return Ok{};
    meshVertexCount = 0;
    meshPath.reset();
    if (!scene.gltf_path) return Ok{};
    auto mesh = loadGltfMesh(*scene.gltf_path);
    if (!mesh) return mesh.error();
    if (mesh->vertices.size() > static_cast<std::size_t>(std::numeric_limits<GLsizei>::max()))
      return Error{*scene.gltf_path + ": too many triangles"};
    glBindBuffer(GL_ARRAY_BUFFER, meshVbo);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(mesh->vertices.size() * sizeof(MeshVertex)),
                 mesh->vertices.data(), GL_STATIC_DRAW);
    meshVertexCount = static_cast<GLsizei>(mesh->vertices.size());
    meshAnchor_m = mesh->anchor_m;
    meshPath = scene.gltf_path;
    if (std::string e = gl::glErrors("uploading " + *scene.gltf_path); !e.empty()) return Error{e};
    return Ok{};
  }

  // Uploads every tabulated profile used by the scene (once: cached while the set is the same).
  Status ensureProfiles(const Scene& scene) {
    std::vector<std::shared_ptr<const Profile>> wanted;
    for (const SceneLamp& sl : scene.lamps) {
      if (!sl.lamp.profile) return Error{"lamp '" + sl.name + "' has no profile"};
      if (std::holds_alternative<TabulatedProfile>(sl.lamp.profile->model()) &&
          std::find(wanted.begin(), wanted.end(), sl.lamp.profile) == wanted.end())
        wanted.push_back(sl.lamp.profile);
    }
    if (wanted == uploadedProfiles) return Ok{};
    std::vector<float> data;
    std::vector<std::int32_t> offsets;
    for (const auto& p : wanted) {
      const auto& t = std::get<TabulatedProfile>(p->model());
      offsets.push_back(static_cast<std::int32_t>(data.size()));
      for (double h : t.horizontal) data.push_back(static_cast<float>(h));
      for (double v : t.vertical) data.push_back(static_cast<float>(v));
      for (double c : t.candela) data.push_back(static_cast<float>(c));
    }
    if (data.empty()) data.push_back(0.0f);
    if (data.size() > static_cast<std::size_t>(maxTextureBufferSize))
      return Error{"lamp profiles need " + std::to_string(data.size()) + " texels, more than GL_MAX_TEXTURE_BUFFER_SIZE " +
                   std::to_string(maxTextureBufferSize)};
    glBindBuffer(GL_TEXTURE_BUFFER, profileBuffer);
    glBufferData(GL_TEXTURE_BUFFER, static_cast<GLsizeiptr>(data.size() * sizeof(float)), data.data(), GL_STATIC_DRAW);
    uploadedProfiles = std::move(wanted);
    profileOffsets = std::move(offsets);
    return Ok{};
  }

  void uploadLamps(const Scene& scene) {
    std::vector<LampGpu> lamps(std::max<std::size_t>(1, scene.lamps.size()), LampGpu{});
    const Vec3& eye = scene.camera.position_m;
    for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
      const Lamp& l = scene.lamps[i].lamp;
      LampGpu& g = lamps[i];
      setVec(g.position, l.position_m - eye);
      setVec(g.axisX, l.worldFromLamp[0]);
      setVec(g.axisY, l.worldFromLamp[1]);
      setVec(g.axisZ, l.worldFromLamp[2]);
      setVec(g.color, l.color);
      std::visit(
          [&](const auto& m) {
            using M = std::decay_t<decltype(m)>;
            if constexpr (std::is_same_v<M, IsotropicProfile>) {
              g.kind[0] = 0;
              g.params[0] = static_cast<float>(m.intensity_cd);
            } else if constexpr (std::is_same_v<M, SpotProfile>) {
              g.kind[0] = 1;
              g.params[0] = static_cast<float>(m.peak_cd);
              g.params[1] = static_cast<float>(m.inner);
              g.params[2] = static_cast<float>(m.outer);
            } else {
              g.kind[0] = 2;
              g.kind[1] = typeCode(m.type);
              g.kind[2] = symmetryCode(m.symmetry);
              g.params[0] = 1.0f;
              // Outside this cone about the axis I = 0 (the GPU airlight cuts rays to it).
              g.params[3] = static_cast<float>(l.profile->supportHalfAngle());
              const auto it = std::find(uploadedProfiles.begin(), uploadedProfiles.end(), l.profile);
              g.table[0] = profileOffsets[static_cast<std::size_t>(it - uploadedProfiles.begin())];
              g.table[1] = static_cast<std::int32_t>(m.horizontal.size());
              g.table[2] = static_cast<std::int32_t>(m.vertical.size());
            }
          },
          l.profile->model());
    }
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, lampSsbo);
    glBufferData(GL_SHADER_STORAGE_BUFFER, static_cast<GLsizeiptr>(lamps.size() * sizeof(LampGpu)), lamps.data(), GL_DYNAMIC_DRAW);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, lampSsbo);
  }

  void uploadPlanes(const Scene& scene) {
    std::vector<PlaneGpu> planes(std::max<std::size_t>(1, scene.planes.size()), PlaneGpu{});
    for (std::size_t i = 0; i < scene.planes.size(); ++i) {
      const Plane& p = scene.planes[i];
      const Vec3 n = glm::normalize(p.normal);
      planes[i].normalOffset[0] = n.x;
      planes[i].normalOffset[1] = n.y;
      planes[i].normalOffset[2] = n.z;
      planes[i].normalOffset[3] = glm::dot(p.point_m - scene.camera.position_m, n);
      planes[i].reflectance[0] = p.reflectance;
    }
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, planeSsbo);
    glBufferData(GL_SHADER_STORAGE_BUFFER, static_cast<GLsizeiptr>(planes.size() * sizeof(PlaneGpu)), planes.data(), GL_DYNAMIC_DRAW);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, planeSsbo);
  }

  // clip = projection · eye, eye = GL view space (x right, y up, −z forward) of a camera-relative
  // world point. Infinite far plane. Pixel centres lie on rayDirection()'s rays, off-axis too: a
  // camera-frame point (X, Y, Z) has image x = cx − f·Y/X, y_down = cy − f·Z/X; with
  // eye = (−Y, Z, −X) and clip w = −eye_z = X,
  //   x_ndc = 2x/W − 1      = (2f/W)·(−Y/X) + (2cx/W − 1)  → proj[0][0] = 2f/W, proj[2][0] = 1 − 2cx/W
  //   y_ndc = 1 − 2y_down/H = (2f/H)·(Z/X)  + (1 − 2cy/H)  → proj[1][1] = 2f/H, proj[2][1] = 2cy/H − 1
  // (proj[2][k] multiplies eye_z = −w). Both off-centre terms are exactly 0 for a centred camera.
  static glm::mat4 clipFromCameraRel(const Camera& cam) {
    const double f = cam.focalLengthPixels();
    const Vec2 c = cam.principalPoint();
    const Mat3 cameraFromWorld = glm::transpose(cam.worldFromCamera);
    // eye = (−y_c, z_c, −x_c) of the camera-frame point (x forward, y left, z up).
    const Mat3 eyeFromCamera(Vec3(0, 0, -1), Vec3(-1, 0, 0), Vec3(0, 1, 0));  // columns
    const Mat3 eyeFromWorld = eyeFromCamera * cameraFromWorld;
    glm::dmat4 view(eyeFromWorld);
    glm::dmat4 proj(0.0);
    proj[0][0] = 2.0 * f / cam.width;
    proj[1][1] = 2.0 * f / cam.height;
    proj[2][0] = 1.0 - 2.0 * c.x / cam.width;
    proj[2][1] = 2.0 * c.y / cam.height - 1.0;
    proj[2][2] = -1.0;
    proj[2][3] = -1.0;
    proj[3][2] = -2.0 * kNearPlane_m;
    return glm::mat4(proj * view);
  }

  // The airlight stage's program (compiled on first use: a machine that never asks for it
  // never compiles it), its target of the frame's size, and the G table of the scene's phase.
  Status ensureAirlight(const Scene& scene) {
    if (airlightProgram == 0) {
      auto prog = gl::linkProgram("surface_fullscreen.vert", "airlight_accurate.frag");
      if (!prog) return prog.error();
      airlightProgram = *prog;
      glGenFramebuffers(1, &airlightFbo);
      glGenTextures(1, &gMomentTex);
      glGenTextures(1, &gMomentLoTex);
      glGenTextures(1, &gThetaTex);
    }
    const Camera& cam = scene.camera;
    if (airlightWidth != cam.width || airlightHeight != cam.height) {
      glDeleteTextures(1, &airlightTex);
      glGenTextures(1, &airlightTex);
      glBindTexture(GL_TEXTURE_2D, airlightTex);
      glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, cam.width, cam.height);
      glBindFramebuffer(GL_FRAMEBUFFER, airlightFbo);
      glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, airlightTex, 0);
      if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        return Error{"airlight framebuffer (RGBA32F) incomplete"};
      airlightWidth = cam.width;
      airlightHeight = cam.height;
    }
    if (!gTableUploaded || !samePhase(gTablePhase, scene.fog.phase)) {
      gTable = gMomentTexels(scene.fog.phase, airlight->table);
      auto upload = [&](GLuint tex, GLenum internal, GLenum format, int w, int h, const std::vector<float>& data) {
        glBindTexture(GL_TEXTURE_2D, tex);
        glTexImage2D(GL_TEXTURE_2D, 0, static_cast<GLint>(internal), w, h, 0, format, GL_FLOAT, data.data());
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      };
      upload(gMomentTex, GL_RGBA32F, GL_RGBA, gTable->nTheta, gTable->nK, gTable->texels);
      upload(gMomentLoTex, GL_RGBA32F, GL_RGBA, gTable->nTheta, gTable->nK, gTable->texelsLo);
      std::vector<float> theta(2 * gTable->theta.size());
      for (std::size_t j = 0; j < gTable->theta.size(); ++j) {
        theta[2 * j] = gTable->theta[j];
        theta[2 * j + 1] = gTable->thetaLo[j];
      }
      upload(gThetaTex, GL_RG32F, GL_RG, gTable->nTheta, 1, theta);
      gTablePhase = scene.fog.phase;
      gTableUploaded = true;
    }
    if (std::string e = gl::glErrors("GPU airlight set-up"); !e.empty()) return Error{e};
    return Ok{};
  }

  void drawAirlight(const Scene& scene, Slot& slot) {
    const Camera& cam = scene.camera;
    glBindFramebuffer(GL_FRAMEBUFFER, airlightFbo);
    const GLenum target = GL_COLOR_ATTACHMENT0;
    glDrawBuffers(1, &target);
    glViewport(0, 0, cam.width, cam.height);
    glDisable(GL_DEPTH_TEST);
    glUseProgram(airlightProgram);
    auto loc = [&](const char* name) { return glGetUniformLocation(airlightProgram, name); };
    const glm::mat3 worldFromCamera(cam.worldFromCamera);
    glUniformMatrix3fv(loc("uWorldFromCamera"), 1, GL_FALSE, glm::value_ptr(worldFromCamera));
    const Vec2 principal = cam.principalPoint();
    glUniform3f(loc("uFocalPrincipal"), static_cast<float>(cam.focalLengthPixels()), static_cast<float>(principal.x),
                static_cast<float>(cam.height - principal.y));
    glUniform1i(loc("uLampCount"), static_cast<GLint>(scene.lamps.size()));
    glUniform1f(loc("uExtinction"), static_cast<float>(scene.fog.extinction_per_m));
    glUniform1f(loc("uAlbedo"), static_cast<float>(scene.fog.albedo));
    glUniform1i(loc("uPieces"), airlight->pieces);
    glUniform1i(loc("uGThetaN"), gTable->nTheta);
    glUniform1i(loc("uGKN"), gTable->nK);
    glUniform1f(loc("uGK0"), static_cast<float>(gTable->k0));
    glUniform1f(loc("uGLogSpan"), static_cast<float>(gTable->logSpan));
    glUniform1f(loc("uGKMax"), static_cast<float>(gTable->kMax));
    int kind = 0;
    float phase[4] = {0, 0, 0, 0};
    if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&scene.fog.phase)) {
      kind = 1;
      phase[0] = static_cast<float>(hg->g);
    } else if (const auto* fm = std::get_if<FogMiePhase>(&scene.fog.phase)) {
      kind = 2;
      phase[0] = static_cast<float>(fm->g_hg);
      phase[1] = static_cast<float>(fm->g_d);
      phase[2] = static_cast<float>(fm->alpha);
      phase[3] = static_cast<float>(fm->w);
    }
    glUniform1i(loc("uPhaseKind"), kind);
    glUniform4fv(loc("uPhase"), 1, phase);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_BUFFER, profileTex);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D, distanceTex);
    glActiveTexture(GL_TEXTURE2);
    glBindTexture(GL_TEXTURE_2D, gMomentTex);
    glActiveTexture(GL_TEXTURE3);
    glBindTexture(GL_TEXTURE_2D, gThetaTex);
    glActiveTexture(GL_TEXTURE4);
    glBindTexture(GL_TEXTURE_2D, gMomentLoTex);
    glActiveTexture(GL_TEXTURE0);
    if (timerQuery) glBeginQuery(GL_TIME_ELAPSED, slot.airlightQuery);
    glBindVertexArray(emptyVao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    if (timerQuery) glEndQuery(GL_TIME_ELAPSED);
    glBindVertexArray(0);
  }

  Status submit(const Scene& scene) {
    const auto t0 = Clock::now();
    if (Status s = egl->makeCurrent(); !s) return s;
    const Camera& cam = scene.camera;
    if (cam.width <= 0 || cam.height <= 0) return Error{"camera width and height must be > 0"};
    if (pending.size() >= slots.size()) return Error{"GlSurfacePass::submit: two frames in flight; collect() one first"};
    if (Status s = ensureFramebuffer(cam.width, cam.height); !s) return s;
    if (Status s = ensureMesh(scene); !s) return s;
    if (Status s = ensureProfiles(scene); !s) return s;
    if (airlight) {
      if (Status s = ensureAirlight(scene); !s) return s;
    }
    uploadLamps(scene);
    uploadPlanes(scene);

    const std::size_t si = nextSlot;
    nextSlot = (nextSlot + 1) % slots.size();
    Slot& slot = slots[si];

    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    const GLenum drawBuffers[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
    glDrawBuffers(2, drawBuffers);
    glViewport(0, 0, cam.width, cam.height);
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthMask(GL_TRUE);
    glDepthFunc(GL_GREATER);
    const auto ia = static_cast<float>(scene.fog.ambient_cd_m2);
    const float skyColor[4] = {ia, ia, ia, 0.0f};
    const float skyDistance[4] = {std::numeric_limits<float>::infinity(), 0.0f, 0.0f, 0.0f};
    const float farDepth = 0.0f;
    glClearBufferfv(GL_COLOR, 0, skyColor);
    glClearBufferfv(GL_COLOR, 1, skyDistance);
    glClearBufferfv(GL_DEPTH, 0, &farDepth);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_BUFFER, profileTex);

    if (timerQuery) glBeginQuery(GL_TIME_ELAPSED, slot.query);
    const auto kt = static_cast<float>(scene.fog.extinction_per_m);
    const auto nLamps = static_cast<GLint>(scene.lamps.size());
    if (!scene.planes.empty()) {
      glUseProgram(planeProgram);
      glUniformMatrix3dv(planeWorldFromCamera, 1, GL_FALSE, glm::value_ptr(cam.worldFromCamera));
      // (f, cx, H − cy): the principal point in GL window coordinates (y up from the bottom).
      const Vec2 principal = cam.principalPoint();
      glUniform3d(planeFocalPrincipal, cam.focalLengthPixels(), principal.x, cam.height - principal.y);
      glUniform1i(planePlaneCount, static_cast<GLint>(scene.planes.size()));
      glUniform1f(planeExtinction, kt);
      glUniform1f(planeAmbient, ia);
      glUniform1i(planeLampCount, nLamps);
      glBindVertexArray(emptyVao);
      glDrawArrays(GL_TRIANGLES, 0, 3);
    }
    if (meshVertexCount > 0) {
      glUseProgram(meshProgram);
      const glm::vec3 anchor(meshAnchor_m - cam.position_m);
      glUniform3fv(meshAnchor, 1, glm::value_ptr(anchor));
      const glm::mat4 clip = clipFromCameraRel(cam);
      glUniformMatrix4fv(meshClip, 1, GL_FALSE, glm::value_ptr(clip));
      glUniform1f(meshExtinction, kt);
      glUniform1f(meshAmbient, ia);
      glUniform1i(meshLampCount, nLamps);
      glBindVertexArray(meshVao);
      glDrawArrays(GL_TRIANGLES, 0, meshVertexCount);
    }
    if (timerQuery) glEndQuery(GL_TIME_ELAPSED);
    glBindVertexArray(0);
    slot.hasAirlight = airlight.has_value();
    if (slot.hasAirlight) drawAirlight(scene, slot);

    // Asynchronous readback: glReadPixels into pixel-pack buffers returns at once; the fence
    // tells collect() when the copies are done.
    const auto nPixels = static_cast<GLsizeiptr>(cam.width) * cam.height;
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    if (slot.hasAirlight) {
      glBindBuffer(GL_PIXEL_PACK_BUFFER, slot.pboAirlight);
      glBufferData(GL_PIXEL_PACK_BUFFER, nPixels * 4 * static_cast<GLsizeiptr>(sizeof(float)), nullptr, GL_STREAM_READ);
      glReadBuffer(GL_COLOR_ATTACHMENT0);
      glReadPixels(0, 0, cam.width, cam.height, GL_RGBA, GL_FLOAT, nullptr);
      glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    }
    glBindBuffer(GL_PIXEL_PACK_BUFFER, slot.pboColor);
    if (slot.width != cam.width || slot.height != cam.height)
      glBufferData(GL_PIXEL_PACK_BUFFER, nPixels * 4 * static_cast<GLsizeiptr>(sizeof(float)), nullptr, GL_STREAM_READ);
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glReadPixels(0, 0, cam.width, cam.height, GL_RGBA, GL_FLOAT, nullptr);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, slot.pboDistance);
    if (slot.width != cam.width || slot.height != cam.height)
      glBufferData(GL_PIXEL_PACK_BUFFER, nPixels * static_cast<GLsizeiptr>(sizeof(float)), nullptr, GL_STREAM_READ);
    glReadBuffer(GL_COLOR_ATTACHMENT1);
    glReadPixels(0, 0, cam.width, cam.height, GL_RED, GL_FLOAT, nullptr);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    slot.width = cam.width;
    slot.height = cam.height;
    slot.fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    glFlush();
    slot.triangles = static_cast<std::size_t>(meshVertexCount) / 3;
    pending.push_back(si);
    if (std::string e = gl::glErrors("surface pass draw/readback"); !e.empty()) return Error{e};
    slot.submitMs = msSince(t0);
    if (!timerQuery) stats.surface_ms = 0.0;
    return Ok{};
  }

  Status collect(SurfaceBuffers& out, std::vector<float>* airlightOut) {
    if (pending.empty()) return Error{"GlSurfacePass::collect: no frame submitted"};
    if (Status s = egl->makeCurrent(); !s) return s;
    const auto t0 = Clock::now();
    Slot& slot = slots[pending.front()];
    pending.pop_front();
    for (;;) {  // wait in 1 s steps; a GPU that never signals is reported, not waited on forever
      const GLenum r = glClientWaitSync(slot.fence, GL_SYNC_FLUSH_COMMANDS_BIT, 1'000'000'000);
      if (r == GL_ALREADY_SIGNALED || r == GL_CONDITION_SATISFIED) break;
      if (r == GL_WAIT_FAILED) {
        glDeleteSync(slot.fence);
        slot.fence = nullptr;
        return Error{"glClientWaitSync failed: " + gl::glErrorName(glGetError())};
      }
      if (msSince(t0) > 30'000.0) return Error{"GL surface pass: the GPU did not finish within 30 s"};
    }
    glDeleteSync(slot.fence);
    slot.fence = nullptr;

    const int w = slot.width, h = slot.height;
    out.width = w;
    out.height = h;
    const auto n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    out.rgb.resize(3 * n);
    out.distance.resize(n);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, slot.pboColor);
    const auto* rgba = static_cast<const float*>(
        glMapBufferRange(GL_PIXEL_PACK_BUFFER, 0, static_cast<GLsizeiptr>(4 * n * sizeof(float)), GL_MAP_READ_BIT));
    if (rgba == nullptr) return Error{"glMapBufferRange (colour PBO) failed: " + gl::glErrorName(glGetError())};
    const auto uw = static_cast<std::size_t>(w);
    for (int j = 0; j < h; ++j) {  // GL rows are bottom-up
      const float* src = rgba + 4 * uw * static_cast<std::size_t>(h - 1 - j);
      float* dst = out.rgb.data() + 3 * uw * static_cast<std::size_t>(j);
      for (std::size_t i = 0; i < uw; ++i) {
        dst[3 * i] = src[4 * i];
        dst[3 * i + 1] = src[4 * i + 1];
        dst[3 * i + 2] = src[4 * i + 2];
      }
    }
    glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, slot.pboDistance);
    const auto* dist = static_cast<const float*>(
        glMapBufferRange(GL_PIXEL_PACK_BUFFER, 0, static_cast<GLsizeiptr>(n * sizeof(float)), GL_MAP_READ_BIT));
    if (dist == nullptr) return Error{"glMapBufferRange (distance PBO) failed: " + gl::glErrorName(glGetError())};
    for (int j = 0; j < h; ++j)
      std::memcpy(out.distance.data() + uw * static_cast<std::size_t>(j), dist + uw * static_cast<std::size_t>(h - 1 - j),
                  uw * sizeof(float));
    glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
    if (airlightOut) {
      if (!slot.hasAirlight) return Error{"GlSurfacePass: the frame was submitted without the GPU airlight stage"};
      airlightOut->resize(3 * n);
      glBindBuffer(GL_PIXEL_PACK_BUFFER, slot.pboAirlight);
      const auto* air = static_cast<const float*>(
          glMapBufferRange(GL_PIXEL_PACK_BUFFER, 0, static_cast<GLsizeiptr>(4 * n * sizeof(float)), GL_MAP_READ_BIT));
      if (air == nullptr) return Error{"glMapBufferRange (airlight PBO) failed: " + gl::glErrorName(glGetError())};
      for (int j = 0; j < h; ++j) {
        const float* src = air + 4 * uw * static_cast<std::size_t>(h - 1 - j);
        float* dst = airlightOut->data() + 3 * uw * static_cast<std::size_t>(j);
        for (std::size_t i = 0; i < uw; ++i) {
          dst[3 * i] = src[4 * i];
          dst[3 * i + 1] = src[4 * i + 1];
          dst[3 * i + 2] = src[4 * i + 2];
        }
      }
      glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
    }
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);

    stats.readback_ms = msSince(t0);
    stats.submit_ms = slot.submitMs;
    stats.triangles = slot.triangles;
    if (timerQuery) {
      GLuint64 ns = 0;
      glGetQueryObjectui64v(slot.query, GL_QUERY_RESULT, &ns);
      stats.surface_ms = static_cast<double>(ns) * 1e-6;
      stats.airlight_ms = 0.0;
      if (slot.hasAirlight) {
        glGetQueryObjectui64v(slot.airlightQuery, GL_QUERY_RESULT, &ns);
        stats.airlight_ms = static_cast<double>(ns) * 1e-6;
      }
    }
    if (std::string e = gl::glErrors("surface pass readback"); !e.empty()) return Error{e};
    return Ok{};
  }
};

Result<std::unique_ptr<GlSurfacePass>> GlSurfacePass::create(const GlOptions& options) {
  auto impl = std::make_unique<Impl>();
  auto ctx = gl::EglContext::create(options);
  if (!ctx) return ctx.error();
  impl->egl = std::move(ctx).value();
  GLint major = 0, minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  auto str = [](GLenum e) {
    const auto* s = reinterpret_cast<const char*>(glGetString(e));
    return std::string(s ? s : "?");
  };
  impl->description = str(GL_VENDOR) + " | " + str(GL_RENDERER) + " | " + str(GL_VERSION) + " | EGL " + impl->egl->platformName();
  if (major < 4 || (major == 4 && minor < 3)) return Error{"OpenGL 4.3 or later is needed, got " + impl->description};
  impl->timerQuery = epoxy_gl_version() >= 33 || epoxy_has_gl_extension("GL_ARB_timer_query");
  if (options.debug_context && (epoxy_gl_version() >= 43 || epoxy_has_gl_extension("GL_KHR_debug"))) {
    glEnable(GL_DEBUG_OUTPUT);
    glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS);
    glDebugMessageCallback(debugCallback, nullptr);
  }
  if (Status s = impl->init(); !s) return s.error();
  return std::unique_ptr<GlSurfacePass>(new GlSurfacePass(std::move(impl)));
}

GlSurfacePass::GlSurfacePass(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlSurfacePass::~GlSurfacePass() = default;

Status GlSurfacePass::render(const Scene& scene, SurfaceBuffers& out) {
  // Wait for frames still in flight from earlier submit() calls so that `out` gets this scene.
  while (!impl_->pending.empty()) {
    SurfaceBuffers discard;
    if (Status s = impl_->collect(discard, nullptr); !s) return s;
  }
  if (Status s = impl_->submit(scene); !s) return s;
  return impl_->collect(out, nullptr);
}

Status GlSurfacePass::render(const Scene& scene, SurfaceBuffers& out, std::vector<float>& airlight) {
  if (!impl_->airlight) return Error{"GlSurfacePass::render: the GPU airlight stage is off (setAirlight)"};
  while (!impl_->pending.empty()) {
    SurfaceBuffers discard;
    if (Status s = impl_->collect(discard, nullptr); !s) return s;
  }
  if (Status s = impl_->submit(scene); !s) return s;
  return impl_->collect(out, &airlight);
}

Status GlSurfacePass::submit(const Scene& scene) { return impl_->submit(scene); }
Status GlSurfacePass::collect(SurfaceBuffers& out) { return impl_->collect(out, nullptr); }
Status GlSurfacePass::collect(SurfaceBuffers& out, std::vector<float>& airlight) { return impl_->collect(out, &airlight); }

Status GlSurfacePass::setAirlight(const std::optional<GpuAirlightOptions>& options) {
  if (options && (options->pieces < 1 || options->pieces > 1024))
    return Error{"GPU airlight: pieces must be in 1..1024, got " + std::to_string(options->pieces)};
  if (options && impl_->airlight &&
      (options->table.g_table_theta != impl_->airlight->table.g_table_theta ||
       options->table.g_table_k != impl_->airlight->table.g_table_k ||
       options->table.g_table_k_max != impl_->airlight->table.g_table_k_max))
    impl_->gTableUploaded = false;
  impl_->airlight = options;
  return Ok{};
}

bool GlSurfacePass::airlightEnabled() const noexcept { return impl_->airlight.has_value(); }
std::string GlSurfacePass::description() const { return impl_->description; }
const GlSurfaceStats& GlSurfacePass::stats() const noexcept { return impl_->stats; }

}  // namespace fogbeam
