#!/usr/bin/env bash
# Command-line tests of brainshift on intraoperative contrasts other than T1, end to end on the
# small built-in case. Usage: ContrastCommandLineTest.sh CASE BRAINSHIFT WORKDIR
set -uo pipefail
case_name=$1
brainshift=$2
work=$3

# shellcheck source=CommandLineTestSupport.sh
source "$(dirname "${BASH_SOURCE[0]}")/CommandLineTestSupport.sh"

# flair_case NAME DEMO_OPTIONS...: runs the demo into $work/flair/NAME and checks that the rigid
# stage is trusted though its normalized mutual information is below the T1-calibrated floor of
# 1.12 that refused it before, that the update completes and is shown, and its landmark TRE.
flair_case() {
  local name=$1
  shift
  local out=$work/flair/$name
  rm -rf "$out"
  mkdir -p "$work/flair"
  "$brainshift" demo --size small "$@" --output-dir "$out" > "$work/flair-$name.log" 2>&1 ||
    { fail "$name: demo $* exited $?: $(tail -n 3 "$work/flair-$name.log")"; return; }
  local r=$out/report.json e=$out/evaluation.json
  [ "$(json_value "$out/case/case.json" "['parameters']['contrast']")" = flair ] || fail "$name: case.json: not flair"
  [ "$(json_value "$r" "['stages']['rigid']['trustworthy']")" = True ] || fail "$name: the rigid stage is not trusted"
  float_check "$r" "['stages']['rigid']['normalized_mutual_information']" "< 1.12"
  python3 - "$r" <<'PY' || fail "$name: a rigid warning: the alignment's gain over displaced poses is near its limit"
import json, sys
sys.exit(1 if any(w.startswith("rigid:") for w in json.load(open(sys.argv[1]))["warnings"]) else 0)
PY
  # The rigid result is right: the head landmarks (rigid motion only) within 1 mm.
  float_check "$e" "['transforms']['brainshift_rigid']['groups']['head']['max_mm']" "< 1.0"
  [ "$(json_value "$e" "['pipeline_complete']")" = True ] || fail "$name: the pipeline did not complete"
  # Shown: trusted, or doubtful with its reason (measured: doubtful on both small FLAIR scans since
  # the field carries the boundary across (aa2bc3f): a little worse where it moves the brain,
  # clearly better inside, the mixed-evidence rule), never rejected.
  local verdict
  verdict=$(json_value "$r" "['trust']['nonrigid']")
  [ "$verdict" = trusted ] || [ "$verdict" = doubtful ] || fail "$name: the update was $verdict"
  [ "$(json_value "$r" "['trust']['rigid_fallback']")" = False ] || fail "$name: the files hold the rigid fallback"
  # The update: measured 0.79 (rf10-flair) and 0.88 mm mean, p95 1.41 and 1.64 mm, against the
  # rigid registration's 1.84 and 1.68 mm mean (5.46 and 4.38 p95).
  local rigid_mean
  rigid_mean=$(json_value "$e" "['transforms']['brainshift_rigid']['mean_mm']")
  float_check "$e" "['transforms']['brainshift']['mean_mm']" "< 1.2"
  float_check "$e" "['transforms']['brainshift']['mean_mm']" "< 0.7 * $rigid_mean"
  float_check "$e" "['transforms']['brainshift']['p95_mm']" "< 2.3"
}

case "$case_name" in
FlairContrast)
  # A FLAIR intraoperative scan: its right rigid alignment
  # has a normalized mutual information of 1.10 to 1.11 on the small case, below the floor that T1
  # alone had set; the trust compares it with the same images' displaced poses instead.
  flair_case rf10-flair --scenario rf10-flair
  flair_case default-flair --contrast flair
  ;;

*)
  echo "unknown case $case_name" >&2
  exit 2
  ;;
esac

if [ "$failures" -ne 0 ]; then
  echo "$case_name: $failures check(s) failed" >&2
  exit 1
fi
echo "$case_name passed"
