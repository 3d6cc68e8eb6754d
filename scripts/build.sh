#!/usr/bin/env bash
# Configures (Ninja, Release, ccache) and builds BrainShift into build/ (or $BRAINSHIFT_BUILD_DIR).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${BRAINSHIFT_BUILD_DIR:-$root/build}
if [ ! -f "$build/build.ninja" ]; then
  cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release
fi
cmake --build "$build" -- -j"$(nproc)"
