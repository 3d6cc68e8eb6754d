#!/usr/bin/env bash
# The operating room's timeline on the full built-in case: one `brainshift watch` session, as the
# host's "Intraoperative update" module runs it (the same logic): the preparation before surgery
# (the preoperative data read and checked, the mesh, the preoperative brain boundary, the served
# finite element worker), then a first scan (5 mm of shift), a second (the built-in 10 mm case) and
# a third (15 mm), each from the image to the warped volumes and the scene, files and all. The
# three scans are the same patient's (the same seed: the same preoperative data) at growing shift.
# Repeated REPEATS times (default 3); the median of each is reported with every stage's time and each
# scan's landmark TRE against its truth (`brainshift evaluate`). Targets (issue 17): a later scan
# <= 3 s, the first <= 7 s on 2 cores.
#
#   [CONFIG=FILE] Testing/Benchmarks/session/run.sh [OUTPUT_DIR]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/session. CONFIG: a configuration file for the
# sessions (`watch --config`; machine.txt names it), to time a setting against the defaults. Writes
# machine.txt, session.csv, summary.md. Run it on a quiet machine: other work slows every figure.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/session}
repeats=${REPEATS:-3}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

ensure_matplotlib # report.py imports benchmark_common.py, which needs it
require_brainshift
config=()
if [ -n "${CONFIG:-}" ]; then
  [ -f "$CONFIG" ] || die "CONFIG=$CONFIG: no such file"
  config=(--config "$(cd "$(dirname "$CONFIG")" && pwd)/$(basename "$CONFIG")")
fi
prepare_output machine.txt session.csv summary.md runs/
write_machine_description
if [ ${#config[@]} -gt 0 ]; then echo "configuration: ${config[1]}: $(tr -s ' \n' ' ' < "${config[1]}")" >> "$out/machine.txt"; fi
mkdir -p "$out/runs"

for shift in 5 10 15; do
  run_logged "$out/runs/case-$shift.log" "$brainshift" demo --shift "$shift" --output-dir "$out/runs/case-$shift"
done
case_dir=$out/runs/case-10/case
for shift in 5 15; do
  cmp -s "$case_dir/preop_image.nii.gz" "$out/runs/case-$shift/case/preop_image.nii.gz" ||
    die "the $shift mm case has other preoperative data than the 10 mm one: not the same patient"
done
scans=$out/runs/case-5/case/intraop_image.nii.gz,$case_dir/intraop_image.nii.gz,$out/runs/case-15/case/intraop_image.nii.gz
for repeat in $(seq 1 "$repeats"); do
  session=$out/runs/session-$repeat
  run_logged "$out/runs/session-$repeat.log" "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" \
    --preop-labels "$case_dir/preop_labels.nii.gz" --overlay "fmri=$case_dir/preop_fmri.nii.gz" \
    --scans "$scans" --output-dir "$session" --overwrite ${config[@]+"${config[@]}"}
  number=1
  for shift in 5 10 15; do
    scan=$session/scan-0$number
    run_logged "$scan/evaluate.log" "$brainshift" evaluate --transform "$scan/intraop_to_preop.h5" \
      --landmarks "$out/runs/case-$shift/case/landmarks.csv" --json "$scan/landmark_tre.json"
    number=$((number + 1))
  done
done
"$python" "$here/report.py" "$out" "$repeats"
