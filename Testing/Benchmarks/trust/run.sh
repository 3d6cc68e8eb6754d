#!/usr/bin/env bash
# Trust assessment benchmark: does the warp stage reject every non-rigid update that is worse than
# the rigid registration alone, and accept those that are better? Built-in cases (shift, craniotomy,
# resection, noise, bias varied) are registered as they are, with the true intraoperative labels,
# and with deliberately damaged segmentations given to the surface stage (the brain moved 8 mm,
# eroded 5 mm, dilated 5 mm, the brain of the same case without shift (the sunken brain filled in),
# the brain of a case opened elsewhere). Every run is scored by landmark TRE against the truth:
# the update's (the one set aside when rejected) against the rigid transform's.
#
#   Testing/Benchmarks/trust/run.sh [OUTPUT_DIR [SIZE...]]
#   SMALL_CASES="default:;t2:--contrast t2 --gap fluid-and-air" Testing/Benchmarks/trust/run.sh DIR small
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/trust; SIZEs default to "small full" (the full
# size runs a subset of the cases). Writes machine.txt, runs.csv (one row per run) and summary.md
# (the confusion table). Needs /usr/bin/python3 with numpy and scipy (python3-numpy, python3-scipy).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/trust}
if [ $# -gt 0 ]; then shift; fi
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(small full)

python=/usr/bin/python3
"$python" -c 'import numpy, scipy.ndimage' 2>/dev/null || die "$python cannot import numpy and scipy (apt-get install python3-numpy python3-scipy)"
require_brainshift
prepare_output machine.txt runs.csv summary.md
write_machine_description
work=$(mktemp -d "${TMPDIR:-/tmp}/brainshift-trust.XXXXXX")
trap 'rm -rf "$work"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

# score FOLDER CASE_DIR SIZE CASE VARIANT STATUS: one row of runs.csv.
score() {
  local folder=$1 case_dir=$2 update=$1/intraop_to_preop.h5
  [ -f "$folder/rejected_intraop_to_preop.h5" ] && update=$folder/rejected_intraop_to_preop.h5
  if [ -f "$update" ] && [ -f "$folder/report.json" ] && grep -q '"trust"' "$folder/report.json"; then
    "$brainshift" evaluate --transform "$update" --landmarks "$case_dir/landmarks.csv" --json "$folder/update_tre.json" >/dev/null
    "$brainshift" evaluate --transform "$folder/rigid_intraop_to_preop.tfm" --landmarks "$case_dir/landmarks.csv" \
      --json "$folder/rigid_tre.json" >/dev/null
  fi
  "$python" "$here/record.py" "$out/runs.csv" "$folder" "$3" "$4" "$5" "$6"
}

# damaged SIZE CASE VARIANT LABELS: the case's rigid result and mesh, LABELS as the segmentation,
# then surface, simulate and warp.
damaged() {
  local size=$1 name=$2 variant=$3 labels=$4 base=$work/$1-$2 folder=$work/$1-$2-$3 status=0
  local case_dir=$base/case
  local inputs=(--preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz"
    --intraop-image "$case_dir/intraop_image.nii.gz")
  mkdir -p "$folder"
  cp "$base/rigid_intraop_to_preop.tfm" "$base/mesh.vtu" "$folder/"
  cp "$labels" "$folder/intraop_labels.nii.gz"
  {
    "$brainshift" surface --preop-labels "$case_dir/preop_labels.nii.gz" --intraop-image "$case_dir/intraop_image.nii.gz" \
      --output-dir "$folder" &&
      "$brainshift" simulate "${inputs[@]}" --output-dir "$folder" &&
      "$brainshift" warp "${inputs[@]}" --output-dir "$folder"
  } > "$folder/log.txt" 2>&1 || status=$?
  score "$folder" "$case_dir" "$size" "$name" "$variant" "$status"
}

damage() { "$python" "$here/damage_labels.py" "$@" >/dev/null; }

for size in "${sizes[@]}"; do
  # name: demo options. Every case shares the head's motion and the intraoperative grid, so one
  # case's labels fit another's grid.
  if [ "$size" = small ] && [ -n "${SMALL_CASES:-}" ]; then
    IFS=';' read -r -a cases <<< "$SMALL_CASES" # e.g. "default:;t2:--contrast t2 --gap fluid-and-air"
  elif [ "$size" = small ]; then
    cases=("default:" "shift3:--shift 3" "shift5:--shift 5" "shift15:--shift 15" "leftpar:--craniotomy left-parietal"
      "vertex-noresect:--craniotomy vertex --no-resection" "noise10:--noise 0.10" "noise25:--noise 0.25"
      "bias50:--bias 0.5" "seed7:--seed 7 --shift 8" "t2:--contrast t2 --gap fluid-and-air" "t2-dark-gap:--contrast t2"
      "flair:--contrast flair --gap fluid-and-air" "t1-post-contrast:--contrast t1-post-contrast --gap fluid-and-air")
  else
    cases=("default:" "shift5:--shift 5")
  fi
  say "$size: the same case without shift, and opened elsewhere (their segmentations are the wrong ones)"
  "$brainshift" demo --size "$size" --shift 0 --output-dir "$work/$size-noshift" > "$work/$size-noshift.log" 2>&1 || true
  "$brainshift" demo --size "$size" --craniotomy left-frontal --output-dir "$work/$size-elsewhere-lf" > "$work/$size-elsewhere-lf.log" 2>&1 || true
  "$brainshift" demo --size "$size" --craniotomy right-parietal --output-dir "$work/$size-elsewhere-rp" > "$work/$size-elsewhere-rp.log" 2>&1 || true
  for entry in "${cases[@]}"; do
    name=${entry%%:*}
    read -r -a options <<< "${entry#*:}"
    base=$work/$size-$name
    say "$size $name: ${options[*]:-(defaults)}"
    status=0
    "$brainshift" demo --size "$size" "${options[@]}" --output-dir "$base" > "$base.log" 2>&1 || status=$?
    score "$base" "$base/case" "$size" "$name" classified "$status"
    labels=$base/intraop_labels.nii.gz
    [ -f "$labels" ] || continue
    damaged "$size" "$name" truth-labels "$base/case/truth/intraop_labels.nii.gz"
    damage "$labels" "$work/l.nii.gz" shift 8 0 0 && damaged "$size" "$name" moved-8mm-x "$work/l.nii.gz"
    damage "$labels" "$work/l.nii.gz" shift 0 0 8 && damaged "$size" "$name" moved-8mm-z "$work/l.nii.gz"
    damage "$labels" "$work/l.nii.gz" shift 4 0 0 && damaged "$size" "$name" moved-4mm-x "$work/l.nii.gz"
    damage "$labels" "$work/l.nii.gz" erode 5 && damaged "$size" "$name" eroded-5mm "$work/l.nii.gz"
    damage "$labels" "$work/l.nii.gz" dilate 5 && damaged "$size" "$name" dilated-5mm "$work/l.nii.gz"
    [ -f "$work/$size-noshift/intraop_labels.nii.gz" ] &&
      damaged "$size" "$name" unshifted-brain "$work/$size-noshift/intraop_labels.nii.gz"
    elsewhere=$work/$size-elsewhere-lf
    [ "$name" = leftpar ] || [ "$name" = vertex-noresect ] || elsewhere=$work/$size-elsewhere-rp
    [ -f "$elsewhere/intraop_labels.nii.gz" ] &&
      damaged "$size" "$name" opened-elsewhere "$elsewhere/intraop_labels.nii.gz"
  done
done

run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/runs.csv"
