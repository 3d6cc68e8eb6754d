#!/usr/bin/env bash
# Finite element solve benchmark: BrainShift's simulate stage (linear elastic model on linear
# tetrahedra, solved by the PETSc/MPI worker) on a brain-sized ellipsoid phantom at several sizes,
# for the candidate solvers on 1 and 2 ranks: the "before surgery" phases (assembly, solver setup)
# and the "during surgery" solve for a new set of boundary values with everything reused, against
# the speed targets and the seed paper's 77,511 equations in under 10 s on 16 CPUs.
#
#   Testing/Benchmarks/simulate/run.sh [OUTPUT_DIR [BENCH_OPTIONS...]]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/simulate. The brainshift binary (and the
# brainshift-fe-worker beside it) is taken from $BRAINSHIFT_BUILD_DIR/bin (default build/bin), as
# scripts/build.sh builds it. BENCH_OPTIONS go to brainshift bench simulate as they are, e.g.
# --equations 20000,77511 --ranks 1,2 --solvers cg+gamg,cg+hypre (default: all sizes, ranks and
# solvers; the full run takes a long time).
# Writes into OUTPUT_DIR: machine.txt, what brainshift bench simulate writes (simulate_bench.csv),
# and the report: summary.md, time_vs_size.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# root, build, brainshift; say, die, run, ensure_matplotlib, require_brainshift, prepare_output,
# write_machine_description.
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
worker=$build/bin/brainshift-fe-worker
out=${1:-$root/Testing/Benchmarks/results/simulate}
if [ $# -gt 0 ]; then shift; fi
bench_options=("$@")

# --- what the benchmark needs -------------------------------------------------------------------
ensure_matplotlib
require_brainshift
[ -x "$worker" ] ||
  die "$worker not found: BrainShift was built without PETSc (scripts/install-dependencies.sh)"
command -v mpiexec >/dev/null 2>&1 ||
  die "mpiexec not found: the finite element worker runs under MPI"

prepare_output machine.txt simulate_bench.csv summary.md time_vs_size.png

# --- the machine --------------------------------------------------------------------------------
mpi_versions() {
  echo "mpiexec: $(mpiexec --version 2>&1 | head -n 1)"
  echo "PETSc: $(pkg-config --modversion PETSc 2>/dev/null || echo unknown)"
}
write_machine_description mpi_versions

# --- BrainShift ---------------------------------------------------------------------------------
run "$brainshift" bench simulate --output-dir "$out" ${bench_options[@]+"${bench_options[@]}"}
[ -f "$out/simulate_bench.csv" ] ||
  die "$out/simulate_bench.csv missing: brainshift bench simulate did not write it"

# --- report -------------------------------------------------------------------------------------
run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/time_vs_size.png"
