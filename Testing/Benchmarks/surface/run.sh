#!/usr/bin/env bash
# Active surface benchmark: the displacement of the brain surface against the built-in case's
# truth, where it fails (shift size 2 to 20 mm, with the true and with the classified intraoperative
# brain as the target; brain masks corrupted by a smooth random boundary error of 0 to 6 mm), for the
# segmentation alone, the image-guarded default and the image-refined variant, and the stage's speed.
#
#   Testing/Benchmarks/surface/run.sh [OUTPUT_DIR [BENCH_OPTIONS...]]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/surface. The brainshift binary is taken from
# $BRAINSHIFT_BUILD_DIR/bin (default build/bin). BENCH_OPTIONS go to brainshift bench surface as
# they are (e.g. --size small --shifts 5,10). Writes into OUTPUT_DIR: machine.txt,
# surface_sweep.csv and surface_speed.json (brainshift bench surface), summary.md,
# error_vs_shift.png and error_vs_corruption.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/surface}
if [ $# -gt 0 ]; then shift; fi
bench_options=("$@")

ensure_matplotlib
require_brainshift
prepare_output machine.txt surface_sweep.csv surface_speed.json summary.md error_vs_shift.png error_vs_corruption.png
write_machine_description

run "$brainshift" bench surface --output-dir "$out" "${bench_options[@]}"
[ -f "$out/surface_sweep.csv" ] || die "$out/surface_sweep.csv missing: brainshift bench surface did not write it"

run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/error_vs_shift.png, $out/error_vs_corruption.png"
