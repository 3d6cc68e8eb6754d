#!/usr/bin/env bash
# The whole intraoperative update, speed against accuracy: `register` on the built-in case over
# mesh resolution, solver tolerance and active-surface iterations (and its variants: shift size,
# craniotomy site, no resection, at the default setting), scored by the landmarks' TRE against the
# truth; the rigid registration alone is the reference point. Then elastix 5, rigid and rigid plus
# B-spline (update/elastix/*.txt), on the same images of each case, scored the same way
# (update/elastix.py): the registration a user would otherwise pick.
#
#   Testing/Benchmarks/update/run.sh [--no-elastix] [OUTPUT_DIR [BENCH_OPTIONS...]]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/update. The brainshift binary is taken from
# $BRAINSHIFT_BUILD_DIR/bin (default build/bin). BENCH_OPTIONS go to brainshift bench update (e.g.
# --size small --no-variants). --no-elastix (or ELASTIX=0) skips the elastix comparison;
# ELASTIX_CASES (names of cases, space-separated, e.g. "default") limits it to those cases (default:
# every case folder under OUTPUT_DIR/runs/). elastix and transformix (Debian's elastix) are
# installed with apt-get when missing. Writes into OUTPUT_DIR: machine.txt, update_bench.csv (with
# the rows "elastix rigid" and "elastix rigid+bspline" of each case), runs/<case>/case/ (the
# inputs) and runs/<case>/elastix/ (elastix's logs and transforms, elastix_result.json),
# summary.md and tre_vs_time.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
elastix=${ELASTIX:-1}
arguments=()
for argument in "$@"; do
  if [ "$argument" = --no-elastix ]; then elastix=0; else arguments+=("$argument"); fi
done
set -- ${arguments[@]+"${arguments[@]}"}
out=${1:-$root/Testing/Benchmarks/results/update}
if [ $# -gt 0 ]; then shift; fi
bench_options=("$@")

# --- what the benchmark needs -------------------------------------------------------------------
if [ "$elastix" != 0 ]; then
  command -v elastix >/dev/null 2>&1 || say "elastix not found: installing Debian's elastix (apt-get install elastix); --no-elastix or ELASTIX=0 skips the comparison"
  ensure_matplotlib elastix
  command -v transformix >/dev/null 2>&1 \
    || die "transformix not found: it comes with elastix (apt-get install elastix); --no-elastix or ELASTIX=0 skips the comparison"
else
  ensure_matplotlib
fi
require_brainshift
prepare_output machine.txt update_bench.csv summary.md tre_vs_time.png

# --- the machine --------------------------------------------------------------------------------
elastix_version() { if [ "$elastix" != 0 ]; then elastix --version 2>&1 | head -n 1; fi; }
write_machine_description elastix_version

# --- BrainShift ---------------------------------------------------------------------------------
run "$brainshift" bench update --output-dir "$out" "${bench_options[@]}"
[ -f "$out/update_bench.csv" ] || die "$out/update_bench.csv missing: brainshift bench update did not write it"

# --- elastix on the same images -----------------------------------------------------------------
# One case at a time, each elastix call on 2 threads (-threads 2); the rows go into update_bench.csv.
if [ "$elastix" != 0 ]; then
  cases=()
  if [ -n "${ELASTIX_CASES:-}" ]; then
    for name in $ELASTIX_CASES; do
      [ -d "$out/runs/$name/case" ] || die "ELASTIX_CASES: $out/runs/$name/case missing (no such case)"
      cases+=("$out/runs/$name/case")
    done
  else
    for case_dir in "$out"/runs/*/case; do
      if [ -d "$case_dir" ]; then cases+=("$case_dir"); fi
    done
  fi
  [ ${#cases[@]} -gt 0 ] || die "no case folder under $out/runs/: brainshift bench update did not keep the cases' inputs"
  for case_dir in "${cases[@]}"; do
    run "$python" "$here/elastix.py" "$case_dir" "$(dirname "$case_dir")/elastix" --csv "$out/update_bench.csv"
  done
else
  say "elastix comparison skipped (--no-elastix or ELASTIX=0)"
fi

# --- report -------------------------------------------------------------------------------------
run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/tre_vs_time.png"
