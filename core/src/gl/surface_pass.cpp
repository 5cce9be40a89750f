// fogbeam — the GL surface pass (see fogbeam/gl/surface_pass.hpp and docs/surface_pass.md).
//
// Frame: clear (sky: distance +inf, depth 0) → the geometry buffer: planes (full-screen triangle,
// surface_plane.frag) → glTF triangles (surface_mesh.*) with depth = 1/(1 + d) and GL_GREATER, each
// writing its normal, ρ and distance → with shading in GL, one full-screen lighting pass over it
// (surface_deferred.frag: L_s per visible pixel, once) → [GPU airlight stage (gpu_airlight_stage.hpp): a full-screen triangle into its own framebuffer
// that samples the distance attachment] → the readback ring (readback_ring.hpp): glReadPixels of
// the attachments into one of two pixel-pack buffer slots + fence; collect() waits on the oldest.
// Lamps and their tabulated profiles reach both draws through LampUpload (lamp_upload.hpp).
#include <fogbeam/gl/surface_pass.hpp>

#include "egl_context.hpp"
#include "gl_errors.hpp"
#include "gl_headers.hpp"
#include "gl_object.hpp"
#include "gpu_airlight_stage.hpp"
#include "lamp_upload.hpp"
#include "readback_ring.hpp"
#include "shader_library.hpp"
#include <fogbeam/render/surface_shading.hpp>
#include <fogbeam/scene/gltf_mesh.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <deque>
#include <optional>
#include <utility>

namespace fogbeam {

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// std430 mirror of PlaneGpu in surface_plane.frag.
struct PlaneGpu {
  double normalOffset[4];
  double reflectance[4];
};
static_assert(sizeof(PlaneGpu) == 64);

constexpr double kNearPlane_m = 0.05;  // mesh clipping only; planes are ray-cast

void GLAPIENTRY debugCallback(GLenum, GLenum type, GLuint, GLenum severity, GLsizei, const GLchar* message, const void*) {
  if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) return;
  std::fprintf(stderr, "fogbeam_gl: GL debug%s: %s\n", type == GL_DEBUG_TYPE_ERROR ? " (error)" : "", message);
}

// clip = projection · eye, eye = GL view space (x right, y up, −z forward) of a camera-relative
// world point. Infinite far plane. Pixel centres lie on rayDirection()'s rays, off-axis too: a
// camera-frame point (X, Y, Z) has image x = cx − f·Y/X, y_down = cy − f·Z/X; with
// eye = (−Y, Z, −X) and clip w = −eye_z = X,
//   x_ndc = 2x/W − 1      = (2f/W)·(−Y/X) + (2cx/W − 1)  → proj[0][0] = 2f/W, proj[2][0] = 1 − 2cx/W
//   y_ndc = 1 − 2y_down/H = (2f/H)·(Z/X)  + (1 − 2cy/H)  → proj[1][1] = 2f/H, proj[2][1] = 2cy/H − 1
// (proj[2][k] multiplies eye_z = −w). Both off-centre terms are exactly 0 for a centred camera.
glm::mat4 clipFromCameraRel(const Camera& cam) {
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

}  // namespace

struct GlSurfacePass::Impl {
  // The context, first: it is destroyed after every GL object below (gl_object.hpp). The
  // constructor runs with it current.
  Impl(std::unique_ptr<gl::EglContext> context, std::string desc, bool timerQueries, bool shadeOnCpu,
       unsigned shadingThreads)
      : egl(std::move(context)), description(std::move(desc)), timerQuery(timerQueries), cpuShading(shadeOnCpu),
        readback(timerQueries) {
    if (cpuShading) shadePool = std::make_unique<ThreadPool>(shadingThreads);
  }
  // Makes the context current so that the members' destructors delete their objects in it.
  ~Impl() {
    if (egl) (void)egl->makeCurrent();
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  std::unique_ptr<gl::EglContext> egl;
  std::string description;
  GlSurfaceStats stats;
  bool timerQuery = false;
  // The geometry draws write a geometry buffer (normal and ρ red in colorTex, ρ green and blue
  // in rhoTex, the distance in distanceTex); it is lit once per pixel, never per fragment (the
  // draws write gl_FragDepth, which turns early depth tests off: forward shading lit every hidden
  // fragment too). With shading on the CPU (GlOptions::shading) collect() lights it with `shader`
  // on `shadePool`, from the lamps and camera of the frame's submit() (shadeFrames, in submission
  // order like the readback ring's slots); otherwise lightProgram does, into litTex.
  bool cpuShading = false;
  SurfaceShader shader;
  std::unique_ptr<ThreadPool> shadePool;
  std::deque<kernels::ShadeFrame> shadeFrames;

  // The geometry draws and the lighting pass: programs and their uniform locations.
  gl::Program planeProgram, meshProgram, lightProgram;
  GLint planeWorldFromCamera = -1, planeFocalPrincipal = -1, planePlaneCount = -1;
  GLint meshAnchor = -1, meshClip = -1;
  GLint lightWorldFromCamera = -1, lightFocalPrincipal = -1, lightExtinction = -1, lightAmbient = -1,
        lightLampCount = -1;
  // The fog light's uniforms (common_photometry.glsl): bins, sums, map rows, columns.
  std::array<GLint, 4> lightFog{-1, -1, -1, -1};
  // With shading in the shaders: the frame's fog light (SurfaceShader::prepareFogLight builds its
  // table and annulus maps; the shaders read them from LampUpload's fog texture).
  FogLightFrame gpuFog;

  // Geometry: the full-screen triangle has no attributes; the glTF mesh (positions relative to
  // its anchor, float) and the planes (double, relative to the eye).
  gl::VertexArray emptyVao = gl::genVertexArray(), meshVao = gl::genVertexArray(), bodyVao = gl::genVertexArray();
  gl::Buffer meshVbo = gl::genBuffer(), planeSsbo = gl::genBuffer(), bodyVbo = gl::genBuffer();
  GLsizei bodyVertexCount = 0;  // the scene's body quads (the bonnet), camera-relative, this frame
  std::vector<MeshVertex> bodyVertices;  // their triangles, rebuilt every frame in kept storage
  GLsizei meshVertexCount = 0;
  Vec3 meshAnchor_m{0.0};
  std::optional<std::string> meshPath;  // the glTF file currently in meshVbo

  // Render targets: the geometry buffer (fbo: normal and ρ red RGBA32F, distance d R32F, ρ green
  // and blue RG32F, depth 1/(1 + d) DEPTH32F); with shading in GL the lit colour L_s (litTex,
  // RGBA32F, drawn through lightFbo) and readFbo (litTex and the distance) for the readback.
  gl::Framebuffer fbo = gl::genFramebuffer(), lightFbo = gl::genFramebuffer(), readFbo = gl::genFramebuffer();
  gl::Texture colorTex, distanceTex, rhoTex, litTex;
  gl::Renderbuffer depthRb;
  int fbWidth = 0, fbHeight = 0;

  gl::LampUpload lamps;
  gl::GpuAirlightStage airlight;
  gl::ReadbackRing readback;

  // Links the surface programs and describes the mesh's vertex layout.
  Status init() {
    auto plane = gl::linkProgram("surface_fullscreen.vert", "surface_plane.frag");
    if (!plane) return plane.error();
    planeProgram = std::move(plane).value();
    auto mesh = gl::linkProgram("surface_mesh.vert", "surface_mesh.frag");
    if (!mesh) return mesh.error();
    meshProgram = std::move(mesh).value();
    const GLuint pp = planeProgram.get(), mp = meshProgram.get();
    planeWorldFromCamera = glGetUniformLocation(pp, "uWorldFromCamera");
    planeFocalPrincipal = glGetUniformLocation(pp, "uFocalPrincipal");
    planePlaneCount = glGetUniformLocation(pp, "uPlaneCount");
    meshAnchor = glGetUniformLocation(mp, "uAnchorFromCamera");
    meshClip = glGetUniformLocation(mp, "uClipFromCameraRel");
    if (!cpuShading) {
      auto light = gl::linkProgram("surface_fullscreen.vert", "surface_deferred.frag");
      if (!light) return light.error();
      lightProgram = std::move(light).value();
      const GLuint lp = lightProgram.get();
      lightWorldFromCamera = glGetUniformLocation(lp, "uWorldFromCamera");
      lightFocalPrincipal = glGetUniformLocation(lp, "uFocalPrincipal");
      lightExtinction = glGetUniformLocation(lp, "uExtinction");
      lightAmbient = glGetUniformLocation(lp, "uAmbient");
      lightLampCount = glGetUniformLocation(lp, "uLampCount");
      const char* fogNames[4] = {"uFogBins", "uFogSums", "uFogMapRows", "uFogMapColumns"};
      for (std::size_t i = 0; i < 4; ++i) lightFog[i] = glGetUniformLocation(lp, fogNames[i]);
    }

    // The glTF mesh and the body quads share the vertex layout (MeshVertex) and the program.
    for (const auto& [vao, vbo] : {std::pair{meshVao.get(), meshVbo.get()}, std::pair{bodyVao.get(), bodyVbo.get()}}) {
      glBindVertexArray(vao);
      glBindBuffer(GL_ARRAY_BUFFER, vbo);
      constexpr auto stride = static_cast<GLsizei>(sizeof(MeshVertex));
      glEnableVertexAttribArray(0);
      glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<const void*>(offsetof(MeshVertex, position)));
      glEnableVertexAttribArray(1);
      glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<const void*>(offsetof(MeshVertex, normal)));
      glEnableVertexAttribArray(2);
      glVertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, stride,
                            reinterpret_cast<const void*>(offsetof(MeshVertex, reflectance)));
    }
    glBindVertexArray(0);
    if (std::string e = gl::glErrors("GL surface pass set-up"); !e.empty()) return Error{e};
    return Ok{};
  }

  // Whether the bound framebuffer is complete; `what` names it in the error.
  static Status complete(const char* what) {
    const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
    if (status == GL_FRAMEBUFFER_COMPLETE) return Ok{};
    char buf[64];
    std::snprintf(buf, sizeof buf, "0x%04X", status);
    return Error{std::string("framebuffer for ") + what + " incomplete: " +
                 (status == GL_FRAMEBUFFER_UNSUPPORTED ? "GL_FRAMEBUFFER_UNSUPPORTED" : buf)};
  }

  // The render targets at the frame's size (re-created when it changes).
  Status ensureFramebuffer(int w, int h) {
    if (w == fbWidth && h == fbHeight) return Ok{};
    GLint maxSize = 0;
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &maxSize);
    if (w > maxSize || h > maxSize)
      return Error{"image " + std::to_string(w) + "x" + std::to_string(h) + " exceeds GL_MAX_RENDERBUFFER_SIZE " +
                   std::to_string(maxSize)};
    colorTex = gl::genTexture();
    glBindTexture(GL_TEXTURE_2D, colorTex.get());
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, w, h);
    distanceTex = gl::genTexture();
    glBindTexture(GL_TEXTURE_2D, distanceTex.get());
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_R32F, w, h);
    rhoTex = gl::genTexture();
    glBindTexture(GL_TEXTURE_2D, rhoTex.get());
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_RG32F, w, h);
    depthRb = gl::genRenderbuffer();
    glBindRenderbuffer(GL_RENDERBUFFER, depthRb.get());
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, w, h);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo.get());
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, colorTex.get(), 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, distanceTex.get(), 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT2, GL_TEXTURE_2D, rhoTex.get(), 0);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depthRb.get());
    if (Status st = complete("the geometry buffer (RGBA32F + R32F + RG32F + DEPTH32F)"); !st) return st;
    if (!cpuShading) {
      litTex = gl::genTexture();
      glBindTexture(GL_TEXTURE_2D, litTex.get());
      glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, w, h);
      glBindFramebuffer(GL_FRAMEBUFFER, lightFbo.get());
      glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, litTex.get(), 0);
      if (Status st = complete("the lit colour (RGBA32F)"); !st) return st;
      // Only read from (glReadPixels): the distance texture is attached here too, never drawn to.
      glBindFramebuffer(GL_FRAMEBUFFER, readFbo.get());
      glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, litTex.get(), 0);
      glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, distanceTex.get(), 0);
      if (Status st = complete("the readback (RGBA32F + R32F)"); !st) return st;
    }
    fbWidth = w;
    fbHeight = h;
    return Ok{};
  }

  // The scene's glTF triangles in meshVbo (loaded on first use, cached by path).
  Status ensureMesh(const Scene& scene) {
    if (meshPath == scene.gltf_path) return Ok{};
    meshVertexCount = 0;
    meshPath.reset();
    if (!scene.gltf_path) return Ok{};
    auto mesh = loadGltfMesh(*scene.gltf_path);
    if (!mesh) return mesh.error();
    if (mesh->vertices.size() > static_cast<std::size_t>(std::numeric_limits<GLsizei>::max()))
      return Error{*scene.gltf_path + ": too many triangles"};
    glBindBuffer(GL_ARRAY_BUFFER, meshVbo.get());
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(mesh->vertices.size() * sizeof(MeshVertex)),
                 mesh->vertices.data(), GL_STATIC_DRAW);
    meshVertexCount = static_cast<GLsizei>(mesh->vertices.size());
    meshAnchor_m = mesh->anchor_m;
    meshPath = scene.gltf_path;
    if (std::string e = gl::glErrors("uploading " + *scene.gltf_path); !e.empty()) return Error{e};
    return Ok{};
  }

  // The scene's planes (unit normal and offset relative to the eye, metres; reflectance) to
  // storage-buffer binding 1.
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
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, planeSsbo.get());
    glBufferData(GL_SHADER_STORAGE_BUFFER, static_cast<GLsizeiptr>(planes.size() * sizeof(PlaneGpu)), planes.data(),
                 GL_DYNAMIC_DRAW);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, planeSsbo.get());
  }

  // The scene's body quads (the bonnet) as two triangles each, relative to the eye (so that the
  // mesh program draws them with a zero anchor), into bodyVbo.
  void uploadBody(const Scene& scene) {
    std::vector<MeshVertex>& v = bodyVertices;
    v.clear();
    for (const Quad& q : scene.body) {
      const Vec3 c = q.corner_m - scene.camera.position_m;
      const Vec3 n = glm::normalize(glm::cross(q.edge_u_m, q.edge_v_m));
      const Vec3 corners[4] = {c, c + q.edge_u_m, c + q.edge_u_m + q.edge_v_m, c + q.edge_v_m};
      for (int k : {0, 1, 2, 0, 2, 3}) {
        MeshVertex mv{};
        for (int a = 0; a < 3; ++a) {
          mv.position[a] = static_cast<float>(corners[k][a]);
          mv.normal[a] = static_cast<float>(n[a]);
          mv.reflectance[a] = static_cast<float>(q.reflectance);
        }
        v.push_back(mv);
      }
    }
    bodyVertexCount = static_cast<GLsizei>(v.size());
    if (v.empty()) return;
    glBindBuffer(GL_ARRAY_BUFFER, bodyVbo.get());
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(v.size() * sizeof(MeshVertex)), v.data(), GL_DYNAMIC_DRAW);
  }

  // Clears the geometry buffer to the sky and draws the planes, the mesh and the body into it,
  // then with shading in GL lights it (lightPixels), all bracketed by `timer` (GL_TIME_ELAPSED;
  // 0: none); with `nothingToDraw` (the CPU lights a frame that has nothing for GL to draw) only
  // the timer.
  void drawSurfaces(const Scene& scene, GLuint timer, bool nothingToDraw) {
    if (nothingToDraw) {  // shading on the CPU, planes and body only: not even a clear is read
      if (timer != 0) {
        glBeginQuery(GL_TIME_ELAPSED, timer);
        glEndQuery(GL_TIME_ELAPSED);
      }
      return;
    }
    const Camera& cam = scene.camera;
    glBindFramebuffer(GL_FRAMEBUFFER, fbo.get());
    const GLenum drawBuffers[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1, GL_COLOR_ATTACHMENT2};
    glDrawBuffers(3, drawBuffers);
    glViewport(0, 0, cam.width, cam.height);
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthMask(GL_TRUE);
    glDepthFunc(GL_GREATER);
    // The sky: no surface (distance +inf); whoever lights the buffer writes I_a there.
    const float zero[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    const float skyDistance[4] = {std::numeric_limits<float>::infinity(), 0.0f, 0.0f, 0.0f};
    const float farDepth = 0.0f;
    glClearBufferfv(GL_COLOR, 0, zero);
    glClearBufferfv(GL_COLOR, 1, skyDistance);
    glClearBufferfv(GL_COLOR, 2, zero);
    glClearBufferfv(GL_DEPTH, 0, &farDepth);

    if (timer != 0) glBeginQuery(GL_TIME_ELAPSED, timer);
    // With shading on the CPU the planes are cast there too (in double, SurfaceShader), so GL
    // draws them only for the GPU airlight stage, which reads their distances here.
    if (!scene.planes.empty() && (!cpuShading || airlight.enabled())) {
      glUseProgram(planeProgram.get());
      glUniformMatrix3dv(planeWorldFromCamera, 1, GL_FALSE, glm::value_ptr(cam.worldFromCamera));
      // (f, cx, H − cy): the principal point in GL window coordinates (y up from the bottom).
      const Vec2 principal = cam.principalPoint();
      glUniform3d(planeFocalPrincipal, cam.focalLengthPixels(), principal.x, cam.height - principal.y);
      glUniform1i(planePlaneCount, static_cast<GLint>(scene.planes.size()));
      glBindVertexArray(emptyVao.get());
      glDrawArrays(GL_TRIANGLES, 0, 3);
    }
    if (meshVertexCount > 0) {
      glUseProgram(meshProgram.get());
      const glm::vec3 anchor(meshAnchor_m - cam.position_m);
      glUniform3fv(meshAnchor, 1, glm::value_ptr(anchor));
      const glm::mat4 clip = clipFromCameraRel(cam);
      glUniformMatrix4fv(meshClip, 1, GL_FALSE, glm::value_ptr(clip));
      glBindVertexArray(meshVao.get());
      glDrawArrays(GL_TRIANGLES, 0, meshVertexCount);
    }
    // The body quads (the bonnet): with shading on the CPU they are cast there, like the
    // planes, and drawn here only for the GPU airlight stage's distances.
    if (bodyVertexCount > 0 && (!cpuShading || airlight.enabled())) {
      glUseProgram(meshProgram.get());
      const glm::vec3 zero3(0.0f);
      glUniform3fv(meshAnchor, 1, glm::value_ptr(zero3));
      glUniformMatrix4fv(meshClip, 1, GL_FALSE, glm::value_ptr(clipFromCameraRel(cam)));
      glBindVertexArray(bodyVao.get());
      glDrawArrays(GL_TRIANGLES, 0, bodyVertexCount);
    }
    if (!cpuShading) lightPixels(scene);
    if (timer != 0) glEndQuery(GL_TIME_ELAPSED);
    glBindVertexArray(0);
  }

  // Shading in GL: every pixel of the geometry buffer lit once (surface_deferred.frag: the lamps'
  // direct light and fog light, the fog between the eye and the surface, I_a on the sky) into
  // litTex, which the readback reads with the distance (readFbo).
  void lightPixels(const Scene& scene) {
    const Camera& cam = scene.camera;
    glBindFramebuffer(GL_FRAMEBUFFER, lightFbo.get());
    const GLenum drawBuffer = GL_COLOR_ATTACHMENT0;
    glDrawBuffers(1, &drawBuffer);
    glDisable(GL_DEPTH_TEST);
    glDepthMask(GL_FALSE);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_BUFFER, lamps.profileTexture());
    glActiveTexture(GL_TEXTURE5);
    glBindTexture(GL_TEXTURE_BUFFER, lamps.fogTexture());
    const std::pair<GLenum, GLuint> gbuffer[] = {
        {GL_TEXTURE1, colorTex.get()}, {GL_TEXTURE2, distanceTex.get()}, {GL_TEXTURE3, rhoTex.get()}};
    for (const auto& [unit, tex] : gbuffer) {
      glActiveTexture(unit);
      glBindTexture(GL_TEXTURE_2D, tex);
    }
    glActiveTexture(GL_TEXTURE0);
    glUseProgram(lightProgram.get());
    const glm::mat3 worldFromCamera(cam.worldFromCamera);
    glUniformMatrix3fv(lightWorldFromCamera, 1, GL_FALSE, glm::value_ptr(worldFromCamera));
    const Vec2 principal = cam.principalPoint();
    glUniform3f(lightFocalPrincipal, static_cast<float>(cam.focalLengthPixels()), static_cast<float>(principal.x),
                static_cast<float>(cam.height - principal.y));
    glUniform1f(lightExtinction, static_cast<float>(scene.fog.extinction_per_m));
    glUniform1f(lightAmbient, static_cast<float>(scene.fog.ambient_cd_m2));
    glUniform1i(lightLampCount, static_cast<GLint>(scene.lamps.size()));
    glUniform1i(lightFog[0], lamps.fogBins());
    glUniform1i(lightFog[1], lamps.fogSums());
    glUniform1i(lightFog[2], lamps.fogMapRows());
    glUniform1i(lightFog[3], lamps.fogMapColumns());
    glBindVertexArray(emptyVao.get());
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glEnable(GL_DEPTH_TEST);
    glDepthMask(GL_TRUE);
  }

  Status submit(const Scene& scene) {
    const auto t0 = Clock::now();
    if (Status s = egl->makeCurrent(); !s) return s;
    const Camera& cam = scene.camera;
    if (cam.width <= 0 || cam.height <= 0) return Error{"camera width and height must be > 0"};
    if (readback.full()) return Error{"GlSurfacePass::submit: two frames in flight; collect() one first"};
    // This frame's resources: targets, mesh, profiles, the airlight stage's; then lamps and planes.
    if (Status s = ensureFramebuffer(cam.width, cam.height); !s) return s;
    if (Status s = ensureMesh(scene); !s) return s;
    if (Status s = lamps.ensureProfiles(scene); !s) return s;
    if (airlight.enabled()) {
      if (Status s = airlight.prepare(scene); !s) return s;
    }
    if (!cpuShading) {  // the shaders light the fog light too: its table and maps (built once)
      shader.prepareFogLight(scene, gpuFog);
      if (Status s = lamps.ensureFogLight(gpuFog); !s) return s;
    }
    lamps.uploadLamps(scene);
    uploadPlanes(scene);
    uploadBody(scene);

    // With shading on the CPU and nothing for GL to draw (no mesh, no GPU airlight: planes and
    // body are cast on the CPU) GL neither clears nor reads back anything.
    const bool nothingDrawn = cpuShading && meshVertexCount == 0 && !airlight.enabled();
    const gl::ReadbackRing::Timers timers = readback.beginFrame();
    drawSurfaces(scene, timers.surface, nothingDrawn);
    if (airlight.enabled())
      airlight.draw(scene, {lamps.profileTexture(), distanceTex.get(), emptyVao.get(), timers.airlight});
    if (cpuShading) shader.prepare(scene, shadeFrames.emplace_back(), shadePool.get());  // in step with the ring's slots
    readback.endFrame({cpuShading ? fbo.get() : readFbo.get(), cpuShading, nothingDrawn, airlight.enabled() ? airlight.framebuffer() : 0u,
                       cam.width, cam.height, static_cast<std::size_t>(meshVertexCount) / 3});
    if (std::string e = gl::glErrors("surface pass draw/readback"); !e.empty()) return Error{e};
    readback.setSubmitMs(msSince(t0));
    if (!timerQuery) stats.surface_ms = 0.0;
    return Ok{};
  }

  Status collect(SurfaceBuffers& out, std::vector<float>* airlightOut) {
    if (readback.empty()) return Error{"GlSurfacePass::collect: no frame submitted"};
    if (Status s = egl->makeCurrent(); !s) return s;
    if (!cpuShading) return readback.collect(out, airlightOut, stats);
    // The frame's lamps and camera leave the queue whatever collect() returns: its slot has.
    const kernels::ShadeFrame frame = std::move(shadeFrames.front());
    shadeFrames.pop_front();
    double shadeMs = 0.0;
    Status st = readback.collect(out, airlightOut, stats, [&](const SurfaceGBufferView& g, SurfaceBuffers& o) {
      const auto t0 = Clock::now();
      shader.shade(frame, g, o, shadePool.get());
      shadeMs = msSince(t0);
    });
    stats.shade_ms = shadeMs;
    return st;
  }

  // Collects (and drops) every frame still in flight, so that the next collect() returns the
  // next submit()'s frame.
  Status drain() {
    while (!readback.empty()) {
      SurfaceBuffers discard;
      if (Status s = collect(discard, nullptr); !s) return s;
    }
    return Ok{};
  }
};

Result<std::unique_ptr<GlSurfacePass>> GlSurfacePass::create(const GlOptions& options) {
  auto ctx = gl::EglContext::create(options);
  if (!ctx) return ctx.error();
  GLint major = 0, minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  auto str = [](GLenum e) {
    const auto* s = reinterpret_cast<const char*>(glGetString(e));
    return std::string(s ? s : "?");
  };
  std::string description =
      str(GL_VENDOR) + " | " + str(GL_RENDERER) + " | " + str(GL_VERSION) + " | EGL " + (*ctx)->platformName();
  if (major < 4 || (major == 4 && minor < 3)) return Error{"OpenGL 4.3 or later is needed, got " + description};
  const bool timerQuery = epoxy_gl_version() >= 33 || epoxy_has_gl_extension("GL_ARB_timer_query");
  if (options.debug_context && (epoxy_gl_version() >= 43 || epoxy_has_gl_extension("GL_KHR_debug"))) {
    glEnable(GL_DEBUG_OUTPUT);
    glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS);
    glDebugMessageCallback(debugCallback, nullptr);
  }
  // Shading on the CPU where the rasteriser is software (docs/surface_pass.md, "Shading on the
  // CPU"): there a fragment shader costs more per lamp and pixel than SIMD code on the same cores.
  const std::string renderer = str(GL_RENDERER);
  const bool software = renderer.find("llvmpipe") != std::string::npos ||
                        renderer.find("softpipe") != std::string::npos ||
                        renderer.find("swrast") != std::string::npos || renderer.find("SWR") != std::string::npos;
  const bool cpuShading =
      options.shading == SurfaceShading::Cpu || (options.shading == SurfaceShading::Auto && software);
  description += cpuShading ? " | shading on the CPU" : " | shading in GL";
  auto impl = std::make_unique<Impl>(std::move(ctx).value(), std::move(description), timerQuery, cpuShading,
                                     options.shading_threads);
  if (Status s = impl->init(); !s) return s.error();
  impl->shader.setTableCacheDir(options.table_cache_dir);
  return std::unique_ptr<GlSurfacePass>(new GlSurfacePass(std::move(impl)));
}

GlSurfacePass::GlSurfacePass(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlSurfacePass::~GlSurfacePass() = default;

Status GlSurfacePass::render(const Scene& scene, SurfaceBuffers& out) {
  // Frames still in flight from earlier submit() calls are dropped so that `out` gets this scene.
  if (Status s = impl_->drain(); !s) return s;
  if (Status s = impl_->submit(scene); !s) return s;
  return impl_->collect(out, nullptr);
}

Status GlSurfacePass::render(const Scene& scene, SurfaceBuffers& out, std::vector<float>& airlight) {
  if (!impl_->airlight.enabled()) return Error{"GlSurfacePass::render: the GPU airlight stage is off (setAirlight)"};
  if (Status s = impl_->drain(); !s) return s;
  if (Status s = impl_->submit(scene); !s) return s;
  return impl_->collect(out, &airlight);
}

Status GlSurfacePass::submit(const Scene& scene) { return impl_->submit(scene); }
Status GlSurfacePass::collect(SurfaceBuffers& out) { return impl_->collect(out, nullptr); }
Status GlSurfacePass::collect(SurfaceBuffers& out, std::vector<float>& airlight) { return impl_->collect(out, &airlight); }

Status GlSurfacePass::setAirlight(const std::optional<GpuAirlightOptions>& options) {
  return impl_->airlight.configure(options);
}

bool GlSurfacePass::airlightEnabled() const noexcept { return impl_->airlight.enabled(); }
SurfaceShading GlSurfacePass::shading() const noexcept {
  return impl_->cpuShading ? SurfaceShading::Cpu : SurfaceShading::Gpu;
}
std::string GlSurfacePass::description() const { return impl_->description; }
std::string GlSurfacePass::takeTableCacheError() { return impl_->shader.takeTableCacheError(); }
const GlSurfaceStats& GlSurfacePass::stats() const noexcept { return impl_->stats; }

}  // namespace fogbeam
