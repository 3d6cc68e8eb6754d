#!/usr/bin/env bash
# The whole intraoperative update, speed against accuracy: `register` on the built-in case over
# mesh resolution, solver tolerance and active-surface iterations (and its variants: shift size,
# craniotomy site, no resection, at the default setting), scored by the landmarks' TRE against the
# truth; the rigid registration alone is the reference point.
#
#   Testing/Benchmarks/update/run.sh [OUTPUT_DIR [BENCH_OPTIONS...]]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/update. The brainshift binary is taken from
# $BRAINSHIFT_BUILD_DIR/bin (default build/bin). BENCH_OPTIONS go to brainshift bench update (e.g.
# --size small --no-variants). Writes into OUTPUT_DIR: machine.txt, update_bench.csv,
# summary.md and tre_vs_time.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/update}
if [ $# -gt 0 ]; then shift; fi
bench_options=("$@")

ensure_matplotlib
require_brainshift
prepare_output machine.txt update_bench.csv summary.md tre_vs_time.png
write_machine_description

run "$brainshift" bench update --output-dir "$out" "${bench_options[@]}"
[ -f "$out/update_bench.csv" ] || die "$out/update_bench.csv missing: brainshift bench update did not write it"

run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/tre_vs_time.png"
