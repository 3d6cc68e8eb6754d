#!/usr/bin/env bash
# How much of each hard scenario's figure is the draw of the classification's prototypes: the
# product's default update (`brainshift demo --scenario NAME`, refinement "auto") run again with
# other seeds of that draw (classification.seed; 2000 is the default), and each scenario's TRE and
# boundary under the craniotomy given over the seeds: each seed's, the least, the mean, the most
# and the spread. The prototypes are a seeded random sample of each tissue's candidate voxels; a
# scenario whose figures move with the seed is judged on them all, not on the default's draw.
#
#   Testing/Benchmarks/seeds/run.sh [OUTPUT_DIR [SCENARIO...]]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/seeds; the scenarios default to all of them
# (brainshift demo --help lists them); SEEDS (default "2000 2001 2002") the seeds. Each run keeps its
# evaluation.json and report.json alone (a run's volumes take about 450 MB). Writes
# OUTPUT_DIR/machine.txt, seeds.csv, summary.md.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/seeds}
if [ $# -gt 0 ]; then shift; fi
scenarios=("$@")
read -r -a seeds <<< "${SEEDS:-2000 2001 2002}"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

ensure_matplotlib # report.py imports benchmark_common.py, which needs it
require_brainshift
scenarios_or_all
for seed in "${seeds[@]}"; do
  [[ $seed =~ ^[0-9]+$ ]] || die "SEEDS: '$seed' is not a whole number"
done
prepare_output machine.txt seeds.csv summary.md runs/
write_machine_description
mkdir -p "$out/runs"

for scenario in "${scenarios[@]}"; do
  for seed in "${seeds[@]}"; do
    folder=$out/runs/$scenario/seed-$seed
    rm -rf "$folder"
    mkdir -p "$folder"
    config=$out/runs/seed-$seed.json
    echo "{\"classification\": {\"refinement_passes\": \"auto\", \"seed\": $seed}}" > "$config"
    "$brainshift" demo --scenario "$scenario" --output-dir "$folder/demo" --config "$config" > "$folder/demo.log" 2>&1 ||
      say "$scenario, seed $seed: exit $? (see $folder/demo.log)"
    for kept in evaluation.json report.json; do
      [ -f "$folder/demo/$kept" ] && mv "$folder/demo/$kept" "$folder/$kept"
    done
    [ -f "$folder/demo/case/case.json" ] && mv "$folder/demo/case/case.json" "$folder/case.json"
    rm -rf "$folder/demo"
    say "$scenario, seed $seed done"
  done
done

run "$python" "$here/report.py" "$out"
say "done: $out/summary.md"
