#!/usr/bin/env bash
# The test command (README; used verbatim by .ci/run): installs what the build needs (Debian
# packages), then runs everything CI checks, and prints how long each stage took:
#
#   build      the default preset (RelWithDebInfo, warnings are errors)
#   unit       every ctest test but the serial ones, -j(nproc)
#   timing     the frame-timing suite and the lock-step run (label timing), alone on the machine:
#              their figures mean something only there
#   serial     the reliability tests (fault injection, UDP flood) and the 120 s soak (labels
#              reliability, soak): mostly waiting on a 60 Hz frame loop, so the sanitizer builds
#              run beside them at nice 19 (the tests keep their frame pace: they assert it)
#   sanitizer builds   build/asan (clang ASan + UBSan, -O1; also the libFuzzer targets) and
#              build/tsan (GCC TSan, -O1), started beside `serial`
#   tsan       scripts/tsan.sh: the threaded I/O and the service under ThreadSanitizer
#   fuzz       scripts/fuzz.sh 20: every decoder and parser of outside input, 20 s each
#   asan       scripts/asan.sh: the whole suite again under ASan + UBSan + LSan
#
# FOGBEAM_TEST_JOBS overrides the parallelism (default: nproc).
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${FOGBEAM_TEST_JOBS:-$(nproc)}
t0=$(date +%s)
declare -a stages=()
last=$t0
mark() {  # mark NAME: the time since the previous mark goes to NAME
  local now
  now=$(date +%s)
  stages+=("$(printf '%-34s %5d s' "$1" $((now - last)))")
  last=$now
}
report() {
  echo "test.sh: stage times (wall clock, ${jobs} jobs):"
  printf '  %s\n' "${stages[@]}"
  echo "  $(printf '%-34s %5d s' total $(($(date +%s) - t0)))"
}
trap 'status=$?; [ $status -ne 0 ] && { echo "test.sh: FAILED (exit $status)"; report; }' EXIT

bash scripts/setup.sh
mark setup
cmake --preset default >/dev/null
cmake --preset asan >/dev/null
cmake --preset tsan >/dev/null
cmake --build --preset default -j "$jobs"
mark "build (default)"

ctest --preset default -j "$jobs" -LE 'timing|reliability|soak'
mark "unit and integration tests"
ctest --preset default -L timing
mark "timing tests (machine otherwise idle)"

# The sanitizer builds use the CPU the serial tests leave idle; nice 19 keeps them from taking it
# from the frame loops under test.
build_log=build/sanitizer-builds.log
mkdir -p build
(
  nice -n 19 cmake --build --preset asan -j "$jobs" &&
  nice -n 19 cmake --build --preset fuzz -j "$jobs" &&
  nice -n 19 cmake --build --preset tsan -j "$jobs"
) >"$build_log" 2>&1 &
builds=$!
serial_status=0
ctest --preset default -L 'reliability|soak' || serial_status=$?
mark "reliability + soak (builds beside)"
if ! wait "$builds"; then
  echo "test.sh: a sanitizer build failed:"; tail -40 "$build_log"; exit 1
fi
mark "sanitizer builds (rest)"
[ "$serial_status" -eq 0 ] || { echo "test.sh: reliability or soak tests failed"; exit "$serial_status"; }

bash scripts/tsan.sh
mark "ThreadSanitizer"
bash scripts/fuzz.sh 20
mark "fuzzing (13 targets x 20 s)"
bash scripts/asan.sh
mark "ASan + UBSan suite"
trap - EXIT
report
echo "test.sh: all stages passed"
