#!/usr/bin/env bash
# Command-line tests of `brainshift send`, `export-dicom`, `watch --igtl-server` and `register
# --export-dicom` against independent readers and clients:
# a server built on libOpenIGTLink (brainshift-interop-test-tool), dciodvfy (dicom3tools), ITK's
# GDCM reader and DCMTK's dcmdump. Usage: InteropCommandLineTest.sh CASE BRAINSHIFT TOOL WORKDIR;
# the demo's small case is in WORKDIR/demo (fixture CommandLine.DemoSmallCase).
set -uo pipefail
case_name=$1
brainshift=$2
tool=$3
work=$4
demo=$work/demo
here=$work/interop-$case_name
# shellcheck source=CommandLineTestSupport.sh
source "$(dirname "${BASH_SOURCE[0]}")/CommandLineTestSupport.sh"

# start_tool MODE ARGS...: runs the test tool in the background; waits for its port in $here/port.
start_tool() {
  rm -f "$here/port"
  "$tool" "$1" "$here/port" "${@:2}" >"$here/tool.out" 2>&1 &
  tool_pid=$!
  for _ in $(seq 100); do [ -s "$here/port" ] && break; sleep 0.05; done
  [ -s "$here/port" ] || fail "the test server did not start"
  port=$(cat "$here/port")
}

# A port where nothing listens: bound by the kernel, then released.
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()'; }

tag() { dcmdump +P "$2" "$1" 2>/dev/null | sed -n 's/.*\[\(.*\)\].*/\1/p' | head -1; }

rm -rf "$here"
mkdir -p "$here"
[ -f "$demo/report.json" ] || { echo "FAILED: no demo in $demo (fixture CommandLine.DemoSmallCase)" >&2; exit 1; }

case "$case_name" in
SendUpdate)
  # Every message checked by the server against the folder's files: type, device, grid, checksum.
  start_tool igtl-server "$demo"
  "$brainshift" send --output-dir "$demo" --igtl "localhost:$port" >"$here/send.out" 2>&1 || fail "send exited $?: $(cat "$here/send.out")"
  wait "$tool_pid" || fail "the server's checks failed: $(grep FAILED "$here/tool.out")"
  cat "$here/tool.out"
  grep -q "^sent 7 messages" "$here/send.out" || fail "send did not report 7 messages: $(cat "$here/send.out")"
  ;;
SendBadInput)
  expect 2 "cannot connect" -- "$brainshift" send --output-dir "$demo" --igtl "127.0.0.1:$(free_port)"
  start_tool igtl-refuse
  expect 2 "closed the connection" -- "$brainshift" send --output-dir "$demo" --igtl "127.0.0.1:$port"
  wait "$tool_pid"
  expect 2 "unknown host" -- "$brainshift" send --output-dir "$demo" --igtl "no-such-host.invalid:18944"
  expect 2 "HOST:PORT" -- "$brainshift" send --output-dir "$demo" --igtl "localhost"
  expect 2 "1 to 65535" -- "$brainshift" send --output-dir "$demo" --igtl "localhost:99999"
  expect 2 "report.json" -- "$brainshift" send --output-dir "$demo/case" --igtl "localhost:18944"
  ;;
ExportDicom)
  out=$here/dicom
  "$brainshift" export-dicom --output-dir "$demo" --to "$out" >"$here/export.out" 2>&1 || fail "export-dicom exited $?: $(cat "$here/export.out")"
  for series in warped_preop_image warped_fmri warped_preop_labels displacement_magnitude_mm; do
    [ -d "$out/$series" ] || { fail "no series $series"; continue; }
    [ "$(ls "$out/$series" | wc -l)" -eq 30 ] || fail "$series: not one file per slice (30)"
  done
  if command -v dciodvfy >/dev/null; then
    for file in "$out"/*/*.dcm; do
      errors=$(dciodvfy "$file" 2>&1 | grep '^Error')
      [ -z "$errors" ] || { fail "dciodvfy $file: $errors"; break; }
    done
  else
    echo "SKIPPED: dciodvfy (Debian dicom3tools) is not installed; the DICOM files were not verified by it"
  fi
  for series in warped_preop_image warped_fmri warped_preop_labels; do
    "$tool" compare-dicom "$out/$series" "$demo/$series.nii.gz" || fail "$series read back differs"
  done
  "$tool" compare-dicom "$out/warped_preop_labels" "$demo/warped_preop_labels.nii.gz" | grep -q "worst 0.000000)" ||
    fail "labels not exact"
  "$tool" compare-dicom "$out/displacement_magnitude_mm" "$demo/displacement_intraop_to_preop.nrrd" || fail "magnitude differs"
  # The labels also as a DICOM Segmentation (dciodvfy checked it above with the series), read back
  # with DCMTK: a segment per label, its frames and voxels the NIfTI label's, the MR series' study.
  seg=$out/warped_preop_labels_seg/SEG0001.dcm
  if [ -f "$seg" ]; then
    "$tool" check-seg "$seg" "$demo/warped_preop_labels.nii.gz" "$out/warped_preop_image" >"$here/seg.out" ||
      fail "the Segmentation read back differs: $(grep FAILED "$here/seg.out")"
    [ "$(grep -c '^segment ' "$here/seg.out")" -eq 4 ] || fail "not 4 segments: $(cat "$here/seg.out")"
    [ "$(tag "$seg" FrameOfReferenceUID)" = "$(tag "$out/warped_preop_labels/IM0001.dcm" FrameOfReferenceUID)" ] ||
      fail "the Segmentation's Frame of Reference is not the labels series'"
    grep -q "wrote $seg\|wrote $out/warped_preop_labels_seg" "$here/export.out" || fail "export-dicom does not report the Segmentation"
  elif "$tool" 2>&1 | grep -q check-seg; then
    fail "no DICOM Segmentation $seg although DCMTK's dcmseg is there"
  fi
  [ "$(tag "$out/warped_fmri/IM0001.dcm" StudyInstanceUID)" = "$(tag "$out/warped_preop_image/IM0030.dcm" StudyInstanceUID)" ] ||
    fail "the series do not share one study"
  [ "$(tag "$out/warped_fmri/IM0001.dcm" FrameOfReferenceUID)" = "$(tag "$out/displacement_magnitude_mm/IM0001.dcm" FrameOfReferenceUID)" ] ||
    fail "the series do not share one Frame of Reference"
  before=$(find "$out" -type f | sort | xargs sha256sum)
  expect 2 "exists already" -- "$brainshift" export-dicom --output-dir "$demo" --to "$out"
  [ "$before" = "$(find "$out" -type f | sort | xargs sha256sum)" ] || fail "a refused export changed $out"
  [ -z "$(ls -A "$out" | grep '^\.')" ] || fail "a staging folder is left in $out"
  ;;
ExportDicomReference)
  # The intraoperative scan as a DICOM series of patient P-0001 (the update's grid, made from an export).
  "$brainshift" export-dicom --output-dir "$demo" --to "$here/made" >/dev/null || fail "export-dicom exited $?"
  scan=$here/scan-dicom
  cp -r "$here/made/warped_preop_image" "$scan"
  dcmodify -nb -m "PatientID=P-0001" -m "PatientName=Doe^Jane" "$scan"/*.dcm >/dev/null || fail "dcmodify failed"
  # A NIfTI scan: the reference on its grid lends its study, patient and Frame of Reference.
  "$brainshift" export-dicom --output-dir "$demo" --to "$here/onto-reference" --reference-series "$scan" >/dev/null ||
    fail "export-dicom --reference-series exited $?"
  for key in StudyInstanceUID FrameOfReferenceUID PatientID; do
    [ "$(tag "$here/onto-reference/warped_fmri/IM0001.dcm" $key)" = "$(tag "$scan/IM0001.dcm" $key)" ] || fail "$key not the reference's"
  done
  # The update of a DICOM scan: its own study and Frame of Reference without a flag.
  cp -r "$demo" "$here/update"
  python3 - "$here/update/report.json" "$scan" <<'PY'
import json, sys
report = json.load(open(sys.argv[1]))
report["case_inputs"]["intraop_image"]["path"] = sys.argv[2]
json.dump(report, open(sys.argv[1], "w"))
PY
  "$brainshift" export-dicom --output-dir "$here/update" --to "$here/from-scan" >/dev/null || fail "export-dicom of a DICOM scan exited $?"
  [ "$(tag "$here/from-scan/warped_preop_labels/IM0001.dcm" FrameOfReferenceUID)" = "$(tag "$scan/IM0001.dcm" FrameOfReferenceUID)" ] ||
    fail "the DICOM scan's Frame of Reference is not kept"
  if [ -f "$here/from-scan/warped_preop_labels_seg/SEG0001.dcm" ]; then
    [ "$(tag "$here/from-scan/warped_preop_labels_seg/SEG0001.dcm" FrameOfReferenceUID)" = "$(tag "$scan/IM0001.dcm" FrameOfReferenceUID)" ] ||
      fail "the Segmentation does not keep the DICOM scan's Frame of Reference"
  fi
  # Another patient's series as reference: one line, exit 2, nothing in the target folder.
  other=$here/other-patient
  cp -r "$scan" "$other"
  dcmodify -nb -m "PatientID=P-0002" "$other"/*.dcm >/dev/null
  expect 2 "another patient" -- "$brainshift" export-dicom --output-dir "$here/update" --to "$here/refused" --reference-series "$other"
  [ ! -e "$here/refused" ] || [ -z "$(ls -A "$here/refused")" ] || fail "a refused export left files in $here/refused"
  ;;
WatchExportDicom)
  # watch --export-dicom: each registered scan's series into DIR/scan-NN/, one study per scan.
  case_dir=$demo/case
  "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --output-dir "$here/session" --scans "$case_dir/intraop_image.nii.gz" --export-dicom "$here/dicom" >"$here/watch.out" 2>&1 ||
    fail "watch exited $?: $(tail -3 "$here/watch.out")"
  [ "$(ls "$here/dicom/scan-01/warped_preop_image" | wc -l)" -eq 30 ] || fail "no series of scan 1 in $here/dicom/scan-01"
  "$tool" compare-dicom "$here/dicom/scan-01/warped_preop_labels" "$here/session/scan-01/warped_preop_labels.nii.gz" >/dev/null ||
    fail "scan 1's labels read back differ"
  grep -q '"dicom"' "$here/session/watch.json" || fail "watch.json does not record the DICOM export"
  ;;
WatchIgtlServer)
  # watch --igtl-server: the test tool's clients (libOpenIGTLink) receive scan 1's update, one drops
  # out inside it, one connects later and gets it on connecting, then IMAGE intraop becomes scan 2.
  case_dir=$demo/case
  port=$(free_port)
  timeout 300 "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --output-dir "$here/session" --scans "$case_dir/intraop_image.nii.gz" --igtl-server "127.0.0.1:$port" --max-scans 2 \
    >"$here/watch.out" 2>"$here/watch.err" &
  watch_pid=$!
  timeout 240 "$tool" igtl-watch-client "$port" "$here/session" "$case_dir/intraop_image.nii.gz" >"$here/client.out" 2>&1 ||
    { fail "the client's checks failed: $(grep FAILED "$here/client.out")"; kill "$watch_pid" 2>/dev/null; }
  wait "$watch_pid" || fail "watch exited $?: $(tail -3 "$here/watch.err")"
  cat "$here/client.out"
  [ "$(grep -c '^ok' "$here/client.out")" -ge 80 ] || fail "fewer checks than four updates' worth passed"
  [ -f "$here/session/scan-02/report.json" ] || fail "the scan sent as IMAGE intraop was not registered as scan-02"
  grep -q "OpenIGTLink client 127.0.0.1:[0-9]* dropped" "$here/watch.err" || fail "the dropped client is not reported on stderr"
  python3 - "$here/session" <<'PY' || fail "watch.json: see above"
import json, os, sys
session = sys.argv[1]
w = json.load(open(os.path.join(session, "watch.json")))
scans = w["scans"]
problems = []
if [s["outcome"] for s in scans] != ["registered", "registered"]: problems.append("outcomes %s" % [s["outcome"] for s in scans])
if not scans[1]["source"].startswith("OpenIGTLink client 127.0.0.1:"): problems.append("scan 2's source " + scans[1]["source"])
received = os.path.join(os.path.abspath(session), "received", "intraop-001.nii.gz")
if scans[1]["intraop_image"] != received or not os.path.isfile(received): problems.append("scan 2's image " + scans[1]["intraop_image"])
if len({s.get("igtl") for s in scans}) != 1 or not str(scans[0].get("igtl")).startswith("pushed "): problems.append("igtl %s" % [s.get("igtl") for s in scans])
events = [e["event"] for e in w["igtl_server"]["events"]]
if events.count("connected") != 3 or events.count("dropped") < 1 or events.count("received scan") != 1:
    problems.append("events %s" % events)
for p in problems: print("FAILED: watch.json: " + p, file=sys.stderr)
sys.exit(1 if problems else 0)
PY
  ;;
WatchIgtlBadInput)
  case_dir=$demo/case
  watch() { "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --output-dir "$here/session" --scans "$case_dir/intraop_image.nii.gz" "$@"; }
  expect 2 "1 to 65535" -- watch --igtl-server 70000
  expect 2 "1 to 65535" -- watch --igtl-server 127.0.0.1:port
  expect 2 "not an IPv4 address" -- watch --igtl-server 999.1.1.1:18944
  start_tool igtl-refuse # a port taken by another server
  expect 2 "cannot listen" -- watch --igtl-server "127.0.0.1:$port"
  kill "$tool_pid" 2>/dev/null
  wait "$tool_pid" 2>/dev/null
  [ ! -e "$here/session/scan-01" ] || fail "a refused session registered a scan"
  ;;
RegisterExportDicom)
  # register --export-dicom: the update's series written after it, as export-dicom writes them.
  case_dir=$demo/case
  register() { "$brainshift" register --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --intraop-image "$case_dir/intraop_image.nii.gz" "$@"; }
  register --output-dir "$here/update" --export-dicom "$here/dicom" >"$here/register.out" 2>&1 ||
    fail "register --export-dicom exited $?: $(tail -3 "$here/register.out")"
  for series in warped_preop_image warped_preop_labels displacement_magnitude_mm; do
    [ "$(ls "$here/dicom/$series" 2>/dev/null | wc -l)" -eq 30 ] || fail "no series $series of 30 files"
  done
  "$tool" compare-dicom "$here/dicom/warped_preop_labels" "$here/update/warped_preop_labels.nii.gz" | grep -q "worst 0.000000)" ||
    fail "the labels read back differ"
  "$tool" compare-dicom "$here/dicom/warped_preop_image" "$here/update/warped_preop_image.nii.gz" >/dev/null ||
    fail "the warped image read back differs"
  touch "$here/a-file"
  expect 2 "not a folder" -- register --output-dir "$here/update2" --export-dicom "$here/a-file"
  [ ! -e "$here/update2/report.json" ] || fail "register ran although --export-dicom is a file"
  ;;
*)
  echo "unknown case $case_name" >&2
  exit 2
  ;;
esac
[ "$failures" -eq 0 ] || exit 1
echo "passed: $case_name"
