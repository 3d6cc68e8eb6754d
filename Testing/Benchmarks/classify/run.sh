#!/usr/bin/env bash
# Tissue classification benchmark: BrainShift's classify stage (k-nearest-neighbour with spatial
# context) on the built-in full-size case: speed and accuracy on the default case, and Dice
# against the true intraoperative labels over a noise sweep and a bias-field sweep (N4 off/on).
#
#   Testing/Benchmarks/classify/run.sh [OUTPUT_DIR]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/classify. The brainshift binary is taken from
# $BRAINSHIFT_BUILD_DIR/bin (default build/bin), as scripts/build.sh builds it.
# Writes into OUTPUT_DIR: machine.txt, what brainshift bench classify --size full writes
# (classification_speed.json, classification_sweep.csv), and the report: summary.md,
# dice_vs_noise.png, dice_vs_bias.png.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../../.." && pwd)
build=${BRAINSHIFT_BUILD_DIR:-$root/build}
brainshift=$build/bin/brainshift
out=${1:-$root/Testing/Benchmarks/results/classify}

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

mkdir -p "$out"
out=$(cd "$out" && pwd)
# Results of an earlier run would mix with this one's.
rm -f "$out/machine.txt" "$out/classification_speed.json" "$out/classification_sweep.csv" \
  "$out/summary.md" "$out/dice_vs_noise.png" "$out/dice_vs_bias.png"

# --- the machine --------------------------------------------------------------------------------
{
  echo "date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
  echo "uname: $(uname -a)"
  echo "nproc: $(nproc)"
  echo "cpu: $(lscpu | grep 'Model name' | sed 's/^Model name:[[:space:]]*//')"
  echo "memory:"
  free -h
  "$brainshift" --version 2>&1 | head -n 1
} > "$out/machine.txt"
cat "$out/machine.txt"

run() {
  say "$*"
  "$@" || die "failed (exit status $?): $*"
}

# --- BrainShift ---------------------------------------------------------------------------------
run "$brainshift" bench classify --size full --output-dir "$out"
for f in classification_speed.json classification_sweep.csv; do
  [ -f "$out/$f" ] || die "$out/$f missing: brainshift bench classify did not write it"
done

# --- report -------------------------------------------------------------------------------------
run "$python" "$here/report.py" "$out"
say "done: $out/summary.md, $out/dice_vs_noise.png, $out/dice_vs_bias.png"
