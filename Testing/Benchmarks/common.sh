# shellcheck shell=bash
# What the benchmarks' run.sh share; each sources it right after `set -euo pipefail`:
#
#   here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
#   # shellcheck source=SCRIPTDIR/../common.sh
#   source "$here/../common.sh"
#
# It sets root (the source tree), build ($BRAINSHIFT_BUILD_DIR, default build/) and brainshift
# (the binary in $build/bin, as scripts/build.sh builds it), and defines the functions below.
# Functions that write results use out, the run.sh's output folder.

# Used by the run.sh that source this file, not here.
# shellcheck disable=SC2034
{
  root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
  build=${BRAINSHIFT_BUILD_DIR:-$root/build}
  brainshift=$build/bin/brainshift
}

say() { printf '== %s\n' "$*"; }
die() { printf 'run.sh: %s\n' "$*" >&2; exit 1; }

# run COMMAND...: says the command, runs it, and stops the benchmark if it fails.
run() {
  say "$*"
  "$@" || die "failed (exit status $?): $*"
}

# run_logged LOG COMMAND...: the command's output goes to LOG.
run_logged() {
  local log=$1
  shift
  say "$* > $log"
  "$@" > "$log" 2>&1 || { cat "$log" >&2; die "failed (exit status $?): $*"; }
}

# --- what the benchmark needs -------------------------------------------------------------------
# pick_python: sets python to the Python that has matplotlib: python3 on PATH if it does, else
# Debian's (python3-matplotlib installs into /usr/bin/python3, which a pyenv or virtualenv python3
# on PATH does not see). Fails when neither can import matplotlib (python is then
# /usr/bin/python3, where apt-get installs it).
pick_python() {
  python=python3
  if ! python3 -c 'import matplotlib' >/dev/null 2>&1; then
    python=/usr/bin/python3
    "$python" -c 'import matplotlib' >/dev/null 2>&1 || return 1
  fi
}

# ensure_matplotlib [COMMAND...]: sets python (pick_python) and installs with apt-get (with sudo
# when not root) python3-matplotlib when no Python can import it, along with each COMMAND that is
# not on PATH (a Debian package of the same name); then stops the benchmark if a COMMAND or
# matplotlib is still missing.
# Its arguments are optional.
# shellcheck disable=SC2120
ensure_matplotlib() {
  local missing=() command
  for command in "$@"; do
    command -v "$command" >/dev/null 2>&1 || missing+=("$command")
  done
  pick_python || missing+=(python3-matplotlib)
  if [ ${#missing[@]} -gt 0 ]; then
    say "installing ${missing[*]}"
    local sudo=()
    [ "$(id -u)" -eq 0 ] || sudo=(sudo)
    "${sudo[@]}" apt-get update
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
  fi
  for command in "$@"; do
    command -v "$command" >/dev/null 2>&1 || die "$command not found after installing it"
  done
  "$python" -c 'import matplotlib' >/dev/null 2>&1 || die "$python cannot import matplotlib"
}

# require_brainshift: stops the benchmark when the brainshift binary is not built.
require_brainshift() {
  [ -x "$brainshift" ] || die "$brainshift not found: build BrainShift first with scripts/build.sh"
}

# scenarios_or_all: the array `scenarios` as the caller named them, else every scenario
# `brainshift demo --help` lists; stops the benchmark when there is none.
scenarios_or_all() {
  if [ ${#scenarios[@]} -eq 0 ]; then
    mapfile -t scenarios < <("$brainshift" demo --help | sed -n 's/.*--scenario TEXT=default.*values): //p' | tr ',' '\n' | tr -d ' ')
  fi
  [ ${#scenarios[@]} -gt 0 ] || die "no scenario named and none listed by brainshift demo --help"
}

# --- the output folder --------------------------------------------------------------------------
# prepare_output ENTRY...: creates out, makes it absolute, and removes the ENTRYs (names in out; a
# folder written with a trailing /) left by an earlier run, whose results would mix with this one's.
prepare_output() {
  mkdir -p "$out"
  out=$(cd "$out" && pwd)
  local entry folders=() files=()
  for entry in "$@"; do
    case $entry in
      */) folders+=("$out/${entry%/}") ;;
      *) files+=("$out/$entry") ;;
    esac
  done
  if [ ${#folders[@]} -gt 0 ]; then rm -rf "${folders[@]}"; fi
  if [ ${#files[@]} -gt 0 ]; then rm -f "${files[@]}"; fi
}

# write_machine_description [COMMAND [ARG...]]: writes out/machine.txt (date, kernel, CPUs,
# memory, then what COMMAND prints, e.g. the versions of other tools, then brainshift's version)
# and shows it.
# Its arguments are optional.
# shellcheck disable=SC2120
write_machine_description() {
  {
    echo "date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
    echo "uname: $(uname -a)"
    echo "nproc: $(nproc)"
    echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg) (1, 5, 15 min; other work on the machine slows the timings)"
    echo "cpu: $(lscpu | grep 'Model name' | sed 's/^Model name:[[:space:]]*//')"
    echo "memory:"
    free -h
    echo "transparent huge pages: $(cat /sys/kernel/mm/transparent_hugepage/enabled 2>/dev/null || echo unknown);" \
      "GLIBC_TUNABLES: ${GLIBC_TUNABLES:-unset (brainshift sets glibc.malloc.hugetlb=1 for itself)}"
    if [ $# -gt 0 ]; then "$@"; fi
    "$brainshift" --version 2>&1 | head -n 1
  } > "$out/machine.txt"
  cat "$out/machine.txt"
}
