#!/usr/bin/env bash
# The README's picture of the host, as the product is: `brainshift demo` (the whole `register` on
# the built-in case), then brainshift-host opens the scene it wrote and saves the window.
#   scripts/host-screenshot.sh [OUTPUT.png]   (default Documentation/images/host.png)
# Needs the build (scripts/build.sh) and xvfb-run.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${BRAINSHIFT_BUILD_DIR:-$root/build}
output=${1:-$root/Documentation/images/host.png}
for program in brainshift brainshift-host; do
  if [ ! -x "$build/bin/$program" ]; then
    echo "host-screenshot.sh: $build/bin/$program not found; build first (scripts/build.sh)" >&2
    exit 2
  fi
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
"$build/bin/brainshift" demo --output-dir "$work/demo" > "$work/demo.log"
mkdir -p "$(dirname "$output")"
xvfb-run -a -s "-screen 0 1400x900x24" \
  "$build/bin/brainshift-host" --module "Fusion and review" --screenshot "$output" "$work/demo/scene.mrml"
echo "wrote $output"
