#!/usr/bin/env bash
# Seeded fuzz run of the command line (issue 18): random corruption of the small built-in case's
# NIfTI headers, voxels and gzip streams, landmark CSVs, transforms, JSON configurations and .mrml
# scenes, each fed to the subcommand that reads it (rigid, mesh, evaluate, mesh/simulate --config,
# bench read-scene). Every run must exit 0, 1 or 2 (no crash, no signal, no hang), print exactly one
# line on stderr when it fails, leave no process of its session (the finite element worker's
# process group included), no `.tmp-*` or empty file, no output folder of a refused run, and its
# input unchanged (fuzz.py says how each input is made and checked).
#
#   Testing/Benchmarks/fuzz/run.sh [--output-dir OUT] [--seed N] [--inputs N] [--demo DIR]
#
# OUT defaults to Testing/Benchmarks/results/fuzz; N inputs (default 300) with seed 18; DIR: the output
# folder of `brainshift demo --size small` (made in a temporary folder when not given). Writes
# machine.txt, runs.csv (one row per input), summary.json and summary.md. Exit status 1 when any
# check failed. Needs python3 (standard library only).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=$root/Testing/Benchmarks/results/fuzz
seed=18 inputs=300 demo=""
while [ $# -gt 0 ]; do
  case $1 in
    --output-dir) out=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --inputs) inputs=$2; shift 2 ;;
    --demo) demo=$2; shift 2 ;;
    *) die "unknown argument $1 (see the comment at the top of run.sh)" ;;
  esac
done

require_brainshift
prepare_output machine.txt runs.csv summary.json summary.md failing-inputs/
write_machine_description
work=$(mktemp -d "${TMPDIR:-/tmp}/brainshift-fuzz.XXXXXX")
trap 'rm -rf "$work"' EXIT
trap 'exit 130' INT # the EXIT trap then runs too
trap 'exit 143' TERM
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
if [ -z "$demo" ]; then
  demo=$work/demo
  run_logged "$work/demo.log" "$brainshift" demo --size small --output-dir "$demo"
fi

say "fuzz: $inputs inputs, seed $seed"
start=$(date +%s)
status=0
python3 "$here/fuzz.py" --brainshift "$brainshift" --demo "$demo" --work "$work/inputs" --output-dir "$out" \
  --config "$root/Resources/Configurations/default.json" --seed "$seed" --inputs "$inputs" || status=$?
seconds=$(( $(date +%s) - start ))

python3 - "$out/summary.json" "$seconds" > "$out/summary.md" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
c = s["counts"]
print(f"# Fuzz run (issue 18): seed {s['seed']}, {c['inputs']} inputs, {sys.argv[2]} s\n")
print("| check | count |\n|---|---|")
for key in ["inputs", "exit_0", "exit_1", "exit_2", "crashes", "hangs", "orphans", "partial_files",
            "stderr_not_one_line", "refused_output_left", "inputs_modified"]:
    print(f"| {key} | {c[key]} |")
print("\n| kind | inputs | exit 0 | exit 1 | exit 2 | other | mean s |\n|---|---|---|---|---|---|---|")
for kind, k in s["by_kind"].items():
    print(f"| {kind} | {k['inputs']} | {k['exit_0']} | {k['exit_1']} | {k['exit_2']} | {k['other']} | {k['seconds'] / k['inputs']:.2f} |")
if s["problems"]:
    print("\n## Problems\n")
    for p in s["problems"]:
        print(f"- input {p['input']} ({p.get('kind', '')}, {p.get('mutation', '')}): {p['findings']}; stderr: {p.get('stderr', '')}")
PY
cat "$out/summary.md"
exit "$status"
