#!/usr/bin/env bash
# The hard scenarios of the built-in case (brainshift demo --scenario): accuracy of the whole update
# where real surgery makes it hard (fluid and air under the craniotomy, another scanner's contrast,
# tumours resected or not, shifts of 5 to 20 mm at four sites, strong noise and bias, a misaligned
# head), against the truth of each case, beside the easy default case. Each scenario runs as:
#   once         the product's default: the classification through the rigid prior, and one refine
#                pass only where the scan's fluid is brighter than its parenchyma (refinement "auto")
#   refined      the refine stage on (classification.refinement_passes 2): it reclassifies with the
#                preoperative labels warped by the solve, and solves again
#   true-labels  the true intraoperative labels instead of the classification: the ceiling of the
#                update given a perfect segmentation (rigid, then the truth's labels, mesh, surface,
#                simulate with the images, so with block matching as by default, warp)
# and, with ELASTIX=1, elastix rigid + B-spline on the same images (update/elastix.py; ELASTIX_SCENARIOS
# limits it to the named scenarios: it takes about 70 s a case).
#
#   Testing/Benchmarks/scenarios/run.sh [OUTPUT_DIR [SCENARIO...]]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/scenarios; the scenarios default to all of
# them (brainshift demo --help lists them). Each demo builds its case anew in its run folder (the
# finite element truth's scenarios take about 30 s more for CalculiX). VARIANTS (default "once
# refined true-labels") chooses the variants; KEEP_ROWS=1 keeps the earlier table's other rows. Writes OUTPUT_DIR/machine.txt, scenarios.csv, summary.md,
# tre_vs_shift.png, tre_vs_time.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/scenarios}
if [ $# -gt 0 ]; then shift; fi
scenarios=("$@")
read -r -a variants <<< "${VARIANTS:-once refined true-labels}"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

if [ "${ELASTIX:-0}" != 0 ]; then ensure_matplotlib elastix; else ensure_matplotlib; fi
require_brainshift
scenarios_or_all
# KEEP_ROWS=1: the rows of the scenarios.csv already in OUTPUT_DIR that this run does not give (other
# variants, other scenarios, elastix) are kept in the new table (report.py --keep-rows).
# The earlier machine description stays, the kept rows having been measured then; a line under it
# says which scenarios this run measured again, when and at what load.
keep=()
previous_machine=
if [ "${KEEP_ROWS:-0}" != 0 ] && [ -f "$out/scenarios.csv" ]; then
  mkdir -p "$out/runs"
  cp "$out/scenarios.csv" "$out/runs/previous-scenarios.csv"
  keep=(--keep-rows "$(cd "$out/runs" && pwd)/previous-scenarios.csv")
  if [ -f "$out/machine.txt" ]; then
    previous_machine=$out/runs/previous-machine.txt
    cp "$out/machine.txt" "$previous_machine"
  fi
fi
prepare_output machine.txt scenarios.csv summary.md tre_vs_shift.png tre_vs_time.png
write_machine_description
if [ -n "$previous_machine" ]; then
  {
    cat "$previous_machine"
    echo "rerun on $(date -u '+%Y-%m-%d %H:%M:%S UTC') (load $(cut -d' ' -f1-3 /proc/loadavg)," \
      "variants ${variants[*]}): ${scenarios[*]}"
  } > "$out/machine.txt.new"
  mv "$out/machine.txt.new" "$out/machine.txt"
fi
mkdir -p "$out/runs"

once_config=$out/runs/once.json
refined_config=$out/runs/refined.json
echo '{"classification": {"refinement_passes": "auto"}}' > "$once_config"
echo '{"classification": {"refinement_passes": 2}}' > "$refined_config"

for scenario in "${scenarios[@]}"; do
  for variant in "${variants[@]}"; do
    folder=$out/runs/$scenario/$variant
    rm -rf "$folder"
    mkdir -p "$(dirname "$folder")"
    case $variant in
      once) "$brainshift" demo --scenario "$scenario" --output-dir "$folder" --config "$once_config" > "$folder.log" 2>&1 || say "$scenario/$variant: exit $? (see $folder.log)" ;;
      refined) "$brainshift" demo --scenario "$scenario" --output-dir "$folder" --config "$refined_config" > "$folder.log" 2>&1 || say "$scenario/$variant: exit $? (see $folder.log)" ;;
      true-labels)
        # The case of this scenario: the "once" run's (else the "refined" run's).
        case_dir=$out/runs/$scenario/once/case
        [ -f "$case_dir/case.json" ] || case_dir=$out/runs/$scenario/refined/case
        [ -f "$case_dir/case.json" ] || die "$scenario: run the variant once or refined before true-labels"
        mkdir -p "$folder"
        inputs=(--preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz"
                --intraop-image "$case_dir/intraop_image.nii.gz" --output-dir "$folder")
        {
          "$brainshift" rigid "${inputs[@]}" &&
          cp "$case_dir/truth/intraop_labels.nii.gz" "$folder/intraop_labels.nii.gz" &&
          "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$folder" &&
          "$brainshift" surface --preop-labels "$case_dir/preop_labels.nii.gz" --intraop-image "$case_dir/intraop_image.nii.gz" --output-dir "$folder" &&
          "$brainshift" simulate "${inputs[@]}" &&
          "$brainshift" warp "${inputs[@]}"
        } > "$folder.log" 2>&1 || say "$scenario/$variant: exit $? (see $folder.log)"
        "$brainshift" evaluate --transform "$folder/intraop_to_preop.h5" --landmarks "$case_dir/landmarks.csv" \
          --json "$folder/evaluation-true-labels.json" >> "$folder.log" 2>&1 || say "$scenario/$variant: no evaluation"
        ;;
      *) die "VARIANTS: unknown variant '$variant' (once, refined, true-labels)" ;;
    esac
    say "$scenario/$variant done"
  done
  if [ "${ELASTIX:-0}" != 0 ] && { [ -z "${ELASTIX_SCENARIOS:-}" ] || [[ " $ELASTIX_SCENARIOS " == *" $scenario "* ]]; }; then
    case_dir=$out/runs/$scenario/once/case
    run "$python" "$here/../update/elastix.py" "$case_dir" "$out/runs/$scenario/elastix" --csv "$out/runs/$scenario/elastix.csv"
  fi
done

run "$python" "$here/report.py" "$out" "${keep[@]}"
say "done: $out/summary.md"
