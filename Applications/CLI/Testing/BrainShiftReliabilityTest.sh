#!/usr/bin/env bash
# Reliability of the brainshift command line (issue 18): nothing lost, nothing orphaned, no silent
# wrong answer. Faults that need no root: a file-size limit for a full disk, a read-only folder (an
# unprivileged user when run as root), signals at chosen moments, concurrent runs.
# Usage: BrainShiftReliabilityTest.sh CASE BRAINSHIFT WORKDIR; WORKDIR/demo holds the small case
# (the DemoSmallCase fixture of the command-line tests).
set -uo pipefail
case_name=$1
brainshift=$2
work=$3
demo=$work/demo
case_dir=$demo/case
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

# shellcheck source=CommandLineTestSupport.sh
source "$(dirname "${BASH_SOURCE[0]}")/CommandLineTestSupport.sh"

live_in_session() { # SID: the processes of the session still running (zombies left to their reaper excluded)
  ps -eo sid=,stat=,pid= | awk -v sid="$1" '$1 == sid && $2 !~ /^Z/ { print $3 }'
}

no_temporaries() { # FOLDER...: no partial file of a run left
  local left
  left=$(find "$@" -name '.tmp-*' 2>/dev/null)
  [ -z "$left" ] || fail "temporary files left: $left"
}

# A folder with the mesh and surface of the small case: simulate's inputs.
simulate_folder() {
  rm -rf "$1" && mkdir -p "$1"
  cp "$demo/mesh.vtu" "$demo/brain_surface.vtp" "$1/"
}

P=$case_dir/preop_image.nii.gz L=$case_dir/preop_labels.nii.gz I=$case_dir/intraop_image.nii.gz

case "$case_name" in
SolveTrueResidual)
  # Richardson stopped after 3 iterations reports "converged" (KSP reason 4) 300 times off the
  # tolerance: a method failure, and the good mesh.vtu stays.
  out=$work/reliability-residual
  simulate_folder "$out"
  "$brainshift" simulate --output-dir "$out" >/dev/null || fail "simulate with the default solver exited $?"
  cp "$out/mesh.vtu" "$out.before"
  expect 1 "does not satisfy the equations" -- "$brainshift" simulate --output-dir "$out" \
    --solver-options "-ksp_type richardson -ksp_max_it 3"
  cmp -s "$out/mesh.vtu" "$out.before" || fail "a failed solve replaced mesh.vtu"
  no_temporaries "$out"
  ;;

SolverOptionsRefused)
  out=$work/reliability-options
  simulate_folder "$out"
  expect 2 "-ksp_typo" -- "$brainshift" simulate --output-dir "$out" --solver-options "-ksp_typo cg"
  expect 2 "garbage" -- "$brainshift" simulate --output-dir "$out" --solver-options "garbage -ksp_rtol 1e-6"
  expect 2 "-ksp_rtol -1" -- "$brainshift" simulate --output-dir "$out" --solver-options "-ksp_rtol -1"
  expect 2 "-ksp_max_it -5" -- "$brainshift" simulate --output-dir "$out" --solver-options "-ksp_max_it -5"
  # Options PETSc reads (the paper's solver, a monitor) still pass.
  "$brainshift" simulate --output-dir "$out" --solver-options "-ksp_type gmres -pc_type bjacobi -ksp_rtol 1e-6" >/dev/null ||
    fail "valid solver options were refused"
  ;;

MaterialRanges)
  out=$work/reliability-materials
  simulate_folder "$out"
  printf '{"materials": {"2": {"youngs_modulus_pa": 1e300}}}' > "$out/huge.json"
  printf '{"materials": {"2": {"youngs_modulus_pa": 1e-300}}}' > "$out/tiny.json"
  printf '{"materials": {"2": {"poisson_ratio": 0.4999}}}' > "$out/locking.json"
  expect 2 "$out/huge.json: materials.2.youngs_modulus_pa" -- "$brainshift" simulate --output-dir "$out" --config "$out/huge.json"
  expect 2 "outside the physical range" -- "$brainshift" simulate --output-dir "$out" --config "$out/tiny.json"
  expect 2 "lock volumetrically" -- "$brainshift" simulate --output-dir "$out" --config "$out/locking.json"
  ;;

UnknownLabelValues)
  out=$work/reliability-labels
  rm -rf "$out" && mkdir -p "$out/inputs"
  # The small case's labels (uint8 NIfTI) with 50 parenchyma voxels set to 255.
  python3 - "$L" "$out/inputs/labels-255.nii.gz" <<'PY'
import gzip, struct, sys
data = bytearray(gzip.open(sys.argv[1]).read())
offset = int(struct.unpack_from('<f', data, 108)[0])
assert struct.unpack_from('<h', data, 70)[0] == 2, 'uint8 labels expected'
changed = 0
for i in range(offset, len(data)):
    if data[i] == 2 and changed < 50:
        data[i] = 255
        changed += 1
gzip.open(sys.argv[2], 'wb').write(bytes(data))
PY
  expect 2 "labels-255.nii.gz: label values 255 (50 voxels)" -- "$brainshift" register --preop-image "$P" \
    --preop-labels "$out/inputs/labels-255.nii.gz" --intraop-image "$I" --output-dir "$out/register"
  expect 2 "label values 255" -- "$brainshift" mesh --preop-labels "$out/inputs/labels-255.nii.gz" --output-dir "$out/mesh"
  [ -e "$out/register" ] && fail "a refused register left $out/register behind"
  # A label the configuration adds is a label of the case.
  printf '{"materials": {"255": {"youngs_modulus_pa": 3000, "poisson_ratio": 0.45}}, "mesh": {"labels": [2, 3, 4]}}' > "$out/inputs/extra.json"
  "$brainshift" mesh --preop-labels "$out/inputs/labels-255.nii.gz" --output-dir "$out/mesh" --config "$out/inputs/extra.json" \
    >/dev/null || fail "a label the configuration adds was refused"
  ;;

FileSizeLimit)
  # A disk that fills during the write: the mesh (1.4 MB) under a 500 KiB file-size limit.
  out=$work/reliability-fsize
  rm -rf "$out" && mkdir -p "$out"
  "$brainshift" mesh --preop-labels "$L" --output-dir "$out" >/dev/null || fail "mesh exited $?"
  cp "$out/mesh.vtu" "$out.before"
  expect 1 "cannot write $out/mesh.vtu" -- bash -c "ulimit -f 500; exec \"\$@\"" limit "$brainshift" mesh --preop-labels "$L" \
    --output-dir "$out" --mesh-resolution 3.5
  cmp -s "$out/mesh.vtu" "$out.before" || fail "a failed write replaced mesh.vtu"
  no_temporaries "$out"
  # The finite element job file (in the temporary folder) under a smaller limit.
  simulate_folder "$out/simulate"
  cp "$out/simulate/mesh.vtu" "$out.before"
  expect 1 "cannot write" -- bash -c "ulimit -f 200; exec \"\$@\"" limit "$brainshift" simulate --output-dir "$out/simulate"
  cmp -s "$out/simulate/mesh.vtu" "$out.before" || fail "a failed simulate replaced mesh.vtu"
  # A compressed volume cut short: the warped volumes of warp (NIfTI's writer does not notice).
  mkdir -p "$out/warp" && find "$demo/" -maxdepth 1 -type f -exec cp {} "$out/warp/" \;
  cp "$out/warp/warped_preop_image.nii.gz" "$out.before"
  expect 1 "cannot write" -- bash -c "ulimit -f 300; exec \"\$@\"" limit "$brainshift" warp --preop-image "$P" \
    --preop-labels "$L" --intraop-image "$I" --output-dir "$out/warp"
  cmp -s "$out/warp/warped_preop_image.nii.gz" "$out.before" || fail "a failed warp replaced warped_preop_image.nii.gz"
  no_temporaries "$out"
  ;;

ReadOnlyFolder)
  out=$work/reliability-readonly
  rm -rf "$out" && mkdir -p "$out/folder" && chmod 555 "$out/folder"
  chmod o+rx "$work" "$out" 2>/dev/null
  as_user=()
  if [ "$(id -u)" -eq 0 ]; then as_user=(setpriv --reuid=65534 --regid=65534 --clear-groups); fi
  # Before any work, as bad input: not after the mesh, as "internal error" with VTK's 14 lines.
  expect 2 "$out/folder: the output folder is not writable" -- "${as_user[@]}" "$brainshift" mesh --preop-labels "$L" \
    --output-dir "$out/folder"
  expect 2 "not writable" -- "${as_user[@]}" "$brainshift" register --preop-image "$P" --preop-labels "$L" \
    --intraop-image "$I" --output-dir "$out/folder"
  [ -z "$(ls -A "$out/folder")" ] || fail "something was written into the read-only folder"
  ;;

OneWriterPerFolder)
  out=$work/reliability-lock
  simulate_folder "$out"
  # A second run while the first holds the folder: refused, naming the first.
  "$brainshift" simulate --output-dir "$out" --solver-options "-pc_type none -ksp_rtol 1e-9" >"$out.log" 2>&1 &
  first=$!
  for _ in $(seq 1 1000); do # its worker running: the folder was claimed before
    [ -n "$(pgrep -P "$first")" ] && break
    sleep 0.01
  done
  if [ -n "$(pgrep -P "$first")" ]; then
    expect 2 "another brainshift run is writing into this folder" -- "$brainshift" mesh --preop-labels "$L" --output-dir "$out"
  else
    fail "the first run's worker was not seen"
  fi
  wait "$first" || fail "the first run exited $? ($(cat "$out.log"))"
  # Once it ended, the folder is free again.
  "$brainshift" simulate --output-dir "$out" >/dev/null || fail "the folder stayed locked after the run"
  ;;

OutputOverInput)
  out=$work/reliability-overwrite
  rm -rf "$out" && mkdir -p "$out"
  cp "$case_dir/landmarks.csv" "$out/landmarks.csv"
  before=$(sha256sum "$out/landmarks.csv")
  expect 2 "--json is an input" -- "$brainshift" evaluate --transform identity --landmarks "$out/landmarks.csv" \
    --json "$out/landmarks.csv"
  [ "$before" = "$(sha256sum "$out/landmarks.csv")" ] || fail "evaluate --json overwrote its landmark file"
  expect 2 "taken by a built-in output" -- "$brainshift" register --preop-image "$P" --preop-labels "$L" \
    --intraop-image "$I" --overlay "preop_image=$case_dir/preop_fmri.nii.gz" --output-dir "$out/register"
  cp "$P" "$out/warped_preop_image.nii.gz"
  expect 2 "under a name the run writes" -- "$brainshift" warp --preop-image "$out/warped_preop_image.nii.gz" \
    --preop-labels "$L" --intraop-image "$I" --output-dir "$out"
  ;;

SignalDuringSimulate)
  # SIGTERM while the finite element worker runs: mpiexec and its ranks end, the temporary folder
  # and partial files go, and the exit status is 128 + 15.
  out=$work/reliability-signal
  rm -rf "$out" && mkdir -p "$out"
  "$brainshift" register --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --output-dir "$out/run" \
    --solver-options "-pc_type none -ksp_rtol 1e-10" >"$out/log" 2>"$out/err" &
  run=$!
  mpiexec_pid=""
  for _ in $(seq 1 6000); do
    mpiexec_pid=$(pgrep -P "$run" | head -1)
    [ -n "$mpiexec_pid" ] && break
    kill -0 "$run" 2>/dev/null || break
    sleep 0.01
  done
  if [ -z "$mpiexec_pid" ]; then
    fail "the worker never started (the run ended: $(cat "$out/err"))"
  else
    job_folder=$(tr '\0' '\n' < "/proc/$mpiexec_pid/cmdline" | grep -m1 'job.bsfe' | xargs -r dirname)
    sleep 0.3 # the ranks up
    kill -TERM "$run"
    wait "$run"
    status=$?
    [ "$status" -eq 143 ] || fail "exit $status after SIGTERM, expected 143 ($(cat "$out/err"))"
    [ "$(grep -c . "$out/err")" -eq 1 ] && grep -q "stopped by SIGTERM" "$out/err" || fail "stderr: $(cat "$out/err")"
    sleep 0.2
    left=$(pgrep -g "$mpiexec_pid")
    [ -z "$left" ] || fail "worker processes left running: $(ps -o pid,args -p "$(echo $left | tr ' ' ,)")"
    [ -n "$job_folder" ] && [ -e "$job_folder" ] && fail "the worker's temporary folder $job_folder was left"
    no_temporaries "$out/run"
  fi
  ;;

StaleTemporaries)
  # The partial files of a run that died outright (SIGKILL) are removed by the next run into the
  # folder; a live process's are not touched.
  out=$work/reliability-stale
  simulate_folder "$out"
  sleep 30 &
  live=$!
  dead=999999999
  echo partial > "$out/.tmp-$dead-0-mesh.vtu"
  echo partial > "$out/.tmp-$live-0-mesh.vtu"
  "$brainshift" simulate --output-dir "$out" >/dev/null || fail "simulate exited $?"
  [ -e "$out/.tmp-$dead-0-mesh.vtu" ] && fail "a dead run's partial file was not removed"
  [ -e "$out/.tmp-$live-0-mesh.vtu" ] || fail "a live process's temporary file was removed"
  kill "$live"
  ;;

OneLineDiagnostics)
  out=$work/reliability-messages
  rm -rf "$out" && mkdir -p "$out/folder-as-image"
  echo "not DICOM" > "$out/folder-as-image/slice.dcm"
  head -c 3000 "$demo/intraop_to_preop.h5" > "$out/truncated.h5"
  expect 2 "$out/truncated.h5" -- "$brainshift" evaluate --transform "$out/truncated.h5" --landmarks "$case_dir/landmarks.csv"
  expect 2 "$out/folder-as-image" -- "$brainshift" rigid --preop-image "$out/folder-as-image" --intraop-image "$I" \
    --output-dir "$out/rigid"
  ;;

StageCaseIdentity)
  # A stage alone checks the case as register does: a folder holding another case's results is
  # refused (exit 2, nothing written) unless --overwrite.
  out=$work/reliability-identity
  rm -rf "$out" && mkdir -p "$out/inputs"
  # Another case: the small case's labels with 20 voxels of parenchyma turned to CSF.
  python3 - "$L" "$out/inputs/other-labels.nii.gz" <<'PY'
import gzip, struct, sys
data = bytearray(gzip.open(sys.argv[1]).read())
offset = int(struct.unpack_from('<f', data, 108)[0])
changed = 0
for i in range(offset, len(data)):
    if data[i] == 2 and changed < 20:
        data[i] = 3
        changed += 1
gzip.open(sys.argv[2], 'wb').write(bytes(data))
PY
  "$brainshift" mesh --preop-labels "$L" --output-dir "$out/mesh" >/dev/null || fail "mesh exited $?"
  grep -q '"preop_labels"' "$out/mesh/report.json" || fail "mesh recorded no case_inputs in report.json"
  before=$(sha256sum "$out/mesh/mesh.vtu" "$out/mesh/report.json")
  expect 2 "$out/mesh: holds the results of another case" -- "$brainshift" mesh --preop-labels "$out/inputs/other-labels.nii.gz" \
    --output-dir "$out/mesh"
  [ "$before" = "$(sha256sum "$out/mesh/mesh.vtu" "$out/mesh/report.json")" ] || fail "a refused stage changed the folder"
  # The same case's other stages are welcome (the labels agree; the image is new to the report).
  "$brainshift" rigid --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --output-dir "$out/mesh" >/dev/null ||
    fail "rigid of the same case into its folder exited $?"
  grep -q '"preop_image"' "$out/mesh/report.json" || fail "rigid did not add its image to case_inputs"
  # register's folder (the demo's) refuses a stage of another case too.
  mkdir -p "$out/register" && cp "$demo/report.json" "$demo/mesh.vtu" "$out/register/"
  expect 2 "holds the results of another case" -- "$brainshift" classify --preop-labels "$out/inputs/other-labels.nii.gz" \
    --intraop-image "$I" --output-dir "$out/register"
  # --overwrite replaces them, and the report starts afresh with the new case.
  "$brainshift" mesh --preop-labels "$out/inputs/other-labels.nii.gz" --output-dir "$out/mesh" --overwrite >/dev/null ||
    fail "mesh --overwrite exited $?"
  grep -q "other-labels.nii.gz" "$out/mesh/report.json" || fail "--overwrite did not record the new case"
  grep -q '"preop_image"' "$out/mesh/report.json" && fail "--overwrite kept the other case's entries in report.json"
  no_temporaries "$out"
  ;;

RigidDegenerateImages)
  # Images too small or featureless to register: bad input (exit 2), one line, no transform.
  out=$work/reliability-degenerate
  rm -rf "$out" && mkdir -p "$out/inputs"
  python3 - "$I" "$out/inputs" <<'PY'
import gzip, struct, sys
data = bytearray(gzip.open(sys.argv[1]).read())
offset = int(struct.unpack_from('<f', data, 108)[0])
dims = struct.unpack_from('<8h', data, 40)
datatype, bitpix = struct.unpack_from('<hh', data, 70)
nbytes = bitpix // 8
header = bytearray(data[:offset])
# A 4x4x4 image: the header's dimensions, the first 64 voxels.
tiny = bytearray(header)
struct.pack_into('<8h', tiny, 40, 3, 4, 4, 4, 1, 1, 1, 1)
gzip.open(sys.argv[2] + '/tiny.nii.gz', 'wb').write(bytes(tiny + data[offset:offset + 64 * nbytes]))
# The full grid with zeros but one voxel (its first byte), and a constant image (all bytes equal).
n = dims[1] * dims[2] * dims[3] * nbytes
speck = bytearray(n); centre = (n // 2) // nbytes * nbytes
speck[centre:centre + nbytes] = data[offset + centre:offset + centre + nbytes] if any(data[offset + centre:offset + centre + nbytes]) else b'\x40' * nbytes
gzip.open(sys.argv[2] + '/speck.nii.gz', 'wb').write(bytes(header + speck))
gzip.open(sys.argv[2] + '/constant.nii.gz', 'wb').write(bytes(header + b'\x40' * n))
PY
  expect 2 "too small to register" -- "$brainshift" rigid --preop-image "$P" --intraop-image "$out/inputs/tiny.nii.gz" --output-dir "$out/tiny"
  expect 2 "foreground is too small to register" -- "$brainshift" rigid --preop-image "$P" --intraop-image "$out/inputs/speck.nii.gz" \
    --output-dir "$out/speck"
  expect 2 "a constant image" -- "$brainshift" rigid --preop-image "$P" --intraop-image "$out/inputs/constant.nii.gz" --output-dir "$out/constant"
  [ -n "$(find "$out" -name rigid_intraop_to_preop.tfm)" ] && fail "a refused registration wrote a transform"
  no_temporaries "$out"
  ;;

SignalDuringWarp)
  # SIGTERM while warp writes its files: exit 143, one line, no `.tmp-*` left, every file there
  # whole (the previous one or the new one), and the next run succeeds.
  out=$work/reliability-signal-warp
  caught=no
  for attempt in 1 2 3 4 5; do
    rm -rf "$out" && mkdir -p "$out/run"
    find "$demo/" -maxdepth 1 -type f -exec cp {} "$out/run/" \;
    ln -s "$case_dir" "$out/run/case" # the demo's scene refers to the case's images there
    "$brainshift" warp --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --output-dir "$out/run" \
      >/dev/null 2>"$out/err" &
    run=$!
    for _ in $(seq 1 4000); do # until its first partial file (or 0.4 s at the latest: mid-run)
      [ -n "$(find "$out/run" -name '.tmp-*' 2>/dev/null | head -1)" ] && break
      kill -0 "$run" 2>/dev/null || break
      sleep 0.0001
    done
    kill -TERM "$run" 2>/dev/null
    wait "$run"
    status=$?
    [ "$status" -eq 0 ] && continue # it had finished: try again
    caught=yes
    break
  done
  if [ "$caught" = no ]; then
    fail "warp always finished before SIGTERM reached it"
  else
    [ "$status" -eq 143 ] || fail "exit $status after SIGTERM during warp, expected 143 ($(cat "$out/err"))"
    [ "$(grep -c . "$out/err")" -eq 1 ] && grep -q "stopped by SIGTERM" "$out/err" || fail "stderr: $(cat "$out/err")"
    no_temporaries "$out/run"
    for volume in "$out"/run/*.nii.gz; do
      gzip -t "$volume" 2>/dev/null || fail "$volume is cut short after SIGTERM"
    done
    "$brainshift" bench read-scene --scene "$out/run/scene.mrml" >/dev/null 2>&1 || fail "scene.mrml unreadable after SIGTERM"
    "$brainshift" warp --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --output-dir "$out/run" >/dev/null ||
      fail "warp after the interrupted one exited $?"
    no_temporaries "$out/run"
  fi
  ;;

SignalDuringWatch)
  # SIGINT to watch, first while it waits for images, then while a scan's finite element worker
  # runs: exit 130, one line, nothing of its session left running, no `.tmp-*`, the folder free.
  out=$work/reliability-signal-watch
  rm -rf "$out" && mkdir -p "$out/incoming"
  setsid "$brainshift" watch --preop-image "$P" --preop-labels "$L" --watch-dir "$out/incoming" --poll-seconds 0.2 \
    --output-dir "$out/session" >"$out/log" 2>"$out/err" &
  run=$!
  for _ in $(seq 1 3000); do
    [ -d "$out/session" ] && break
    sleep 0.01
  done
  sleep 1 # waiting for images
  kill -INT "$run"
  wait "$run"
  status=$?
  [ "$status" -eq 130 ] || fail "exit $status after SIGINT to a waiting watch, expected 130 ($(cat "$out/err"))"
  [ "$(grep -c . "$out/err")" -eq 1 ] && grep -q "stopped by SIGINT" "$out/err" || fail "stderr: $(cat "$out/err")"
  sleep 0.2
  left=$(live_in_session "$run")
  [ -z "$left" ] || fail "processes of the waiting watch left: $(ps -o pid,args -p "$(echo $left | tr ' ' ,)")"

  # A scan in progress: the session's served worker is running when SIGINT comes.
  cp "$I" "$out/incoming/scan1.nii.gz"
  setsid "$brainshift" watch --preop-image "$P" --preop-labels "$L" --watch-dir "$out/incoming" --poll-seconds 0.2 \
    --output-dir "$out/session" --overwrite --solver-options "-pc_type none -ksp_rtol 1e-10" >"$out/log" 2>"$out/err" &
  run=$!
  worker=""
  for _ in $(seq 1 6000); do
    worker=$(pgrep -P "$run" | head -1)
    [ -n "$worker" ] && break
    kill -0 "$run" 2>/dev/null || break
    sleep 0.01
  done
  if [ -z "$worker" ]; then
    fail "the watch session's worker never started ($(cat "$out/err"))"
  else
    job_folder=$(tr '\0' '\n' < "/proc/$worker/cmdline" | grep -m1 'job.bsfe' | xargs -r dirname)
    sleep 0.3
    kill -INT "$run"
    wait "$run"
    status=$?
    [ "$status" -eq 130 ] || fail "exit $status after SIGINT during a scan, expected 130 ($(cat "$out/err"))"
    [ "$(grep -c . "$out/err")" -eq 1 ] && grep -q "stopped by SIGINT" "$out/err" || fail "stderr: $(cat "$out/err")"
    sleep 0.2
    left=$(live_in_session "$run")
    [ -z "$left" ] || fail "processes of the watch session left: $(ps -o pid,args -p "$(echo $left | tr ' ' ,)")"
    [ -n "$job_folder" ] && [ -e "$job_folder" ] && fail "the worker's temporary folder $job_folder was left"
  fi
  no_temporaries "$out/session"
  # The folder is free again: a new session may claim it.
  rm -f "$out/incoming/scan1.nii.gz"
  timeout --preserve-status -s INT 3 "$brainshift" watch --preop-image "$P" --preop-labels "$L" --watch-dir "$out/incoming" \
    --output-dir "$out/session" --overwrite >/dev/null 2>"$out/err"
  status=$?
  [ "$status" -eq 130 ] || fail "a new session in the folder exited $status, expected 130 at its SIGINT ($(cat "$out/err"))"
  ;;

*)
  echo "unknown case $case_name" >&2
  exit 2
  ;;
esac
[ "$failures" -eq 0 ] || { echo "$case_name: $failures failure(s)" >&2; exit 1; }
echo "$case_name: passed"
