#!/usr/bin/env bash
# The first README command: installs the Debian packages, builds, and runs the main job,
# `brainshift demo`, on the built-in case. Output: brainshift-demo/ (or $1).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
output=${1:-$root/brainshift-demo}
bash "$root/scripts/install-dependencies.sh"
bash "$root/scripts/build.sh"
build=${BRAINSHIFT_BUILD_DIR:-$root/build}
"$build/bin/brainshift" demo --output-dir "$output"
