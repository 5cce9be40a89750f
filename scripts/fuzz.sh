#!/usr/bin/env bash
# Fuzzes every decoder and parser that reads outside input (issue 6): builds the libFuzzer targets
# with clang, ASan and UBSan (the `fuzz` build preset: target fuzz_all of build/asan, the same
# build that runs the suite under sanitizers in scripts/asan.sh), replays the crash regressions
# (tests/fuzz/regressions/<target>/: inputs that once crashed, now each a test), then runs each
# target for SECONDS (default 20) on a scratch copy of its seed corpus (tests/fuzz/corpus/<target>)
# and prints one line per target: executions, corpus size and coverage reached. Targets run
# FOGBEAM_FUZZ_JOBS at a time (default nproc), each on one core. Exits 1 after the first crash,
# leak, timeout or sanitizer report, leaving the reproducer under build/asan/fuzz-findings.
#
# usage: scripts/fuzz.sh [SECONDS] [TARGET…]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-20}
shift || true
bash scripts/setup.sh
cmake --preset asan >/dev/null
cmake --build --preset fuzz -j "$(nproc)"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(udp_message dbc candump cannelloni ies eulumdat csv_profile scene scenario esmini_csv service_config can_config gltf)
fi
jobs=${FOGBEAM_FUZZ_JOBS:-$(nproc)}
findings=build/asan/fuzz-findings
scratchRoot=build/asan/fuzz-scratch
rm -rf "$findings" "$scratchRoot"
mkdir -p "$findings"

# One target: regressions, then SECONDS of fuzzing; its summary line goes to $findings/$t.line.
fuzz_one() {
  local t=$1 bin=build/asan/tests/fuzz/fuzz_$1 reg=tests/fuzz/regressions/$1 nreg=0
  if [ -d "$reg" ] && [ -n "$(ls -A "$reg")" ]; then
    nreg=$(ls -A "$reg" | wc -l)
    "$bin" -runs=0 "$reg"/* >"$findings/$t.regressions.log" 2>&1 || {
      echo "fuzz: $t: a regression input fails again:"; tail -30 "$findings/$t.regressions.log"; return 1; }
  fi
  local scratch=$scratchRoot/$t
  mkdir -p "$scratch"
  # -max_len 65536: larger than any datagram (65507) and than the shipped files fed as seeds.
  if ! "$bin" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 -print_final_stats=1 \
      -artifact_prefix="$findings/$t-" "$scratch" "tests/fuzz/corpus/$t" >"$findings/$t.log" 2>&1; then
    echo "fuzz: $t found a failure (reproducer: $(ls "$findings"/"$t"-* 2>/dev/null | head -1)):"
    grep -m1 -A25 "ERROR\|runtime error\|deadly signal" "$findings/$t.log" || tail -30 "$findings/$t.log"
    return 1
  fi
  local runs rate corpus cov
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$findings/$t.log" | grep -o '[0-9]*$' || echo 0)
  rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$findings/$t.log" | grep -o '[0-9]*$' || echo 0)
  corpus=$(ls -A "$scratch" | wc -l)
  cov=$(grep -o 'cov: [0-9]*' "$findings/$t.log" | tail -1 | grep -o '[0-9]*' || echo 0)
  printf '%-16s %12s %10s %8s %8s  %s\n' "$t" "$runs" "$rate" "$corpus" "$cov" "$nreg passed" >"$findings/$t.line"
}

failed=0
running=0
for t in "${targets[@]}"; do
  if [ "$running" -ge "$jobs" ]; then
    wait -n || failed=1
    running=$((running - 1))
  fi
  [ "$failed" -eq 0 ] || break
  fuzz_one "$t" &
  running=$((running + 1))
done
while [ "$running" -gt 0 ]; do
  wait -n || failed=1
  running=$((running - 1))
done
printf '%-16s %12s %10s %8s %8s  %s\n' target executions exec/s corpus cov regressions
for t in "${targets[@]}"; do [ -f "$findings/$t.line" ] && cat "$findings/$t.line"; done
[ "$failed" -eq 0 ] || { echo "fuzz: failure (logs in $findings)"; exit 1; }
echo "fuzz: ${#targets[@]} targets, ${seconds} s each, $jobs at a time: no crash, leak, timeout or sanitizer report"
