#!/usr/bin/env bash
# The README's pictures of the host, as the product is:
#   - the surgeon's view (Documentation/images/surgeon-view.png): the "Intraoperative update" module
#     through a two-scan session on the built-in case (a first scan at 5 mm of shift, then the
#     built-in 10 mm one), driven by brainshift-host's own command line, saved once the second
#     scan is shown;
#   - the expert's panels (Documentation/images/host.png): `brainshift demo` (the whole `register`
#     on the built-in case), then brainshift-host opens the scene it wrote.
#   scripts/host-screenshot.sh [OUTPUT_FOLDER]   (default Documentation/images)
# Needs the build (scripts/build.sh) and xvfb-run.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${BRAINSHIFT_BUILD_DIR:-$root/build}
output=${1:-$root/Documentation/images}
for program in brainshift brainshift-host; do
  if [ ! -x "$build/bin/$program" ]; then
    echo "host-screenshot.sh: $build/bin/$program not found; build first (scripts/build.sh)" >&2
    exit 2
  fi
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$output"
"$build/bin/brainshift" demo --output-dir "$work/demo" > "$work/demo.log"
"$build/bin/brainshift" demo --shift 5 --output-dir "$work/early" > "$work/early.log"
case_dir=$work/demo/case
xvfb-run -a -s "-screen 0 1400x900x24" \
  "$build/bin/brainshift-host" --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
  --overlay "fmri=$case_dir/preop_fmri.nii.gz" --session-dir "$work/session" \
  --scan "$work/early/case/intraop_image.nii.gz" --scan "$case_dir/intraop_image.nii.gz" \
  --screenshot "$output/surgeon-view.png"
echo "wrote $output/surgeon-view.png"
xvfb-run -a -s "-screen 0 1400x900x24" \
  "$build/bin/brainshift-host" --module "Fusion and review" --screenshot "$output/host.png" "$work/demo/scene.mrml"
echo "wrote $output/host.png"
