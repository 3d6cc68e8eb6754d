#!/usr/bin/env bash
# Block matching inside the brain (the simulate stage's second solve): accuracy against time over
# the number of blocks, the search radius, the rejection rounds and the matches' stiffness, one
# knob at a time around the default, beside the surface-driven solve alone, on hard scenarios of
# the built-in case. Each scenario's case is built once (`demo`, block matching off: that run is
# the surface-only point); every setting then runs `register` on the same images and is scored by
# the landmarks' TRE against the case's truth.
#
#   Testing/Benchmarks/blockmatching/run.sh [OUTPUT_DIR [SCENARIO...]]
#
# Runs of other scenarios left in OUTPUT_DIR/runs by an earlier call are reported with these.
# OUTPUT_DIR defaults to Testing/Benchmarks/results/blockmatching; the scenarios default to
# default rf20-lowfield lf20-intact-hypointense lp15-fe-sliding-intact. Writes OUTPUT_DIR/machine.txt,
# settings.csv, summary.md and tre_vs_time.png (the Pareto front of each scenario marked).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/blockmatching}
if [ $# -gt 0 ]; then shift; fi
scenarios=("$@")
[ ${#scenarios[@]} -gt 0 ] || scenarios=(default rf20-lowfield lf20-intact-hypointense lp15-fe-sliding-intact)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

ensure_matplotlib
require_brainshift
prepare_output machine.txt settings.csv summary.md tre_vs_time.png # runs/<scenario> are replaced one by one
write_machine_description
mkdir -p "$out/runs/configs"

# name -> the block_matching settings over the defaults (Resources/Configurations/default.json).
declare -A settings=(
  [surface-only]='"enabled": false'
  [default]=''
  [blocks-500]='"maximum_blocks": 500, "block_spacing_mm": 5.0'
  [blocks-1500]='"maximum_blocks": 1500, "block_spacing_mm": 5.0'
  [blocks-6000]='"maximum_blocks": 6000, "block_spacing_mm": 3.0'
  [radius-3]='"search_radius_mm": 3.0'
  [radius-10]='"search_radius_mm": 10.0'
  [rounds-0]='"rejection_rounds": 0'
  [rounds-6]='"rejection_rounds": 6'
  [rejection-1mm]='"rejection_floor_mm": 1.0, "outlier_factor": 2.5'
  [stiffness-0.03]='"stiffness_n_per_mm": 0.03'
  [stiffness-0.1]='"stiffness_n_per_mm": 0.1'
  [stiffness-0.3]='"stiffness_n_per_mm": 0.3'
  [stiffness-3]='"stiffness_n_per_mm": 3.0'
  [unsmoothed]='"smoothing_mm": 0'
  [smoothing-1mm]='"smoothing_mm": 1.0'
  [by-structure]='"selection_cell_mm": 0'
  [cells-12mm]='"selection_cell_mm": 12.0'
  [blocks-5000]='"maximum_blocks": 5000'
)
for name in "${!settings[@]}"; do
  printf '{"block_matching": {%s}}\n' "${settings[$name]}" > "$out/runs/configs/$name.json"
done

for scenario in "${scenarios[@]}"; do
  folder=$out/runs/$scenario
  rm -rf "$folder"
  mkdir -p "$folder"
  run_logged "$folder/surface-only.log" "$brainshift" demo --scenario "$scenario" --output-dir "$folder/surface-only" \
    --config "$out/runs/configs/surface-only.json"
  case_dir=$folder/surface-only/case
  for name in "${!settings[@]}"; do
    [ "$name" = surface-only ] && continue
    # A rejected update exits 1 with its files the rigid result's: scored as it is.
    "$brainshift" register --preop-image "$case_dir/preop_image.nii.gz" \
      --preop-labels "$case_dir/preop_labels.nii.gz" --intraop-image "$case_dir/intraop_image.nii.gz" \
      --overlay "fmri=$case_dir/preop_fmri.nii.gz" --output-dir "$folder/$name" --config "$out/runs/configs/$name.json" \
      > "$folder/$name.log" 2>&1 || say "$scenario/$name: exit $? (see $folder/$name.log)"
    [ -f "$folder/$name/intraop_to_preop.h5" ] || continue
    run_logged "$folder/$name.evaluate.log" "$brainshift" evaluate --transform "$folder/$name/intraop_to_preop.h5" \
      --landmarks "$case_dir/landmarks.csv" --json "$folder/$name/evaluation-landmarks.json"
  done
  say "$scenario done"
done
run "$python" "$here/report.py" "$out"
