#!/usr/bin/env bash
# Runs the threaded parts under ThreadSanitizer (issue 6): the state store (copy-on-write snapshots
# under concurrent writers), the UDP receiver, CAN input sources, shared-memory writer and readers
# (the 2 s hammer test with two reader threads), the UDP → render → shm end-to-end path, the
# plugin::Service tests (receivers, status server, heartbeat and frame loop; stop() joining them);
# then `fogbeam serve`'s frame loop itself for 6 s with every one of its threads busy (UDP, CAN,
# status server, heartbeat, table builds, airlight workers; tests/reliability/tsan_serve.py).
# Builds the `tsan` preset; known non-races are suppressed in tests/tsan.supp (each explained).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake --preset tsan >/dev/null
cmake --build build/tsan --target fogbeam_ipc_tests fogbeam_service_tests fogbeam -j "$(nproc)"
export TSAN_OPTIONS="suppressions=$PWD/tests/tsan.supp halt_on_error=1 second_deadlock_stack=1"
build/tsan/tests/fogbeam_ipc_tests --gtest_filter='StateStore*:UdpReceiver*:ShmChannel*:CanInput*'
build/tsan/tests/fogbeam_service_tests --gtest_filter='EndToEnd*:HostDepth*:WireMeta*:Service.*'
/usr/bin/python3 tests/reliability/tsan_serve.py build/tsan/plugin/fogbeam tests/data/service/timing.toml \
  tests/data/scenarios/soak.toml tests/data/can/mapping.toml ipc/python 6
echo "tsan: state store, UDP receiver, CAN input, shm channel, end-to-end and Service tests and the serve frame loop clean under ThreadSanitizer"
