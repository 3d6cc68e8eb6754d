#!/usr/bin/env bash
# Tissue classification benchmark: BrainShift's classify stage (k-nearest-neighbour with spatial
# context) on the built-in full-size case: speed and accuracy on the default case, and Dice
# against the true intraoperative labels over a noise sweep and a bias-field sweep (N4 off/on).
#
#   Testing/Benchmarks/classify/run.sh [OUTPUT_DIR]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/classify. The brainshift binary is taken from
# $BRAINSHIFT_BUILD_DIR/bin (default build/bin), as scripts/build.sh builds it.
# Writes into OUTPUT_DIR: machine.txt, what brainshift bench classify --size full writes
# (classification_speed.json, classification_sweep.csv), and the report: summary.md,
# dice_vs_noise.png, dice_vs_bias.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# root, build, brainshift; say, die, run, ensure_matplotlib, require_brainshift, prepare_output,
# write_machine_description.
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/classify}

# --- what the benchmark needs -------------------------------------------------------------------
ensure_matplotlib
require_brainshift

prepare_output machine.txt classification_speed.json classification_sweep.csv summary.md \
  dice_vs_noise.png dice_vs_bias.png

# --- the machine --------------------------------------------------------------------------------
write_machine_description

# --- BrainShift ---------------------------------------------------------------------------------
run "$brainshift" bench classify --size full --output-dir "$out"
for f in classification_speed.json classification_sweep.csv; do
  [ -f "$out/$f" ] || die "$out/$f missing: brainshift bench classify did not write it"
done

# --- report -------------------------------------------------------------------------------------
run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/dice_vs_noise.png, $out/dice_vs_bias.png"
