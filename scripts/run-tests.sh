#!/usr/bin/env bash
# The second README command: builds if needed and runs every test (CTest), under a virtual X
# server when one is available (the rendering and GUI tests need it).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${BRAINSHIFT_BUILD_DIR:-$root/build}
bash "$root/scripts/build.sh"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# The test drivers' allocations on transparent huge pages too, as brainshift and brainshift-host
# arrange for themselves (Core/ProcessMemory.h): first touches of large images cost much less.
if [ -z "${GLIBC_TUNABLES:-}" ]; then export GLIBC_TUNABLES=glibc.malloc.hugetlb=1; fi
if command -v xvfb-run >/dev/null 2>&1; then
  xvfb-run -a ctest --test-dir "$build" -j"$(nproc)" --output-on-failure "$@"
else
  ctest --test-dir "$build" -j"$(nproc)" --output-on-failure "$@"
fi
