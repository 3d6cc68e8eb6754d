#!/usr/bin/env bash
# The block matches of the hard scenarios' runs against each scenario's truth (match_error.py):
# how far off a match is, along the directions its block pins down and along those it does not,
# beside the surface-driven prediction the search started from. Reads the runs the scenario table
# left (Testing/Benchmarks/scenarios/run.sh, the "once" variant: runs/<scenario>/once with its
# block_matches.vtp and case/), so run that first; matches nothing itself.
#
#   Testing/Benchmarks/blockmatching/match_error.sh [OUTPUT_DIR [SCENARIO_RUNS_DIR]]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/blockmatching-truth, SCENARIO_RUNS_DIR to
# Testing/Benchmarks/results/scenarios/runs. Writes OUTPUT_DIR/machine.txt, match_error.csv and
# match_error.md. Installs python3-h5py, python3-nibabel, python3-scipy and python3-vtk9 with
# apt-get when Debian's Python lacks them.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/blockmatching-truth}
runs=${2:-$root/Testing/Benchmarks/results/scenarios/runs}
python=/usr/bin/python3

missing=()
for pair in h5py:python3-h5py nibabel:python3-nibabel scipy:python3-scipy vtkmodules:python3-vtk9; do
  "$python" -c "import ${pair%%:*}" >/dev/null 2>&1 || missing+=("${pair#*:}")
done
if [ ${#missing[@]} -gt 0 ]; then
  say "installing ${missing[*]}"
  sudo=()
  [ "$(id -u)" -eq 0 ] || sudo=(sudo)
  "${sudo[@]}" apt-get update
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
fi

folders=()
for folder in "$runs"/*/once; do
  [ -f "$folder/block_matches.vtp" ] && [ -f "$folder/case/truth/intraop_to_preop.h5" ] && folders+=("$folder")
done
[ ${#folders[@]} -gt 0 ] || die "no scenario runs with block matches under $runs (run Testing/Benchmarks/scenarios/run.sh first)"
prepare_output machine.txt match_error.csv match_error.md
write_machine_description
run "$python" "$here/match_error.py" "$out" "${folders[@]}"
say "done: $out/match_error.md"
