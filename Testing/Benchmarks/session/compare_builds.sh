#!/usr/bin/env bash
# Two builds of BrainShift on the same session, alternating on one machine: the three scans of
# run.sh (the built-in case at 5, 10 and 15 mm, one `brainshift watch` with the fMRI overlay), each
# build's session REPEATS times (default 3), A then B then A... so that the machine's drift over the
# hour falls on both alike. A VM's speed can wander by the hour; two builds timed an hour apart are
# not comparable, two timed this way are.
#
#   Testing/Benchmarks/session/compare_builds.sh BUILD_A_BIN BUILD_B_BIN [OUTPUT_DIR]
#
# BUILD_*_BIN: a folder holding a build's `brainshift` and `brainshift-fe-worker` (a copy of
# build/bin: the worker is found beside the command). OUTPUT_DIR (default
# Testing/Benchmarks/results/session-ab) gets machine.txt, sessions.csv (build, repeat, scan,
# pipeline seconds, each stage's, the warp's parts; each session's user / system / wall CPU seconds)
# and summary.md (the medians). The cases are made by build A.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
[ $# -ge 2 ] || die "usage: compare_builds.sh BUILD_A_BIN BUILD_B_BIN [OUTPUT_DIR]"
builds=("$(cd "$1" && pwd)" "$(cd "$2" && pwd)")
for b in "${builds[@]}"; do
  [ -x "$b/brainshift" ] && [ -x "$b/brainshift-fe-worker" ] || die "$b: no brainshift and brainshift-fe-worker there"
done
out=${3:-$root/Testing/Benchmarks/results/session-ab}
repeats=${REPEATS:-3}
[[ $repeats =~ ^[1-9][0-9]*$ ]] || die "REPEATS=$repeats: not a whole number above 0"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
ensure_matplotlib
brainshift=${builds[0]}/brainshift
prepare_output machine.txt sessions.csv summary.md runs/
write_machine_description
{ echo "build A: ${builds[0]} ($("${builds[0]}/brainshift" --version 2>&1 | head -n 1))"
  echo "build B: ${builds[1]} ($("${builds[1]}/brainshift" --version 2>&1 | head -n 1))"; } >> "$out/machine.txt"
mkdir -p "$out/runs"
for shift in 5 10 15; do
  run_logged "$out/runs/case-$shift.log" "${builds[0]}/brainshift" demo --shift "$shift" --output-dir "$out/runs/case-$shift"
done
case_dir=$out/runs/case-10/case
scans=$out/runs/case-5/case/intraop_image.nii.gz,$case_dir/intraop_image.nii.gz,$out/runs/case-15/case/intraop_image.nii.gz
echo "build,repeat,scan,pipeline_seconds,rigid,classify,surface,simulate,warp,warp_step,warp_field,warp_trust,warp_files,session_user_seconds,session_system_seconds,session_wall_seconds" > "$out/sessions.csv"
for repeat in $(seq 1 "$repeats"); do
  for index in 0 1; do
    name=$([ "$index" = 0 ] && echo A || echo B)
    session=$out/runs/session-$name-$repeat
    run_logged "$session.log" /usr/bin/time -f "%U %S %e" -o "$session.time" "${builds[$index]}/brainshift" watch \
      --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
      --overlay "fmri=$case_dir/preop_fmri.nii.gz" --scans "$scans" --output-dir "$session" --overwrite
    "$python" - "$session" "$name" "$repeat" >> "$out/sessions.csv" <<'PY'
import json, sys
session, name, repeat = sys.argv[1:4]
user, system, wall = open(session + ".time").read().split()[:3]
for scan in (1, 2, 3):
    report = json.load(open(f"{session}/scan-{scan:02d}/report.json"))
    stages = report["stages"]
    warp = stages["warp"]
    figures = [report["pipeline_wall_seconds"]] + [stages[s]["wall_seconds"] for s in ("rigid", "classify", "surface", "simulate", "warp")]
    figures += [warp["warp_seconds"], warp["field_seconds"], warp["trust_seconds"], warp["write_seconds"]]
    print(",".join([name, repeat, str(scan)] + [f"{v:.3f}" for v in figures] + [user, system, wall]))
PY
  done
done
"$python" - "$out" <<'PY'
import csv, statistics, sys
out = sys.argv[1]
rows = list(csv.DictReader(open(f"{out}/sessions.csv")))
def median(build, scan, key):
    return statistics.median(float(r[key]) for r in rows if r["build"] == build and r["scan"] == str(scan))
lines = ["# Two builds on the same session, alternating (`Testing/Benchmarks/session/compare_builds.sh`)", "",
         "Builds in `machine.txt`; medians over the repeats, seconds.", "",
         "| scan | A | B | rigid A / B | classify A / B | surface A / B | simulate A / B | warp A / B |",
         "|---|---:|---:|---|---|---|---|---|"]
for scan in (1, 2, 3):
    cells = [f"{median('A', scan, k):.2f} / {median('B', scan, k):.2f}" for k in ("rigid", "classify", "surface", "simulate", "warp")]
    lines.append(f"| {scan} | {median('A', scan, 'pipeline_seconds'):.2f} | {median('B', scan, 'pipeline_seconds'):.2f} | " + " | ".join(cells) + " |")
for build in ("A", "B"):
    sessions = sorted({(r["repeat"], r["session_user_seconds"]) for r in rows if r["build"] == build})
    lines.append("")
    lines.append(f"Build {build}: CPU user seconds per session " + ", ".join(u for _, u in sessions) + ".")
open(f"{out}/summary.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
