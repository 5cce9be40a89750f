/* fogbeam — a host image generator's stand-in for the cab loop (docs/service.md, "Host depth"):
 * it draws its own world (the road plane z = 0 and a box 2 m wide, 1.5 m tall, 30 m ahead)
 * analytically into a depth buffer, publishes it with its camera through the C SDK, reads
 * fogbeam's overlay for that frame (a [[channel]] with depth_from = DEPTH), composites
 * host·A + RGB and writes the last composite as a PNG. It prints the time from each depth
 * publish to the publish of its overlay (CLOCK_MONOTONIC on both sides).
 *
 *   fogbeam_host_standin DEPTH OVERLAY WIDTH HEIGHT FRAMES PNG [RATE_HZ [TIMEOUT_S]]
 *
 * RATE_HZ 0 (default): lock-step, each depth frame waits for its overlay (fogbeam serve in
 * lock-step); otherwise depth frames go out at that rate whatever fogbeam does (free-running).
 * The eye moves 0.25 m forward per frame from x = 0 (fogbeam's axes: x forward, y left, z up),
 * at 1.2 m, looking along +x with a 60° horizontal field of view. The first 10 frames (start-up,
 * tables) are left out of the figures. Exits 0 when at least half the frames got their overlay.
 * Plain C99 on the SDK alone; the PNG is written by hand (stored deflate blocks: no zlib needed
 * for an example). */
#include <fogbeam/fogbeam_host.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static uint64_t now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static void sleep_ns(uint64_t ns) {
  struct timespec ts = {(time_t)(ns / 1000000000u), (long)(ns % 1000000000u)};
  nanosleep(&ts, NULL);
}

static float half_to_float(uint16_t h) {
  const int e = (h >> 10) & 0x1F, m = h & 0x3FF;
  const float s = (h & 0x8000) ? -1.0f : 1.0f;
  if (e == 0) return s * ldexpf((float)m, -24);
  if (e == 31) return m ? NAN : s * INFINITY;
  return s * ldexpf((float)(m | 0x400), e - 25);
}

/* The host's world: distance along the ray (eye e, unit direction d) to the road or the box. */
static const double kBoxMin[3] = {30.0, -1.0, 0.0}, kBoxMax[3] = {31.0, 1.0, 1.5};
static double trace(const double e[3], const double d[3], int* hitBox) {
  double t = d[2] < 0.0 ? -e[2] / d[2] : INFINITY; /* road plane z = 0 */
  double t0 = 0.0, t1 = INFINITY;
  for (int k = 0; k < 3; ++k) { /* slabs */
    if (d[k] == 0.0) {
      if (e[k] < kBoxMin[k] || e[k] > kBoxMax[k]) t1 = -1.0;
      continue;
    }
    double a = (kBoxMin[k] - e[k]) / d[k], b = (kBoxMax[k] - e[k]) / d[k];
    if (a > b) { const double x = a; a = b; b = x; }
    if (a > t0) t0 = a;
    if (b < t1) t1 = b;
  }
  *hitBox = t0 <= t1 && t0 < t;
  return *hitBox ? t0 : t;
}

/* ---- PNG (8-bit RGB): signature, IHDR, one IDAT of stored deflate blocks, IEND ---- */
static uint32_t crc_table[256];
static void crc_init(void) {
  for (uint32_t n = 0; n < 256; ++n) {
    uint32_t c = n;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    crc_table[n] = c;
  }
}
static uint32_t crc(uint32_t c, const unsigned char* p, size_t n) {
  c ^= 0xFFFFFFFFu;
  for (size_t i = 0; i < n; ++i) c = crc_table[(c ^ p[i]) & 0xFF] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}
static void be32(unsigned char* p, uint32_t v) {
  p[0] = (unsigned char)(v >> 24); p[1] = (unsigned char)(v >> 16); p[2] = (unsigned char)(v >> 8); p[3] = (unsigned char)v;
}
static void chunk(FILE* f, const char* type, const unsigned char* data, uint32_t n) {
  unsigned char head[8];
  be32(head, n);
  memcpy(head + 4, type, 4);
  fwrite(head, 1, 8, f);
  if (n) fwrite(data, 1, n, f);
  uint32_t c = crc(0, (const unsigned char*)type, 4);
  c = crc(c, data, n);
  unsigned char tail[4];
  be32(tail, c);
  fwrite(tail, 1, 4, f);
}
static int write_png(const char* path, const unsigned char* rgb, uint32_t w, uint32_t h) {
  const size_t raw_n = (size_t)h * (1 + 3 * (size_t)w); /* a filter byte (0) per row */
  unsigned char* raw = malloc(raw_n);
  const size_t blocks = raw_n / 65535 + 1;
  unsigned char* z = malloc(2 + raw_n + 5 * blocks + 4);
  if (!raw || !z) return 1;
  for (uint32_t y = 0; y < h; ++y) {
    raw[y * (1 + 3 * (size_t)w)] = 0;
    memcpy(raw + y * (1 + 3 * (size_t)w) + 1, rgb + (size_t)y * 3 * w, 3 * (size_t)w);
  }
  size_t o = 0;
  z[o++] = 0x78; z[o++] = 0x01; /* zlib header, no compression */
  for (size_t i = 0; i < raw_n || i == 0;) {
    const size_t n = raw_n - i > 65535 ? 65535 : raw_n - i;
    z[o++] = i + n == raw_n ? 1 : 0; /* BFINAL, BTYPE 00 = stored */
    z[o++] = (unsigned char)n; z[o++] = (unsigned char)(n >> 8);
    z[o++] = (unsigned char)~n; z[o++] = (unsigned char)(~n >> 8);
    memcpy(z + o, raw + i, n);
    o += n; i += n;
    if (n == 0) break;
  }
  uint32_t a = 1, b = 0; /* Adler-32 */
  for (size_t i = 0; i < raw_n; ++i) { a = (a + raw[i]) % 65521; b = (b + a) % 65521; }
  be32(z + o, (b << 16) | a);
  o += 4;
  FILE* f = fopen(path, "wb");
  if (!f) return 1;
  static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
  fwrite(sig, 1, 8, f);
  unsigned char ihdr[13];
  be32(ihdr, w); be32(ihdr + 4, h);
  ihdr[8] = 8; ihdr[9] = 2; ihdr[10] = 0; ihdr[11] = 0; ihdr[12] = 0; /* 8-bit RGB */
  chunk(f, "IHDR", ihdr, 13);
  chunk(f, "IDAT", z, (uint32_t)o);
  chunk(f, "IEND", NULL, 0);
  const int bad = fclose(f) != 0;
  free(raw);
  free(z);
  return bad;
}

static int cmp_double(const void* a, const void* b) {
  const double x = *(const double*)a, y = *(const double*)b;
  return x < y ? -1 : x > y;
}

int main(int argc, char** argv) {
  if (argc < 7) {
    fprintf(stderr, "usage: %s DEPTH OVERLAY WIDTH HEIGHT FRAMES PNG [RATE_HZ [TIMEOUT_S]]\n", argv[0]);
    return 2;
  }
  const char* depthName = argv[1];
  const char* overlayName = argv[2];
  const uint32_t w = (uint32_t)strtoul(argv[3], NULL, 10), h = (uint32_t)strtoul(argv[4], NULL, 10);
  const long frames = strtol(argv[5], NULL, 10);
  const char* png = argv[6];
  const double rate = argc > 7 ? strtod(argv[7], NULL) : 0.0;
  const double timeout_s = argc > 8 ? strtod(argv[8], NULL) : 120.0;
  if (w == 0 || h == 0 || frames < 1) return 2;
  crc_init();

  fogbeam_depth_writer* dw = NULL;
  if (fogbeam_depth_create(depthName, w, h, &dw) != FOGBEAM_OK) {
    fprintf(stderr, "host_standin: %s\n", fogbeam_last_error());
    return 1;
  }
  const size_t n = (size_t)w * h;
  float* depth = malloc(n * sizeof(float));
  unsigned char* box = malloc(n);
  uint64_t* sent_ns = calloc((size_t)frames + 1, sizeof(uint64_t));
  double* latency = calloc((size_t)frames + 1, sizeof(double));
  if (!depth || !box || !sent_ns || !latency) return 1;

  /* The camera: a centred pinhole, 60° wide, square pixels (fogbeam's Camera::rayDirection). */
  const double fov = 60.0 * M_PI / 180.0, f = 0.5 * w / tan(0.5 * fov);
  fogbeam_reader* r = NULL;
  const uint64_t start = now_ns();
  const uint64_t deadline = start + (uint64_t)(timeout_s * 1e9);
  const uint64_t period = rate > 0.0 ? (uint64_t)(1e9 / rate) : 0;
  size_t bytes = 0;
  uint16_t* overlay = NULL;
  long got = 0, measured = 0;
  uint64_t lastHostFrame = 0;
  double eye[3] = {0.0, 0.0, 1.2};

  for (long k = 1; k <= frames && now_ns() < deadline; ++k) {
    eye[0] = 0.25 * (double)(k - 1);
    for (uint32_t y = 0; y < h; ++y) {
      for (uint32_t x = 0; x < w; ++x) {
        /* Camera +x forward, +y left, +z up; pixel x to the right, y down. */
        double d[3] = {f, -((double)x + 0.5 - 0.5 * w), -((double)y + 0.5 - 0.5 * h)};
        const double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (int c = 0; c < 3; ++c) d[c] /= len;
        int hit = 0;
        depth[(size_t)y * w + x] = (float)trace(eye, d, &hit);
        box[(size_t)y * w + x] = (unsigned char)hit;
      }
    }
    fogbeam_camera cam;
    memset(&cam, 0, sizeof cam);
    cam.frame = (uint64_t)k;
    cam.sim_time_s = (double)(k - 1) / 30.0;
    for (int c = 0; c < 3; ++c) cam.position_m[c] = eye[c];
    cam.fov_x_deg = 60.0f;
    sent_ns[k] = now_ns();
    if (fogbeam_depth_publish(dw, depth, &cam) != FOGBEAM_OK) {
      fprintf(stderr, "host_standin: %s\n", fogbeam_last_error());
      return 1;
    }
    /* Read overlays: lock-step until this frame's arrives; free-running until the next period. */
    const uint64_t until = period ? sent_ns[k] + period : deadline;
    for (;;) {
      if (!r && fogbeam_attach(overlayName, &r) == FOGBEAM_OK) {
        bytes = fogbeam_frame_bytes(r);
        overlay = malloc(bytes);
        if (!overlay) return 1;
      }
      if (r) {
        fogbeam_frame_info info;
        const int rc = fogbeam_latest(r, overlay, bytes, &info);
        if (rc == FOGBEAM_OK && info.host_frame != lastHostFrame && info.host_frame <= (uint64_t)k) {
          lastHostFrame = info.host_frame;
          if (info.format != FOGBEAM_FORMAT_RGBA16F_OVERLAY || info.width != w || info.height != h) {
            fprintf(stderr, "host_standin: %s is not a %ux%u overlay channel\n", overlayName, w, h);
            return 1;
          }
          ++got;
          if ((long)info.host_frame > 10) latency[measured++] = (double)(info.publish_ns - sent_ns[info.host_frame]) * 1e-6;
          if (!period && info.host_frame == (uint64_t)k) break;
        } else if (rc == FOGBEAM_WRITER_GONE) {
          fogbeam_detach(r);
          r = NULL;
        }
      }
      const uint64_t t = now_ns();
      if (t >= until || t >= deadline) break;
      sleep_ns(100000); /* 0.1 ms */
    }
  }

  /* The composite of the last overlay read: the host's own luminance (cd/m²: road 0.5, box 2,
   * sky 0.05) · T + the in-scattered light, tone-mapped L / (1 + L) and sRGB-encoded. */
  if (overlay && got > 0) {
    unsigned char* rgb = malloc(3 * n);
    if (!rgb) return 1;
    for (size_t i = 0; i < n; ++i) {
      const double host = box[i] ? 2.0 : isinf(depth[i]) ? 0.05 : 0.5;
      const double T = half_to_float(overlay[4 * i + 3]);
      for (int c = 0; c < 3; ++c) {
        const double L = host * T + half_to_float(overlay[4 * i + (size_t)c]);
        const double v = L / (1.0 + L);
        const double s = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
        rgb[3 * i + (size_t)c] = (unsigned char)(s < 0 ? 0 : s > 1 ? 255 : s * 255.0 + 0.5);
      }
    }
    if (write_png(png, rgb, w, h) != 0) fprintf(stderr, "host_standin: cannot write %s\n", png);
    free(rgb);
  }
  qsort(latency, (size_t)measured, sizeof(double), cmp_double);
  const double p50 = measured ? latency[measured / 2] : 0.0, p95 = measured ? latency[(measured * 95) / 100] : 0.0;
  printf("{\"size\": \"%ux%u\", \"mode\": \"%s\", \"depth_frames\": %ld, \"overlays\": %ld, \"measured\": %ld, "
         "\"latency_ms_p50\": %.2f, \"latency_ms_p95\": %.2f, \"png\": \"%s\"}\n",
         w, h, period ? "free-running" : "lock-step", frames, got, measured, p50, p95, png);
  if (r) fogbeam_detach(r);
  fogbeam_depth_destroy(dw);
  free(overlay);
  free(depth);
  free(box);
  free(sent_ns);
  free(latency);
  return got * 2 >= frames ? 0 : 1;
}
