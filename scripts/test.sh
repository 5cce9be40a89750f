#!/usr/bin/env bash
# Installs what the build needs (Debian packages), builds with the default preset
# (warnings are errors) and runs every test, then the threaded parts under ThreadSanitizer
# (scripts/tsan.sh), then builds the libFuzzer targets (clang, ASan, UBSan) and fuzzes each decoder
# and parser for 20 s (scripts/fuzz.sh), then the whole suite again under ASan + UBSan + LSan
# (scripts/asan.sh, the debug preset). Used verbatim by .ci/run.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake --preset default >/dev/null
cmake --build --preset default -j "$(nproc)"
ctest --preset default -j "$(nproc)"
bash scripts/tsan.sh
bash scripts/fuzz.sh 20
bash scripts/asan.sh
