#!/usr/bin/env bash
# Rigid registration benchmark: BrainShift's rigid stage on the built-in case (accuracy and speed
# on the full-size case, capture range on the small case) against elastix 5 on the same images.
#
#   Testing/Benchmarks/rigid/run.sh [OUTPUT_DIR]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/rigid. The brainshift binary is taken from
# $BRAINSHIFT_BUILD_DIR/bin (default build/bin), as scripts/build.sh builds it.
# Writes into OUTPUT_DIR: machine.txt, full/ (brainshift bench rigid --size full, then elastix's
# result: elastix/, elastix.tfm, elastix_evaluation.json, truth_evaluation.json,
# elastix_accuracy.json), capture/ (brainshift bench rigid --size small --capture-range), and
# the report: summary.md, capture_range.md, capture_range.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# root, build, brainshift; say, die, run, ensure_matplotlib, require_brainshift, prepare_output,
# write_machine_description.
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/rigid}

# --- what the benchmark needs -------------------------------------------------------------------
ensure_matplotlib elastix
require_brainshift

prepare_output full/ capture/ machine.txt summary.md capture_range.md capture_range.png

# --- the machine --------------------------------------------------------------------------------
elastix_version() { elastix --version 2>&1 | head -n 1; }
write_machine_description elastix_version

# --- BrainShift ---------------------------------------------------------------------------------
run "$brainshift" bench rigid --size full --output-dir "$out/full"
run "$brainshift" bench rigid --size small --capture-range --output-dir "$out/capture"

# --- elastix on the same full-size case ---------------------------------------------------------
case_dir=$out/full/case
for f in intraop_image.nii.gz preop_image.nii.gz landmarks.csv truth/rigid_intraop_to_preop.tfm; do
  [ -f "$case_dir/$f" ] || die "$case_dir/$f missing: brainshift bench rigid did not write the case"
done
# As many timed runs as BrainShift's (the result is deterministic: fixed random seed).
runs=$("$python" -c 'import json, sys; print(int(json.load(open(sys.argv[1])).get("runs", 3)))' \
  "$out/full/rigid_accuracy.json")
[ "$runs" -ge 1 ] || runs=1
seconds=()
for ((i = 1; i <= runs; i++)); do
  elx=$out/full/elastix
  rm -rf "$elx"
  mkdir -p "$elx"
  say "elastix run $i of $runs"
  start=$(date +%s.%N)
  elastix -f "$case_dir/intraop_image.nii.gz" -m "$case_dir/preop_image.nii.gz" \
    -p "$here/elastix_rigid.txt" -out "$elx" > "$elx/stdout.txt" 2>&1 \
    || die "elastix failed; see $elx/stdout.txt and $elx/elastix.log"
  end=$(date +%s.%N)
  seconds+=("$("$python" -c 'import sys; print(f"{float(sys.argv[2]) - float(sys.argv[1]):.3f}")' "$start" "$end")")
  say "elastix: ${seconds[-1]} s"
done
run "$python" "$here/elastix_result.py" convert "$elx/TransformParameters.0.txt" "$out/full/elastix.tfm"
run_logged "$out/full/elastix_evaluation.txt" "$brainshift" evaluate --transform "$out/full/elastix.tfm" \
  --landmarks "$case_dir/landmarks.csv" --json "$out/full/elastix_evaluation.json"
run_logged "$out/full/truth_evaluation.txt" "$brainshift" evaluate \
  --transform "$case_dir/truth/rigid_intraop_to_preop.tfm" \
  --landmarks "$case_dir/landmarks.csv" --json "$out/full/truth_evaluation.json"
run "$python" "$here/elastix_result.py" compare --transform "$out/full/elastix.tfm" \
  --truth "$case_dir/truth/rigid_intraop_to_preop.tfm" --evaluation "$out/full/elastix_evaluation.json" \
  --wall-seconds "${seconds[@]}" --json "$out/full/elastix_accuracy.json"

# --- report -------------------------------------------------------------------------------------
run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/capture_range.md, $out/capture_range.png"
