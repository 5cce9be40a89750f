/* fogbeam — example image-generator side: attach to a channel with the C host SDK and read
 * frames as they come, printing what each frame says about itself.
 *
 *   fogbeam_host_example [CHANNEL [FRAMES [TIMEOUT_S]]]   (defaults: main 10 5)
 *
 * Exits 0 after FRAMES distinct frames, 1 on timeout or error. Plain C99: the SDK's interface
 * has no C++ in it. */
#include <fogbeam/fogbeam_host.h>

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char** argv) {
  const char* channel = argc > 1 ? argv[1] : "main";
  const long want = argc > 2 ? strtol(argv[2], NULL, 10) : 10;
  const double timeout = argc > 3 ? strtod(argv[3], NULL) : 5.0;
  const double start = now_s();
  fogbeam_reader* r = NULL;
  while (fogbeam_attach(channel, &r) != FOGBEAM_OK) {
    if (now_s() - start > timeout) {
      fprintf(stderr, "host_reader: %s\n", fogbeam_last_error());
      return 1;
    }
    struct timespec pause = {0, 10000000};
    nanosleep(&pause, NULL);
  }
  const size_t size = fogbeam_frame_bytes(r);
  unsigned char* pixels = malloc(size);
  if (!pixels) return 1;
  long got = 0;
  uint64_t last = 0;
  while (got < want && now_s() - start < timeout) {
    fogbeam_frame_info info;
    const int rc = fogbeam_latest(r, pixels, size, &info);
    if (rc == FOGBEAM_OK && info.frame != last) {
      last = info.frame;
      ++got;
      printf("frame %llu  %ux%u format %u  sim %.3f s  lights 0x%x  total %.2f ms  latency %.2f ms  first byte %u\n",
             (unsigned long long)info.frame, info.width, info.height, info.format, info.sim_time_s, info.lights,
             info.total_ms, info.latency_ms, pixels[0]);
    } else if (rc == FOGBEAM_WRITER_GONE || rc == FOGBEAM_ERROR) {
      fprintf(stderr, "host_reader: writer gone or error (%d): %s\n", rc, fogbeam_last_error());
      break;
    } else {
      struct timespec pause = {0, 1000000};
      nanosleep(&pause, NULL);
    }
  }
  free(pixels);
  fogbeam_detach(r);
  printf("host_reader: %ld frame(s) read\n", got);
  return got >= want ? 0 : 1;
}
