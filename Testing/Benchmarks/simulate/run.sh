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
root=$(cd "$here/../../.." && pwd)
build=${BRAINSHIFT_BUILD_DIR:-$root/build}
brainshift=$build/bin/brainshift
worker=$build/bin/brainshift-fe-worker
out=${1:-$root/Testing/Benchmarks/results/simulate}
if [ $# -gt 0 ]; then shift; fi
bench_options=("$@")

say() { printf '== %s\n' "$*"; }
die() { printf 'run.sh: %s\n' "$*" >&2; exit 1; }

# --- what the benchmark needs -------------------------------------------------------------------
# The Python that has matplotlib: python3 on PATH if it does, else Debian's (python3-matplotlib
# installs into /usr/bin/python3, which a pyenv or virtualenv python3 on PATH does not see).
missing=()
python=python3
if ! python3 -c 'import matplotlib' >/dev/null 2>&1; then
  python=/usr/bin/python3
  "$python" -c 'import matplotlib' >/dev/null 2>&1 || missing+=(python3-matplotlib)
fi
if [ ${#missing[@]} -gt 0 ]; then
  say "installing ${missing[*]}"
  sudo=()
  [ "$(id -u)" -eq 0 ] || sudo=(sudo)
  "${sudo[@]}" apt-get update
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
fi
"$python" -c 'import matplotlib' >/dev/null 2>&1 || die "$python cannot import matplotlib"
[ -x "$brainshift" ] || die "$brainshift not found: build BrainShift first with scripts/build.sh"
[ -x "$worker" ] ||
  die "$worker not found: BrainShift was built without PETSc (scripts/install-dependencies.sh)"
command -v mpiexec >/dev/null 2>&1 ||
  die "mpiexec not found: the finite element worker runs under MPI"

mkdir -p "$out"
out=$(cd "$out" && pwd)
# Results of an earlier run would mix with this one's.
rm -f "$out/machine.txt" "$out/simulate_bench.csv" "$out/summary.md" "$out/time_vs_size.png"

# --- the machine --------------------------------------------------------------------------------
{
  echo "date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
  echo "uname: $(uname -a)"
  echo "nproc: $(nproc)"
  echo "cpu: $(lscpu | grep 'Model name' | sed 's/^Model name:[[:space:]]*//')"
  echo "memory:"
  free -h
  echo "mpiexec: $(mpiexec --version 2>&1 | head -n 1)"
  echo "PETSc: $(pkg-config --modversion PETSc 2>/dev/null || echo unknown)"
  "$brainshift" --version 2>&1 | head -n 1
} > "$out/machine.txt"
cat "$out/machine.txt"

run() {
  say "$*"
  "$@" || die "failed (exit status $?): $*"
}

# --- BrainShift ---------------------------------------------------------------------------------
run "$brainshift" bench simulate --output-dir "$out" ${bench_options[@]+"${bench_options[@]}"}
[ -f "$out/simulate_bench.csv" ] ||
  die "$out/simulate_bench.csv missing: brainshift bench simulate did not write it"

# --- report -------------------------------------------------------------------------------------
run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/time_vs_size.png"
