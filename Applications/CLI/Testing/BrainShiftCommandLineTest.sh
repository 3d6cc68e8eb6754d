#!/usr/bin/env bash
# Command-line tests of brainshift. Usage: BrainShiftCommandLineTest.sh CASE BRAINSHIFT WORKDIR
# DemoSmallCase runs `brainshift demo --size small` once into WORKDIR/demo; the other cases use it.
set -uo pipefail
case_name=$1
brainshift=$2
work=$3
demo=$work/demo
case_dir=$demo/case

# shellcheck source=CommandLineTestSupport.sh
source "$(dirname "${BASH_SOURCE[0]}")/CommandLineTestSupport.sh"

# Small inputs crafted with Python's standard library (no numpy): a NIfTI with a NaN voxel,
# a truncated one, a text file posing as an image.
make_bad_inputs() {
  local dir=$1
  mkdir -p "$dir"
  python3 - "$dir" <<'PY'
import gzip, struct, sys, math
d = sys.argv[1]
def nifti(path, values, dims=(4, 4, 4)):
    hdr = bytearray(348)
    struct.pack_into('<i', hdr, 0, 348)
    struct.pack_into('<8h', hdr, 40, 3, dims[0], dims[1], dims[2], 1, 1, 1, 1)
    struct.pack_into('<h', hdr, 70, 16)   # float32
    struct.pack_into('<h', hdr, 72, 32)
    struct.pack_into('<8f', hdr, 76, 1, 1, 1, 1, 1, 1, 1, 1)
    struct.pack_into('<f', hdr, 108, 352)
    struct.pack_into('<h', hdr, 252, 1)   # qform_code
    hdr[344:348] = b'n+1\0'
    data = struct.pack('<%df' % len(values), *values)
    with gzip.open(path, 'wb') as f:
        f.write(bytes(hdr) + b'\0' * 4 + data)
n = 64
nifti(d + '/nan.nii.gz', [float(i) if i != 10 else math.nan for i in range(n)])
good = d + '/good.nii.gz'
nifti(good, [float(i) for i in range(n)])
nifti(d + '/zeros.nii.gz', [0.0] * 512, (8, 8, 8))
raw = open(good, 'rb').read()
open(d + '/truncated.nii.gz', 'wb').write(raw[: len(raw) // 2])
open(d + '/text.nii.gz', 'w').write('this is not an image\n')
PY
}

case "$case_name" in
DemoSmallCase)
  rm -rf "$demo"
  mkdir -p "$work"
  "$brainshift" demo --size small --output-dir "$demo" || fail "demo exited $?"
  # The case scene opens on the intraoperative scan; its landmark lists are locked in the scene
  # and in their .mrk.json files alike, and show their names.
  python3 - "$demo/case/scene.mrml" <<'PY' || fail "case/scene.mrml does not open on the intraoperative scan"
import json, os, sys, xml.etree.ElementTree as ET
scene = sys.argv[1]
root = ET.parse(scene).getroot()
by_id = {e.get("id"): e for e in root}
refs = lambda e: dict(r.split(":", 1) for r in e.get("references", "").split(";") if ":" in r)
composites = root.findall("SliceComposite")
assert sorted(c.get("layoutName") for c in composites) == ["Green", "Red", "Yellow"], composites
for c in composites:
    background = by_id[refs(c)["backgroundVolume"]]
    storage = by_id[refs(background)["storage"]]
    assert os.path.basename(storage.get("fileName")) == "intraop_image.nii.gz", storage.get("fileName")
lists = root.findall("MarkupsFiducial")
assert len(lists) == 2, lists
for m in lists:
    assert m.get("locked") == "true", m.get("locked")
    assert by_id[refs(m)["display"]].get("pointLabelsVisibility") == "true"
    markup = json.load(open(os.path.join(os.path.dirname(scene), by_id[refs(m)["storage"]].get("fileName"))))["markups"][0]
    assert markup["locked"] is True and all(p["locked"] is True for p in markup["controlPoints"]), markup["locked"]
PY
  # The update's solves (a worker kept for the surface's and the matches' solves) use incomplete
  # Cholesky in the blocks: with PETSc's ILU(0) CG broke down (KSP reason -8) on the same case
  # meshed with grading 1, which now solves.
  [ "$(json_value "$demo/report.json" "['stages']['simulate']['solver']")" = "cg+bjacobi/icc" ] ||
    fail "the update's solve is not CG with incomplete Cholesky blocks"
  # The segmentation's offset at the brain boundary is measured (-0.83 mm on these 2.5 x 2.5 x 5 mm
  # voxels, the deep brain still better than rigid) and within a third of a voxel: no warning.
  float_check "$demo/report.json" "['stages']['surface']['boundary_offset']['nodes']" "> 4000"
  float_check "$demo/report.json" "['stages']['surface']['boundary_offset']['median_normal_mm']" "> -1.0"
  ! offset_warned "$demo/report.json" || fail "the small case's segmentation offset was warned of"
  c=$demo/case
  printf '{"mesh": {"grading": 1.0}}\n' > "$work/graded-mesh.json"
  "$brainshift" register --preop-image "$c/preop_image.nii.gz" --preop-labels "$c/preop_labels.nii.gz" \
    --intraop-image "$c/intraop_image.nii.gz" --output-dir "$work/graded-update" --config "$work/graded-mesh.json" >/dev/null ||
    fail "the update on a graded mesh exited $?"
  float_check "$work/graded-update/report.json" "['stages']['simulate']['relative_residual']" "< 1e-4"
  ;;

HelpEverywhere)
  expect 0 "" -- "$brainshift" --help
  for sub in demo register watch rigid classify mesh surface simulate warp evaluate bench; do
    expect 0 "" -- "$brainshift" "$sub" --help
  done
  "$brainshift" register --help | grep -q -- "--solver-options" || fail "register --help lacks --solver-options"
  ;;

UsageErrors)
  expect 2 "subcommand is required" -- "$brainshift"
  expect 2 "" -- "$brainshift" no-such-command
  expect 2 "--no-such-flag" -- "$brainshift" evaluate --no-such-flag --transform a --landmarks b
  expect 2 "--landmarks is required" -- "$brainshift" evaluate --transform a.tfm
  expect 2 "--ranks" -- "$brainshift" simulate --output-dir "$work/x" --ranks many
  expect 2 "--size" -- "$brainshift" demo --size huge --output-dir "$work/usage-demo"
  expect 2 "--shift" -- "$brainshift" demo --shift 80 --output-dir "$work/usage-demo"
  expect 2 "--craniotomy" -- "$brainshift" demo --craniotomy occipital --output-dir "$work/usage-demo"
  expect 2 "--tumour-depth: 5 mm is outside 13 to 40 mm" -- "$brainshift" demo --tumour-depth 5 --output-dir "$work/usage-demo"
  [ -e "$work/usage-demo" ] && fail "a refused demo left $work/usage-demo behind"
  expect 2 "ranks" -- "$brainshift" register --preop-image "$case_dir/preop_image.nii.gz" \
    --preop-labels "$case_dir/preop_labels.nii.gz" --intraop-image "$case_dir/intraop_image.nii.gz" \
    --output-dir "$work/usage-register" --ranks 0
  ;;

EvaluateTruth)
  out=$work/evaluate-truth
  rm -rf "$out"
  "$brainshift" evaluate --transform "$case_dir/truth/intraop_to_preop.h5" --landmarks "$case_dir/landmarks.csv" \
    --json "$out/truth.json" > "$out.txt" || fail "evaluate exited $?"
  grep -q "per pair" "$out.txt" || fail "evaluate printed no per-pair table"
  float_check "$out/truth.json" "['mean_mm']" "< 0.02"
  float_check "$out/truth.json" "['max_mm']" "< 0.02"
  [ "$(json_value "$out/truth.json" "['pairs'][0]['name']")" = "craniotomy-01" ] || fail "first pair is not craniotomy-01"
  pairs=$(($(wc -l < "$case_dir/landmarks.csv") - 1))
  [ "$(json_value "$out/truth.json" "['pairs'].__len__()")" = "$pairs" ] || fail "not every pair is in the JSON"
  # No registration: the misalignment and the shift themselves.
  "$brainshift" evaluate --transform identity --landmarks "$case_dir/landmarks.csv" --json "$out/identity.json" >/dev/null \
    || fail "evaluate of the identity exited $?"
  float_check "$out/identity.json" "['mean_mm']" "> 8"
  # The rigid part alone: exact on the head, far off under the craniotomy.
  "$brainshift" evaluate --transform "$case_dir/truth/rigid_intraop_to_preop.tfm" --landmarks "$case_dir/landmarks.csv" \
    --json "$out/rigid.json" >/dev/null || fail "evaluate of the rigid part exited $?"
  float_check "$out/rigid.json" "['groups']['head']['max_mm']" "< 0.02"
  float_check "$out/rigid.json" "['groups']['craniotomy']['mean_mm']" "> 3"
  ;;

EvaluateBadInput)
  bad=$work/evaluate-bad
  rm -rf "$bad" && mkdir -p "$bad"
  truth=$case_dir/truth/intraop_to_preop.h5
  expect 2 "$bad/none.h5: no such file" -- "$brainshift" evaluate --transform "$bad/none.h5" --landmarks "$case_dir/landmarks.csv"
  printf 'not a transform\n' > "$bad/text.tfm"
  expect 2 "$bad/text.tfm" -- "$brainshift" evaluate --transform "$bad/text.tfm" --landmarks "$case_dir/landmarks.csv"
  printf 'name,x,y,z\n' > "$bad/header.csv"
  expect 2 "$bad/header.csv:1" -- "$brainshift" evaluate --transform "$truth" --landmarks "$bad/header.csv"
  head -3 "$case_dir/landmarks.csv" > "$bad/nan.csv"
  printf 'x-01,nan,0,0,0,0,0\n' >> "$bad/nan.csv"
  expect 2 "$bad/nan.csv:4" -- "$brainshift" evaluate --transform "$truth" --landmarks "$bad/nan.csv"
  expect 2 "no pairs" -- "$brainshift" evaluate --transform "$truth" --landmarks <(head -1 "$case_dir/landmarks.csv")
  expect 2 "" -- "$brainshift" evaluate --transform "$truth" --landmarks "$bad/header.csv" --json "$bad/out.json"
  [ -e "$bad/out.json" ] && fail "a failed evaluate wrote $bad/out.json"
  ;;

RegisterBadInput)
  bad=$work/register-bad
  rm -rf "$bad"
  make_bad_inputs "$bad/inputs"
  before=$(checksums "$bad/inputs" "$case_dir")
  P=$case_dir/preop_image.nii.gz L=$case_dir/preop_labels.nii.gz I=$case_dir/intraop_image.nii.gz
  run() { expect 2 "$1" -- "$brainshift" register "${@:2}" --output-dir "$bad/out"; }
  run "$bad/inputs/missing.nii.gz: no such file" --preop-image "$bad/inputs/missing.nii.gz" --preop-labels "$L" --intraop-image "$I"
  run "$bad/inputs/text.nii.gz" --preop-image "$P" --preop-labels "$L" --intraop-image "$bad/inputs/text.nii.gz"
  run "$bad/inputs/truncated.nii.gz" --preop-image "$P" --preop-labels "$L" --intraop-image "$bad/inputs/truncated.nii.gz"
  run "NaN" --preop-image "$bad/inputs/nan.nii.gz" --preop-labels "$L" --intraop-image "$I"
  run "another grid" --preop-image "$P" --preop-labels "$bad/inputs/good.nii.gz" --intraop-image "$I"
  run "not a label map" --preop-image "$P" --preop-labels "$P" --intraop-image "$I"
  run "$bad/inputs/nan.nii.gz" --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --overlay "fmri=$bad/inputs/nan.nii.gz"
  run "NAME=FILE" --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --overlay "fmri"
  printf '{"materials": {"2": {"poisson_ratio": 0.5}}}' > "$bad/config.json"
  run "poisson_ratio" --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --config "$bad/config.json"
  run "mesh resolution" --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --mesh-resolution 0.01
  [ -e "$bad/out" ] && fail "register on bad input left outputs in $bad/out: $(ls "$bad/out")"
  after=$(checksums "$bad/inputs" "$case_dir")
  [ "$before" = "$after" ] || fail "inputs were modified"
  ;;

WatchSession)
  # Serial scans in one session: each scan registered into its folder as register would, the later
  # one reusing the earlier's work and the served worker (assembled once, its fixed nodes
  # eliminated anew); a scan that fails is reported and the session goes on; the exit says so.
  out=$work/watch
  rm -rf "$out" && mkdir -p "$out"
  printf 'not an image' > "$out/broken.nii"
  status=0
  "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --overlay fmri="$case_dir/preop_fmri.nii.gz" --output-dir "$out/session" \
    --scans "$case_dir/intraop_image.nii.gz,$out/broken.nii,$case_dir/intraop_image.nii.gz" >/dev/null 2>"$out/stderr" || status=$?
  [ "$status" = "1" ] || fail "watch with a broken scan exited $status, expected 1"
  grep -q "scan 2 ($out/broken.nii)" "$out/stderr" || fail "the broken scan was not named: $(cat "$out/stderr")"
  for entry in "0 registered" "1 failed: $out/broken.nii" "2 registered"; do
    index=${entry%% *}
    expected=${entry#* }
    outcome=$(json_value "$out/session/watch.json" "['scans'][$index]['outcome']")
    [ "${outcome:0:${#expected}}" = "$expected" ] || fail "watch.json: scan $((index + 1)) outcome '$outcome', expected '$expected'"
  done
  # Each scan's trust verdict is in watch.json (the broken scan's update never got assessed).
  for entry in "0 trusted" "1 not assessed" "2 trusted"; do
    trust=$(json_value "$out/session/watch.json" "['scans'][${entry%% *}]['trust']")
    [ "$trust" = "${entry#* }" ] || fail "watch.json: scan $((${entry%% *} + 1)) trust '$trust', expected '${entry#* }'"
  done
  for scan in scan-01 scan-03; do
    for file in intraop_to_preop.h5 displacement_intraop_to_preop.nrrd warped_preop_image.nii.gz warped_fmri.nii.gz scene.mrml; do
      [ -s "$out/session/$scan/$file" ] || fail "$scan lacks $file"
    done
    [ "$(json_value "$out/session/$scan/report.json" "['stages']['simulate']['served']")" = "True" ] || fail "$scan: not served"
  done
  # The worker, the mesh and the preoperative boundary were prepared before the first scan.
  [ "$(json_value "$out/session/preoperative/report.json" "['stages']['worker']['prepared']")" = "True" ] ||
    fail "the session did not prepare the worker before surgery"
  [ -s "$out/session/preoperative/mesh.vtu" ] || fail "the session did not prepare the mesh before surgery"
  for scan in scan-01 scan-03; do
    [ "$(json_value "$out/session/$scan/report.json" "['stages']['simulate']['worker_prepared']")" = "False" ] ||
      fail "$scan prepared a worker again"
    json_value "$out/session/$scan/report.json" "['stages']['mesh']['reused_from']" >/dev/null 2>&1 || fail "$scan meshed again"
  done
  [ "$(json_value "$out/session/scan-01/report.json" "['prepared_case']")" = "$out/session/preoperative" ] ||
    fail "the first scan does not name the prepared case"
  [ "$(json_value "$out/session/scan-03/report.json" "['previous_scan']")" = "$out/session/scan-01" ] ||
    fail "the later scan did not follow the last registered one"
  [ "$(json_value "$out/session/scan-03/report.json" "['stages']['mesh']['reused_from']")" = "$out/session/scan-01/mesh.vtu" ] ||
    fail "the later scan did not reuse the mesh"
  # The served solve is the one-shot solve: the same transform as register on the same scan.
  "$brainshift" evaluate --transform "$out/session/scan-03/intraop_to_preop.h5" --landmarks "$case_dir/landmarks.csv" \
    --json "$out/tre.json" >/dev/null || fail "evaluate exited $?"
  float_check "$out/tre.json" "['mean_mm']" "< 1.5"
  # A folder the scanner writes into: each new image (once its size holds) in name order.
  mkdir -p "$out/scanner"
  cp "$case_dir/intraop_image.nii.gz" "$out/scanner/a.nii.gz"
  cp "$case_dir/intraop_image.nii.gz" "$out/scanner/b.nii.gz"
  printf 'notes' > "$out/scanner/notes.txt"
  "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --output-dir "$out/folder" --watch-dir "$out/scanner" --max-scans 2 --poll-seconds 0.1 >/dev/null ||
    fail "watch --watch-dir exited $?"
  [ "$(json_value "$out/folder/watch.json" "['scans'][1]['intraop_image']")" = "$out/scanner/b.nii.gz" ] ||
    fail "the folder's second image was not the second scan"
  [ -s "$out/folder/scan-02/intraop_to_preop.h5" ] || fail "the folder's second scan wrote no transform"
  # An earlier session's folder is refused (its scans kept) unless --overwrite.
  expect 2 "holds an earlier watch session" -- "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" \
    --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out/folder" --scans "$case_dir/intraop_image.nii.gz"
  [ -s "$out/folder/scan-02/intraop_to_preop.h5" ] || fail "a refused watch touched the earlier session's scans"
  expect 2 "either --scans or --watch-dir" -- "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" \
    --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out/none"
  expect 2 "--watch-dir is not a folder" -- "$brainshift" watch --preop-image "$case_dir/preop_image.nii.gz" \
    --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out/none" --watch-dir "$out/missing"
  ;;

SerialScans)
  # A later scan of the same case reuses what the first prepared: the rigid alignment as the start,
  # the classification prototypes, the mesh and the preoperative surface fit; its result is as good.
  first=$work/serial/scan-1
  later=$work/serial/scan-2
  rm -rf "$work/serial"
  # The reuse rules are compared pass for pass: without the refine stage, whose passes would carry
  # the later scan's 0.02 mm different rigid start into every figure compared below.
  mkdir -p "$work/serial"
  printf '{"classification": {"refinement_passes": 0}}\n' > "$work/serial/no-refine.json"
  inputs=(--preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz"
    --intraop-image "$case_dir/intraop_image.nii.gz" --config "$work/serial/no-refine.json")
  # (the first scan with prototypes picked beforehand, as a user would: they are carried forward)
  "$brainshift" register "${inputs[@]}" --output-dir "$first" --prototypes "$demo/classification_prototypes.json" >/dev/null ||
    fail "first scan exited $?"
  # A first scan meshes and fits the preoperative boundary beside its rigid registration and
  # classification (PreparationAhead): the stages take them, with the same figures as when made in
  # line (the mesh stage run alone below makes the same mesh).
  float_check "$first/report.json" "['stages']['mesh']['made_ahead_seconds']" "> 0"
  [ "$(json_value "$first/report.json" "['stages']['surface']['preop_boundary_from']")" = "made beside the rigid registration" ] ||
    fail "the first scan did not take the preoperative boundary made beside its rigid registration"
  float_check "$first/report.json" "['stages']['surface']['preop_boundary_made_ahead_seconds']" "> 0"
  # Deterministic: the same scan registered again writes the same files, byte for byte (the
  # worker's partition the same every run, and each match's tetrahedron the lowest that holds it;
  # intraop_to_preop.h5 carries HDF5's own metadata, report.json the times).
  again=$work/serial/scan-1-again
  "$brainshift" register "${inputs[@]}" --output-dir "$again" --prototypes "$demo/classification_prototypes.json" >/dev/null ||
    fail "the first scan again exited $?"
  for file in intraop_labels.nii.gz brain_surface.vtp mesh.vtu block_matches.vtp displacement_intraop_to_preop.nrrd \
    displacement_uncertainty_mm.nii.gz warped_preop_image.nii.gz warped_preop_labels.nii.gz; do
    cmp -s "$first/$file" "$again/$file" || fail "the same scan registered again wrote another $file"
  done
  mkdir -p "$work/serial/mesh-alone"
  "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$work/serial/mesh-alone" >/dev/null ||
    fail "mesh alone exited $?"
  for key in nodes tetrahedra min_dihedral_degrees; do
    [ "$(json_value "$work/serial/mesh-alone/report.json" "['stages']['mesh']['$key']")" = \
      "$(json_value "$first/report.json" "['stages']['mesh']['$key']")" ] || fail "the mesh made ahead differs in $key from the mesh stage's"
  done
  "$brainshift" register "${inputs[@]}" --output-dir "$later" --previous "$first" >/dev/null || fail "later scan exited $?"
  [ "$(json_value "$later/report.json" "['stages']['rigid']['initialised_from']")" = "$first/rigid_intraop_to_preop.tfm" ] ||
    fail "the later scan's rigid registration did not start from the first's"
  [ "$(json_value "$later/report.json" "['stages']['rigid']['starts_scored']")" = "0" ] || fail "the later scan searched starts again"
  [ "$(json_value "$later/report.json" "['stages']['classify']['prototypes_from']")" = "$first/classification_prototypes.json" ] ||
    fail "the later scan did not reuse the picked prototypes"
  # Prototypes a scan chose by itself are chosen afresh on the next (a mesh of another resolution
  # is made anew too).
  "$brainshift" register "${inputs[@]}" --output-dir "$work/serial/auto-1" --mesh-resolution 6 >/dev/null || fail "auto-1 exited $?"
  "$brainshift" register "${inputs[@]}" --output-dir "$work/serial/auto-2" --mesh-resolution 5 --previous "$work/serial/auto-1" \
    >/dev/null || fail "auto-2 exited $?"
  [ "$(json_value "$work/serial/auto-2/report.json" "['stages']['classify']['prototypes_given']")" = "False" ] ||
    fail "prototypes chosen automatically were reused"
  [ "$(json_value "$work/serial/auto-2/report.json" "['stages']['mesh'].get('reused_from', '')")" = "" ] ||
    fail "a mesh of another resolution was reused"
  [ "$(json_value "$work/serial/auto-2/report.json" "['stages']['surface']['preop_boundary_from']")" = "" ] ||
    fail "the preoperative fit of another mesh was reused"
  [ "$(json_value "$later/report.json" "['stages']['mesh']['reused_from']")" = "$first/mesh.vtu" ] || fail "the mesh was not reused"
  [ "$(json_value "$later/report.json" "['stages']['surface']['preop_boundary_from']")" = "$first/brain_surface.vtp" ] ||
    fail "the preoperative surface fit was not reused"
  [ "$(json_value "$later/report.json" "['stages']['mesh']['nodes']")" = "$(json_value "$first/report.json" "['stages']['mesh']['nodes']")" ] ||
    fail "the reused mesh's figures differ"
  # The same scan again: the same surface displacements (the reused fit is the one found before).
  # The later scan's rigid start differs by about 0.02 mm, and the classification reads the
  # preoperative image through it: the means stay within 0.02 mm, the largest displacement (one
  # node's) within 0.05 (8.10 against 8.12 mm measured). A wrong fit reused moves them by millimetres.
  for key in mean_displacement_mm:0.02 max_displacement_mm:0.05 mean_residual_mm:0.02; do
    tolerance=${key#*:}
    key=${key%:*}
    value=$(json_value "$first/report.json" "['stages']['surface']['$key']")
    float_check "$later/report.json" "['stages']['surface']['$key']" "< $value + $tolerance"
    float_check "$later/report.json" "['stages']['surface']['$key']" "> $value - $tolerance"
  done
  for scan in "$first" "$later"; do
    "$brainshift" evaluate --transform "$scan/intraop_to_preop.h5" --landmarks "$case_dir/landmarks.csv" --json "$scan/tre.json" \
      >/dev/null || fail "evaluate exited $?"
  done
  float_check "$later/tre.json" "['mean_mm']" "< $(json_value "$first/tre.json" "['mean_mm']") + 0.05"
  # A tumour an earlier scan found resected stays resected: a later, larger shift may sink tissue
  # into its place through the rigid prior, where the image decision would call it in place.
  [ "$(json_value "$first/report.json" "['stages']['classify']['tumour_resected']")" = True ] || fail "the first scan kept the tumour"
  [ "$(json_value "$later/report.json" "['stages']['classify']['tumour_evidence']['decided_by']")" = \
    "an earlier scan of this case (resected there)" ] || fail "the later scan decided the resection again"
  # Another case's folder is refused (nothing written), as --previous or as --output-dir, unless --overwrite.
  # (another case: the preoperative image with one voxel changed; the same data in another file
  # would be the same case)
  python3 - "$case_dir/preop_image.nii.gz" "$work/serial/other_preop.nii" <<'PY' || fail "cannot write the other case's image"
import gzip, struct, sys
data = bytearray(gzip.open(sys.argv[1]).read())
offset = int(struct.unpack("<f", bytes(data[108:112]))[0])  # vox_offset
data[offset + 5000] ^= 0x40
open(sys.argv[2], "wb").write(bytes(data))
PY
  other=(--preop-image "$work/serial/other_preop.nii" --preop-labels "$case_dir/preop_labels.nii.gz"
    --intraop-image "$case_dir/intraop_image.nii.gz")
  before=$(checksums "$first")
  expect 2 "holds the results of another case" -- "$brainshift" register "${other[@]}" --output-dir "$first"
  [ "$before" = "$(checksums "$first")" ] || fail "a refused register changed the folder"
  expect 2 "--previous is another case's output" -- "$brainshift" register "${other[@]}" --output-dir "$work/serial/other" \
    --previous "$first"
  expect 2 "--previous is not a folder" -- "$brainshift" register "${inputs[@]}" --output-dir "$work/serial/other" \
    --previous "$work/serial/missing"
  "$brainshift" register "${other[@]}" --output-dir "$first" --overwrite >/dev/null || fail "register --overwrite exited $?"
  [ "$(json_value "$first/report.json" "['case_inputs']['preop_image']['path']")" = "$work/serial/other_preop.nii" ] ||
    fail "--overwrite did not replace the folder's case"
  ;;
RegisterEndToEnd)
  out=$work/register
  rm -rf "$out"
  L=$case_dir/preop_labels.nii.gz
  "$brainshift" register --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$L" \
    --intraop-image "$case_dir/intraop_image.nii.gz" --overlay "fmri=$case_dir/preop_fmri.nii.gz" --output-dir "$out" >/dev/null ||
    fail "register exited $?"
  for f in rigid_intraop_to_preop.tfm intraop_to_preop.h5 displacement_intraop_to_preop.nrrd intraop_labels.nii.gz \
    warped_preop_image.nii.gz warped_preop_labels.nii.gz warped_fmri.nii.gz mesh.vtu brain_surface.vtp scene.mrml report.json; do
    [ -s "$out/$f" ] || fail "register did not write $f"
  done
  for stage in rigid classify mesh surface simulate warp; do
    json_value "$out/report.json" "['stages']['$stage']['wall_seconds']" >/dev/null || fail "report.json lacks $stage"
  done
  for key in voxels folded_voxels; do
    json_value "$out/report.json" "['stages']['warp']['$key']" >/dev/null || fail "report.json lacks warp.$key"
  done
  # Every file the scene points at exists beside it.
  python3 - "$out/scene.mrml" <<'PY' || fail "scene.mrml points at missing files"
import os, re, sys
scene = sys.argv[1]
text = open(scene).read()
files = re.findall(r'fileName="([^"]+)"', text)
assert files, "no files in the scene"
missing = [f for f in files if not os.path.exists(os.path.join(os.path.dirname(scene), f))]
assert not missing, missing
for needed in ("warped_preop_image.nii.gz", "brain_surface.vtp", "intraop_to_preop.h5"):
    assert needed in text, needed
PY
  # Slicer opens it fused: Four-Up, each slice view on the scan with the warped fMRI and labels over it.
  python3 - "$out/scene.mrml" "$case_dir/intraop_image.nii.gz" <<'PY' || fail "scene.mrml does not open fused"
import os, sys, xml.etree.ElementTree as ET
scene, intraop = sys.argv[1:]
root = ET.parse(scene).getroot()
by_id = {e.get("id"): e for e in root}
refs = lambda e: dict(r.split(":", 1) for r in e.get("references", "").split(";") if ":" in r)
file_of = lambda volume: os.path.realpath(os.path.join(os.path.dirname(scene), by_id[refs(volume)["storage"]].get("fileName")))
assert [l.get("currentViewArrangement") for l in root.findall("Layout")] == ["3"]
composites = root.findall("SliceComposite")
assert sorted(c.get("layoutName") for c in composites) == ["Green", "Red", "Yellow"], composites
for c in composites:
    r = refs(c)
    assert file_of(by_id[r["backgroundVolume"]]) == os.path.realpath(intraop), file_of(by_id[r["backgroundVolume"]])
    assert os.path.basename(file_of(by_id[r["foregroundVolume"]])) == "warped_fmri.nii.gz"
    assert by_id[r["labelVolume"]].tag == "LabelMapVolume"
    assert os.path.basename(file_of(by_id[r["labelVolume"]])) == "warped_preop_labels.nii.gz"
    assert 0.3 <= float(c.get("foregroundOpacity")) <= 0.7
PY
  # The whole update against the truth: better than the rigid part alone.
  "$brainshift" evaluate --transform "$out/intraop_to_preop.h5" --landmarks "$case_dir/landmarks.csv" --json "$out/tre.json" \
    >/dev/null || fail "evaluate exited $?"
  "$brainshift" evaluate --transform "$out/rigid_intraop_to_preop.tfm" --landmarks "$case_dir/landmarks.csv" \
    --json "$out/tre_rigid.json" >/dev/null || fail "evaluate exited $?"
  float_check "$out/tre.json" "['mean_mm']" "< 0.7 * $(json_value "$out/tre_rigid.json" "['mean_mm']")"
  float_check "$out/tre.json" "['p95_mm']" "< 2.0"
  # The field is the same mapping as the transform file.
  "$brainshift" evaluate --transform "$out/displacement_intraop_to_preop.nrrd" --landmarks "$case_dir/landmarks.csv" \
    --json "$out/tre_field.json" >/dev/null || fail "evaluate of the field exited $?"
  float_check "$out/tre_field.json" "['mean_mm']" "< $(json_value "$out/tre.json" "['mean_mm']") + 1e-3"
  float_check "$out/tre_field.json" "['mean_mm']" "> $(json_value "$out/tre.json" "['mean_mm']") - 1e-3"
  ;;

WarpStage)
  out=$work/warp-stage
  rm -rf "$out" && mkdir -p "$out"
  P=$case_dir/preop_image.nii.gz L=$case_dir/preop_labels.nii.gz I=$case_dir/intraop_image.nii.gz
  expect 2 "rigid_intraop_to_preop.tfm: not found; run \`brainshift rigid\`" -- "$brainshift" warp --preop-image "$P" \
    --preop-labels "$L" --intraop-image "$I" --output-dir "$out"
  cp "$demo/rigid_intraop_to_preop.tfm" "$demo/brain_surface.vtp" "$out/"
  "$brainshift" mesh --preop-labels "$L" --output-dir "$out" >/dev/null || fail "mesh exited $?"
  expect 2 "mesh.vtu: no point array \"Displacement\"; run \`brainshift simulate\`" -- "$brainshift" warp --preop-image "$P" \
    --preop-labels "$L" --intraop-image "$I" --output-dir "$out"
  [ -e "$out/scene.mrml" ] && fail "a scene was written without a deformation"
  expect 2 "no such file" -- "$brainshift" warp --preop-image "$out/none.nii.gz" --preop-labels "$L" --intraop-image "$I" \
    --output-dir "$out"
  expect 2 "" -- "$brainshift" bench
  expect 2 "--mesh-resolutions" -- "$brainshift" bench update --output-dir "$out/bench" --mesh-resolutions 0.1
  expect 2 "--methods" -- "$brainshift" bench surface --output-dir "$out/bench" --methods nonsense
  ;;

TrustAssessment)
  # The demo's update is trusted; an update built on a segmentation moved 7.5 mm is worse than the
  # rigid registration and is rejected: exit 1, every file holds the rigid transform, the report
  # and the scene say so, the update set aside is kept, nothing of the update is published.
  out=$work/trust
  rm -rf "$out" && mkdir -p "$out/good" "$out/damaged"
  P=$case_dir/preop_image.nii.gz L=$case_dir/preop_labels.nii.gz I=$case_dir/intraop_image.nii.gz
  [ "$(json_value "$demo/report.json" "['trust']['nonrigid']")" = trusted ] || fail "the demo's update is not trusted"
  cp "$demo/rigid_intraop_to_preop.tfm" "$demo/mesh.vtu" "$demo/brain_surface.vtp" "$demo/intraop_labels.nii.gz" "$demo/report.json" "$out/good/"
  "$brainshift" warp --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --output-dir "$out/good" >/dev/null ||
    fail "warp of the demo's update exited $?"
  [ "$(json_value "$out/good/report.json" "['trust']['nonrigid']")" = trusted ] || fail "the update is not trusted on its own"
  float_check "$out/good/report.json" "['trust']['moved']['gain']" "> 0.02"
  [ -e "$out/good/rejected_intraop_to_preop.h5" ] && fail "a trusted update wrote rejected_intraop_to_preop.h5"
  grep -q "rigid fallback" "$out/good/scene.mrml" && fail "the scene of a trusted update says rigid fallback"
  # The segmentation moved 3 voxels (7.5 mm on the small case) along the first grid axis.
  shift_labels_along_first_axis "$demo/intraop_labels.nii.gz" "$out/damaged/intraop_labels.nii.gz"
  cp "$demo/rigid_intraop_to_preop.tfm" "$demo/mesh.vtu" "$out/damaged/"
  "$brainshift" surface --preop-labels "$L" --intraop-image "$I" --output-dir "$out/damaged" >/dev/null || fail "surface exited $?"
  "$brainshift" simulate --output-dir "$out/damaged" >/dev/null || fail "simulate exited $?"
  expect 1 "the non-rigid update is rejected and the rigid registration is shown instead" -- "$brainshift" warp \
    --preop-image "$P" --preop-labels "$L" --intraop-image "$I" --output-dir "$out/damaged"
  r=$out/damaged/report.json
  [ "$(json_value "$r" "['trust']['nonrigid']")" = rejected ] || fail "report.json: trust.nonrigid is not rejected"
  [ "$(json_value "$r" "['trust']['rigid_fallback']")" = True ] || fail "report.json: trust.rigid_fallback is not true"
  [ "$(json_value "$r" "['stages']['warp']['rigid_fallback']")" = True ] || fail "report.json: warp.rigid_fallback is not true"
  float_check "$r" "['trust']['moved']['gain']" "< -0.05"
  json_value "$r" "['warnings']" | grep -q "non-rigid update is rejected" || fail "report.json: no warning of the rejection"
  grep -q "intraop_to_preop (rigid fallback)" "$out/damaged/scene.mrml" || fail "the scene does not mark the rigid fallback"
  for f in rejected_intraop_to_preop.h5 intraop_to_preop.h5 displacement_intraop_to_preop.nrrd warped_preop_image.nii.gz; do
    [ -s "$out/damaged/$f" ] || fail "$f not written"
  done
  # The files hold the rigid transform: the same landmark errors as the rigid file; the update set
  # aside is worse.
  for t in intraop_to_preop.h5 displacement_intraop_to_preop.nrrd rigid_intraop_to_preop.tfm rejected_intraop_to_preop.h5; do
    "$brainshift" evaluate --transform "$out/damaged/$t" --landmarks "$case_dir/landmarks.csv" --json "$out/$t.json" >/dev/null ||
      fail "evaluate $t exited $?"
  done
  rigid_tre=$(json_value "$out/rigid_intraop_to_preop.tfm.json" "['mean_mm']")
  float_check "$out/intraop_to_preop.h5.json" "['mean_mm']" "- $rigid_tre < 0.01"
  float_check "$out/intraop_to_preop.h5.json" "['mean_mm']" "- $rigid_tre > -0.01"
  float_check "$out/displacement_intraop_to_preop.nrrd.json" "['mean_mm']" "- $rigid_tre < 0.01"
  float_check "$out/rejected_intraop_to_preop.h5.json" "['mean_mm']" "> $rigid_tre + 1"
  # The update's files wait in a staging folder while the assessment runs: none is left behind, and
  # the rejected update's confidence map is not published.
  for d in good damaged; do
    [ -e "$out/$d/.warp-staging" ] && fail "$d: the warp's staging folder was left behind"
    ls -a "$out/$d" | grep -q "^\.tmp-" && fail "$d: temporary files were left behind"
  done
  [ -s "$out/good/displacement_uncertainty_mm.nii.gz" ] || fail "the trusted update has no confidence map"
  [ -e "$out/damaged/displacement_uncertainty_mm.nii.gz" ] && fail "the rejected update's confidence map was published"
  ;;
DemoRefusesForeignFolder)
  out=$work/foreign
  rm -rf "$out" && mkdir -p "$out"
  printf '{"stages": {"rigid": {"wall_seconds": 1}}, "warnings": []}\n' > "$out/report.json"
  expect 2 "another run" -- "$brainshift" demo --size small --output-dir "$out"
  grep -q '"rigid"' "$out/report.json" || fail "the foreign report was changed"
  ;;

RigidStage)
  out=$work/rigid-stage
  rm -rf "$out"
  # Started without GLIBC_TUNABLES, brainshift runs itself again with its allocations on
  # transparent huge pages where the kernel gives them (ProcessMemory.h); the run below opts out.
  env -u GLIBC_TUNABLES "$brainshift" rigid --preop-image "$case_dir/preop_image.nii.gz" \
    --preop-labels "$case_dir/preop_labels.nii.gz" --intraop-image "$case_dir/intraop_image.nii.gz" --output-dir "$out" \
    >/dev/null || fail "rigid exited $?"
  [ -s "$out/rigid_intraop_to_preop.tfm" ] || fail "rigid wrote no rigid_intraop_to_preop.tfm"
  huge=False
  grep -qE '\[(always|madvise)\]' /sys/kernel/mm/transparent_hugepage/enabled 2>/dev/null && huge=True
  [ "$(json_value "$out/report.json" "['huge_page_allocations']")" = "$huge" ] ||
    fail "report.json huge_page_allocations is not $huge (transparent huge pages: $(cat /sys/kernel/mm/transparent_hugepage/enabled 2>&1))"
  for key in wall_seconds metric_value iterations iterations_per_level winning_start_degrees; do
    json_value "$out/report.json" "['stages']['rigid']['$key']" >/dev/null || fail "report.json lacks rigid.$key"
  done
  "$brainshift" evaluate --transform "$out/rigid_intraop_to_preop.tfm" --landmarks "$case_dir/landmarks.csv" \
    --json "$out/evaluation.json" >/dev/null || fail "evaluate exited $?"
  float_check "$out/evaluation.json" "['groups']['head']['max_mm']" "< 0.6"
  # Same inputs, same transform, on huge pages or not.
  GLIBC_TUNABLES=glibc.malloc.hugetlb=0 "$brainshift" rigid --preop-image "$case_dir/preop_image.nii.gz" \
    --preop-labels "$case_dir/preop_labels.nii.gz" --intraop-image "$case_dir/intraop_image.nii.gz" \
    --output-dir "$out/again" >/dev/null || fail "rigid exited $?"
  [ "$(json_value "$out/again/report.json" "['huge_page_allocations']")" = "False" ] ||
    fail "GLIBC_TUNABLES=glibc.malloc.hugetlb=0 did not keep 4 KiB pages"
  cmp -s "$out/rigid_intraop_to_preop.tfm" "$out/again/rigid_intraop_to_preop.tfm" || fail "rigid is not deterministic"
  # An intraoperative image without foreground is bad input; unrelated images are refused (exit 1).
  make_bad_inputs "$out/inputs"
  expect 1 "cannot be trusted" -- "$brainshift" rigid --preop-image "$case_dir/preop_image.nii.gz" \
    --intraop-image "$case_dir/truth/intraop_labels.nii.gz" --output-dir "$out/labels-as-image"
  [ -e "$out/labels-as-image/rigid_intraop_to_preop.tfm" ] && fail "an untrusted rigid result was written"
  grep -q '"trustworthy": false' "$out/labels-as-image/report.json" || fail "report.json does not record the refusal"
  expect 2 "zeros.nii.gz: a constant image" -- "$brainshift" rigid --preop-image "$case_dir/preop_image.nii.gz" \
    --intraop-image "$out/inputs/zeros.nii.gz" --output-dir "$out/zeros"
  ;;

ClassifyStage)
  out=$work/classify-stage
  rm -rf "$out"
  L=$case_dir/preop_labels.nii.gz I=$case_dir/intraop_image.nii.gz
  expect 2 "run \`brainshift rigid\` on this output folder first" -- "$brainshift" classify --preop-labels "$L" \
    --intraop-image "$I" --output-dir "$out"
  "$brainshift" rigid --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$L" --intraop-image "$I" \
    --output-dir "$out" >/dev/null || fail "rigid exited $?"
  "$brainshift" classify --preop-labels "$L" --intraop-image "$I" --output-dir "$out" >/dev/null || fail "classify exited $?"
  for f in intraop_labels.nii.gz classification_prototypes.json; do [ -s "$out/$f" ] || fail "classify did not write $f"; done
  for key in wall_seconds voxels prototypes knn_seconds tumour_resected; do
    json_value "$out/report.json" "['stages']['classify']['$key']" >/dev/null || fail "report.json lacks classify.$key"
  done
  # The draw of the prototypes is recorded (classification.seed; another seed, another draw).
  [ "$(json_value "$out/report.json" "['stages']['classify']['seed']")" = 2000 ] || fail "report.json lacks the prototypes' seed"
  [ "$(json_value "$out/report.json" "['stages']['rigid']['trustworthy']")" = "True" ] || fail "the rigid entry was lost"
  # The next scan reuses the recorded prototypes: on the same scan, the same labels.
  mkdir -p "$out/again" && cp "$out/rigid_intraop_to_preop.tfm" "$out/again/"
  "$brainshift" classify --preop-labels "$L" --intraop-image "$I" --output-dir "$out/again" \
    --prototypes "$out/classification_prototypes.json" >/dev/null || fail "classify with recorded prototypes exited $?"
  cmp -s "$out/intraop_labels.nii.gz" "$out/again/intraop_labels.nii.gz" || fail "recorded prototypes gave other labels"
  [ "$(json_value "$out/again/report.json" "['stages']['classify']['prototypes_given']")" = "True" ] || fail "not recorded as given"
  printf '{"frame": "intraop", "prototypes": [{"name": "p", "label": 2, "position": [9999, 0, 0]}]}' > "$out/far.json"
  expect 2 "'p'" -- "$brainshift" classify --preop-labels "$L" --intraop-image "$I" --output-dir "$out/again" --prototypes "$out/far.json"
  printf '{"classification": {"k": 0}}' > "$out/k0.json"
  expect 2 "classification.k" -- "$brainshift" classify --preop-labels "$L" --intraop-image "$I" --output-dir "$out/again" --config "$out/k0.json"
  ;;

MeshStage)
  out=$work/mesh-stage
  rm -rf "$out"
  "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out" --mesh-resolution 6 >/dev/null \
    || fail "mesh exited $?"
  [ -s "$out/mesh.vtu" ] && grep -q 'Name="Label"' "$out/mesh.vtu" || fail "mesh.vtu lacks the cell array Label"
  for key in wall_seconds nodes tetrahedra min_dihedral_degrees inverted_tetrahedra volume_ml; do
    json_value "$out/report.json" "['stages']['mesh']['$key']" >/dev/null || fail "report.json lacks mesh.$key"
  done
  [ "$(json_value "$out/report.json" "['stages']['mesh']['inverted_tetrahedra']")" = "0" ] || fail "inverted tetrahedra"
  float_check "$out/report.json" "['stages']['mesh']['min_dihedral_degrees']" ">= 10"
  expect 2 "finer than the label map's voxels" -- "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" \
    --output-dir "$out" --mesh-resolution 1
  printf '{"mesh": {"labels": [2, 9]}}' > "$out/nine.json"
  expect 2 "tissue label 9" -- "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out" \
    --config "$out/nine.json"
  # Graded: fewer nodes than the uniform lattice at the same resolution; the settings reported.
  "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out/graded" --mesh-resolution 4 \
    --mesh-grading 1 --mesh-roi=-20,10,30,15 >/dev/null || fail "graded mesh exited $?"
  "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out/uniform" --mesh-resolution 4 \
    >/dev/null || fail "uniform mesh exited $?"
  graded_nodes=$(json_value "$out/graded/report.json" "['stages']['mesh']['nodes']")
  uniform_nodes=$(json_value "$out/uniform/report.json" "['stages']['mesh']['nodes']")
  [ "$graded_nodes" -lt "$uniform_nodes" ] || fail "graded mesh: $graded_nodes nodes, not fewer than the uniform $uniform_nodes"
  [ "$(json_value "$out/graded/report.json" "['stages']['mesh']['grading']")" = "1.0" ] || fail "report.json lacks mesh.grading"
  [ "$(json_value "$out/graded/report.json" "['stages']['mesh']['region_of_interest']['radius_mm']")" = "15.0" ] ||
    fail "report.json lacks mesh.region_of_interest"
  expect 2 "--mesh-roi" -- "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out/bad" \
    --mesh-roi=1,2,3,-4
  expect 2 "mesh grading" -- "$brainshift" mesh --preop-labels "$case_dir/preop_labels.nii.gz" --output-dir "$out/bad" \
    --mesh-grading -2
  ;;

SurfaceStage)
  out=$work/surface-stage
  rm -rf "$out" && mkdir -p "$out"
  L=$case_dir/preop_labels.nii.gz I=$case_dir/intraop_image.nii.gz
  expect 2 "mesh.vtu: not found; run \`brainshift mesh\`" -- "$brainshift" surface --preop-labels "$L" --intraop-image "$I" \
    --output-dir "$out"
  cp "$demo/mesh.vtu" "$demo/rigid_intraop_to_preop.tfm" "$demo/intraop_labels.nii.gz" "$out/"
  before=$(checksums "$out" "$case_dir")
  "$brainshift" surface --preop-labels "$L" --intraop-image "$I" --output-dir "$out" >/dev/null || fail "surface exited $?"
  [ "$before" = "$(checksums "$out/mesh.vtu" "$out/rigid_intraop_to_preop.tfm" "$out/intraop_labels.nii.gz" "$case_dir")" ] ||
    fail "surface modified its inputs"
  for array in Displacement DisplacementMagnitude MeshNodeId Imposed; do
    grep -q "Name=\"$array\"" "$out/brain_surface.vtp" || fail "brain_surface.vtp lacks the point array $array"
  done
  for key in wall_seconds surface_nodes imposed_nodes mean_residual_mm iterations converged free_nodes; do
    json_value "$out/report.json" "['stages']['surface']['$key']" >/dev/null || fail "report.json lacks surface.$key"
  done
  float_check "$out/report.json" "['stages']['surface']['mean_residual_mm']" "< 1.0"
  float_check "$out/report.json" "['stages']['surface']['max_displacement_mm']" "> 3"
  # The truth's labels as the target: the displacements follow the true shift.
  cp "$case_dir/truth/intraop_labels.nii.gz" "$out/intraop_labels.nii.gz"
  "$brainshift" surface --preop-labels "$L" --intraop-image "$I" --output-dir "$out" >/dev/null || fail "surface exited $?"
  cp "$out/brain_surface.vtp" "$out/first.vtp"
  "$brainshift" surface --preop-labels "$L" --intraop-image "$I" --output-dir "$out" >/dev/null || fail "surface exited $?"
  cmp -s "$out/brain_surface.vtp" "$out/first.vtp" || fail "surface is not deterministic"
  # Bad input: an intraoperative segmentation without brain, a corrupt mesh, a missing classification.
  python3 - "$case_dir/intraop_image.nii.gz" "$out/empty_labels.nii.gz" <<'PY'
import gzip, struct, sys
# The intraoperative image's header (its grid), as unsigned 16-bit zeros: a segmentation without brain.
raw = gzip.open(sys.argv[1], 'rb').read()
hdr = bytearray(raw[:348])
dims = struct.unpack_from('<8h', hdr, 40)
offset = int(struct.unpack_from('<f', hdr, 108)[0])
struct.pack_into('<h', hdr, 70, 512)  # uint16
struct.pack_into('<h', hdr, 72, 16)
struct.pack_into('<2f', hdr, 112, 1.0, 0.0)  # scl_slope, scl_inter
count = dims[1] * dims[2] * dims[3]
with gzip.open(sys.argv[2], 'wb') as f:
    f.write(bytes(hdr) + raw[348:offset] + b'\0' * (2 * count))
PY
  mkdir -p "$out/empty" && cp "$out/mesh.vtu" "$out/rigid_intraop_to_preop.tfm" "$out/empty/"
  cp "$out/empty_labels.nii.gz" "$out/empty/intraop_labels.nii.gz"
  expect 2 "holds no brain" -- "$brainshift" surface --preop-labels "$L" --intraop-image "$I" --output-dir "$out/empty"
  [ -e "$out/empty/brain_surface.vtp" ] && fail "a surface was written for an empty segmentation"
  mkdir -p "$out/corrupt" && cp "$out/rigid_intraop_to_preop.tfm" "$out/intraop_labels.nii.gz" "$out/corrupt/"
  head -c 2000 "$out/mesh.vtu" > "$out/corrupt/mesh.vtu"
  expect 2 "corrupt/mesh.vtu: the model has no points" -- "$brainshift" surface --preop-labels "$L" --intraop-image "$I" --output-dir "$out/corrupt"
  rm "$out/intraop_labels.nii.gz"
  expect 2 "run \`brainshift classify\`" -- "$brainshift" surface --preop-labels "$L" --intraop-image "$I" --output-dir "$out"
  ;;

SimulateStage)
  source_case=$(dirname "$work")/SimulateStageCase
  out=$work/simulate-stage
  rm -rf "$out" && mkdir -p "$out"
  cp "$source_case/mesh.vtu" "$source_case/brain_surface.vtp" "$out/"
  "$brainshift" simulate --output-dir "$out" --ranks 2 >/dev/null || fail "simulate exited $?"
  grep -q 'Name="Displacement"' "$out/mesh.vtu" || fail "mesh.vtu has no point array Displacement"
  for key in wall_seconds equations ranks iterations relative_residual assembly_seconds setup_seconds solve_seconds; do
    json_value "$out/report.json" "['stages']['simulate']['$key']" >/dev/null || fail "report.json lacks simulate.$key"
  done
  [ "$(json_value "$out/report.json" "['stages']['simulate']['ranks']")" = "2" ] || fail "simulate did not run on 2 ranks"
  # The tuned default for a one-shot solve of this size, to its tolerance (1e-5, preconditioned).
  [ "$(json_value "$out/report.json" "['stages']['simulate']['solver']")" = "cg+bjacobi/icc" ] || fail "not the tuned default solver"
  float_check "$out/report.json" "['stages']['simulate']['relative_residual']" "< 1e-4"
  # The paper's solver, through the options.
  "$brainshift" simulate --output-dir "$out" --solver-options "-ksp_type gmres -pc_type bjacobi -sub_pc_type ilu" >/dev/null || fail "gmres exited $?"
  [ "$(json_value "$out/report.json" "['stages']['simulate']['solver']")" = "gmres+bjacobi/ilu" ] || fail "the solver options were not used"
  printf '{"materials": {"4": {"poisson_ratio": 0.5}}}' > "$out/incompressible.json"
  expect 2 "poisson_ratio" -- "$brainshift" simulate --output-dir "$out" --config "$out/incompressible.json"
  expect 1 "did not converge" -- "$brainshift" simulate --output-dir "$out" --solver-options "-ksp_type cg -pc_type none -ksp_max_it 1"
  rm "$out/brain_surface.vtp"
  expect 2 "brain_surface.vtp: no such file" -- "$brainshift" simulate --output-dir "$out"
  ;;

DemoEndToEnd)
  for f in report.json evaluation.json case/case.json case/scene.mrml case/landmarks.csv case/preop_image.nii.gz \
    case/preop_labels.nii.gz case/preop_fmri.nii.gz case/intraop_image.nii.gz case/truth/intraop_labels.nii.gz \
    case/truth/intraop_to_preop.h5 case/truth/rigid_intraop_to_preop.tfm; do
    [ -s "$demo/$f" ] || fail "demo did not write $f"
  done
  find "$demo" -name '.tmp-*' | grep -q . && fail "temporary files left in $demo"
  float_check "$demo/evaluation.json" "['transforms']['truth']['mean_mm']" "< 0.02"
  float_check "$demo/evaluation.json" "['transforms']['identity']['mean_mm']" "> 8"
  float_check "$demo/report.json" "['demo']['case_seconds']" "> 0"
  [ "$(json_value "$demo/evaluation.json" "['pipeline_complete']")" = "True" ] || fail "the demo's pipeline did not complete"
  float_check "$demo/evaluation.json" "['transforms']['brainshift']['mean_mm']" "< 0.7 * $(json_value "$demo/evaluation.json" "['transforms']['brainshift_rigid']['mean_mm']")"
  [ -s "$demo/rigid_intraop_to_preop.tfm" ] || fail "the demo's register did not run the rigid stage"
  float_check "$demo/evaluation.json" "['transforms']['brainshift_rigid']['groups']['head']['max_mm']" "< 0.6"
  [ -s "$demo/intraop_labels.nii.gz" ] || fail "the demo's register did not run the classify stage"
  [ -s "$demo/mesh.vtu" ] || fail "the demo's register did not run the mesh stage"
  float_check "$demo/evaluation.json" "['classification']['brain_dice']" ">= 0.95"
  float_check "$demo/evaluation.json" "['classification']['brain_surface_distance_mm']" "<= 1.0"
  [ -s "$demo/brain_surface.vtp" ] || fail "the demo's register did not run the surface stage"
  grep -q 'Name="Displacement"' "$demo/mesh.vtu" || fail "the demo's register did not run the simulate stage"
  float_check "$demo/evaluation.json" "['surface']['mean_error_mm']" "< 1.5"
  float_check "$demo/evaluation.json" "['surface']['moving_mean_error_mm']" "< 0.5 * $(json_value "$demo/evaluation.json" "['surface']['moving_true_mean_displacement_mm']")"
  ;;

HardScenario)
  # A hard scenario end to end (small): a 15 mm sink under a right frontal craniotomy, fluid under
  # air in the gap and the cavity, a bright cavity rim, 5 % noise, 30 % bias. Measured: TRE 0.56 mm
  # mean against 2.51 for the rigid registration, p95 1.14 against 8.15, craniotomy 0.90 against
  # 6.56, near the cavity 0.81 against 6.41 (0.56, 1.37, 0.90, 0.87 before the blocks were spread
  # over the brain; 0.65, 1.65, 0.88, 0.88 with the tumour kept in place; 0.94, 2.29, 1.40, 1.34
  # before the gap took the fluid pooled over the sunken brain).
  hard=$work/hard-scenario
  rm -rf "$hard"
  "$brainshift" demo --size small --scenario rf15-cavityrim --output-dir "$hard" > "$work/hard-scenario.log" 2>&1 \
    || fail "demo --scenario rf15-cavityrim failed: $(tail -n 3 "$work/hard-scenario.log")"
  e=$hard/evaluation.json
  rigid_mean=$(json_value "$e" "['transforms']['brainshift_rigid']['mean_mm']")
  rigid_p95=$(json_value "$e" "['transforms']['brainshift_rigid']['p95_mm']")
  rigid_craniotomy=$(json_value "$e" "['transforms']['brainshift_rigid']['groups']['craniotomy']['mean_mm']")
  rigid_cavity=$(json_value "$e" "['transforms']['brainshift_rigid']['groups']['near-cavity']['mean_mm']")
  float_check "$e" "['transforms']['brainshift']['mean_mm']" "< 0.5 * $rigid_mean"
  float_check "$e" "['transforms']['brainshift']['mean_mm']" "< 1.2"
  float_check "$e" "['transforms']['brainshift']['p95_mm']" "< 0.4 * $rigid_p95"
  float_check "$e" "['transforms']['brainshift']['groups']['craniotomy']['mean_mm']" "< 0.3 * $rigid_craniotomy"
  float_check "$e" "['transforms']['brainshift']['groups']['near-cavity']['mean_mm']" "< 0.3 * $rigid_cavity"
  [ "$(json_value "$hard/report.json" "['trust']['nonrigid']")" = "trusted" ] || fail "the hard scenario's update was not trusted"
  # The brain boundary under the craniotomy, as the whole transform shows it: measured 1.15 mm mean
  # against 7.50 for the rigid registration (the surface's nodes stop short on this coarse case).
  # 1.23 with the tumour kept in place, 2.00 before the classification's gap took the fluid pooled over the sunken brain
  # (classify.fluid_joined_to_gaps_ml), 2.98 before the field carried the correction across the
  # boundary: both fail the bound.
  rigid_boundary=$(json_value "$e" "['boundary_under_craniotomy']['shown']['brainshift_rigid']['mean_abs_mm']")
  float_check "$e" "['boundary_under_craniotomy']['shown']['brainshift']['mean_abs_mm']" "< 0.22 * $rigid_boundary"
  # Both ways (from the shown boundary too, which sees preoperative brain left in the gap): 1.21
  # against 8.07 for the rigid registration.
  rigid_both=$(json_value "$e" "['boundary_under_craniotomy']['shown']['brainshift_rigid']['symmetric_mean_abs_mm']")
  float_check "$e" "['boundary_under_craniotomy']['shown']['brainshift']['symmetric_mean_abs_mm']" "< 0.22 * $rigid_both"
  float_check "$hard/report.json" "['stages']['classify']['fluid_joined_to_gaps_ml']" "> 0.2"
  float_check "$hard/report.json" "['stages']['surface']['directional_nodes']" "> 100"
  # The tumour was resected, but at 15 mm its place through the rigid prior holds the tissue that
  # sank into it: the first classification keeps it. Where the first solve put the tumour, 27.5 % of
  # it looks like fluid and 5.8 % like air (the air's bound 5 %, which decides alone for a tumour
  # that looked like the parenchyma; 8.4-16.8 % on the full-size scenarios, at most 2.2 % where the
  # tumour stayed): decided resected, classified again.
  # Kept in place, the case measured 0.65 / 1.65 mm, craniotomy 0.88, near the cavity 0.88
  # (0.62 / 1.42, 0.76, 0.81 resected).
  [ "$(json_value "$hard/report.json" "['stages']['refine']['tumour_where_solved']['resected']")" = True ] ||
    fail "where the first solve put the tumour, its resection was not seen"
  [ "$(json_value "$hard/report.json" "['stages']['classify']['tumour_evidence']['decided_by']")" = "the tumour where the first solve put it" ] ||
    fail "the classification did not take the decision made where the solve put the tumour"
  [ "$(json_value "$hard/report.json" "['stages']['classify']['tumour_resected']")" = True ] || fail "the hard scenario's tumour was kept"
  # Here the look is the late one, on the solve with the block matches (the early one, on the
  # surface's solve, saw 30 % like fluid: below), and the pass after it solved on the worker the
  # first solve started.
  [ "$(json_value "$hard/report.json" "['stages']['simulate']['block_matching']['used']")" = True ] ||
    fail "the pass after the second look did not match the blocks"
  [ "$(grep -c "simulate: partition" "$work/hard-scenario.log")" = 1 ] || fail "the second look's solve started another worker"
  # Every pass counted once, from the first stage to the last: at least the stages that ran once
  # and the refine stage, which holds the second pass.
  once_seconds=$(json_value "$hard/report.json" "['stages']['rigid']['wall_seconds'] + d['stages']['mesh']['wall_seconds'] + d['stages']['refine']['wall_seconds'] + d['stages']['warp']['wall_seconds']")
  float_check "$hard/report.json" "['pipeline_wall_seconds']" "> $once_seconds"
  # The refine stage (by default only in T2-like scans: elsewhere it made the scenarios worse,
  # README) runs when asked and reports each pass.
  printf '{"classification": {"refinement_passes": 1}}\n' > "$work/hard-refine.json"
  "$brainshift" refine --preop-image "$hard/case/preop_image.nii.gz" --preop-labels "$hard/case/preop_labels.nii.gz" \
    --intraop-image "$hard/case/intraop_image.nii.gz" --output-dir "$hard" --config "$work/hard-refine.json" >/dev/null \
    || fail "refine exited $?"
  float_check "$hard/report.json" "['stages']['refine']['passes']" "== 1"
  float_check "$hard/report.json" "['stages']['refine']['per_pass'][0]['mean_change_mm']" ">= 0"
  grep -q "warped by refine pass 1" "$hard/report.json" || fail "refine did not classify with the warped prior"
  mkdir -p "$work/refine-empty"
  expect 2 "rigid_intraop_to_preop.tfm: not found; run \`brainshift rigid\`" -- "$brainshift" refine \
    --preop-image "$hard/case/preop_image.nii.gz" --preop-labels "$hard/case/preop_labels.nii.gz" \
    --intraop-image "$hard/case/intraop_image.nii.gz" --output-dir "$work/refine-empty"
  [ "$(json_value "$hard/case/case.json" "['parameters']['gap']")" = "fluid-and-air" ] || fail "the scenario's gap is not fluid and air"
  # The early look: at 20 mm (small rf20) the surface's solve alone already puts the tumour where
  # 79 % of it looks like fluid and 11 % like air (measured); the first solve then leaves the block
  # matches to the pass that classifies again, which matches them once.
  deep=$work/hard-scenario-rf20
  rm -rf "$deep"
  "$brainshift" demo --size small --scenario rf20-lowfield --output-dir "$deep" > "$work/hard-scenario-rf20.log" 2>&1 \
    || fail "demo --scenario rf20-lowfield failed: $(tail -n 3 "$work/hard-scenario-rf20.log")"
  [ "$(json_value "$deep/report.json" "['stages']['refine']['tumour_where_solved']['on']")" = "the surface's solve, before the block matches" ] ||
    fail "rf20: the tumour's second look was not made on the surface's solve"
  grep -q "simulate: block matching waits: where the surface's solve puts the tumour overturns" "$work/hard-scenario-rf20.log" ||
    fail "rf20: the first solve matched blocks the second look discards"
  [ "$(grep -c "simulate: block matching waits" "$work/hard-scenario-rf20.log")" = 1 ] || fail "rf20: block matching waited in more than the first solve"
  [ "$(json_value "$deep/report.json" "['stages']['simulate']['block_matching']['used']")" = True ] ||
    fail "rf20: the pass after the second look did not match the blocks"
  [ "$(json_value "$deep/report.json" "['stages']['classify']['tumour_resected']")" = True ] || fail "rf20: the tumour was kept"
  [ "$(grep -c "simulate: partition" "$work/hard-scenario-rf20.log")" = 1 ] || fail "rf20: the second look's solve started another worker"
  ;;

SuperficialTumour)
  # A nearly isointense tumour left in place, reaching the cortex under a 15 mm sink (small
  # lp15-fe-superficial-intact: the truth from CalculiX, the brain surface sliding). It sank with
  # the brain: its place through the rigid prior holds the gap's fluid, and the first classification
  # finds it resected. Where the first solve put it, 0.7 % of it looks like fluid and none like air:
  # in place, classified again on the labels warped by that solve. Measured: TRE 0.58 / 1.37 mm,
  # tumour margin 1.04, craniotomy 1.01 (0.77 / 1.98, 1.46, 1.36 before the blocks were spread
  # over the brain); left resected (as before the look went both ways, or with
  # classification.tumour_second_look off) 1.06 / 3.08, 2.64, 1.92, with the blocks as before.
  superficial=$work/superficial-tumour
  rm -rf "$superficial"
  "$brainshift" demo --size small --scenario lp15-fe-superficial-intact --output-dir "$superficial" > "$work/superficial-tumour.log" 2>&1 \
    || fail "demo --scenario lp15-fe-superficial-intact failed: $(tail -n 3 "$work/superficial-tumour.log")"
  r=$superficial/report.json
  float_check "$superficial/case/case.json" "['parameters']['tumour_depth_mm']" "== 13"
  [ "$(json_value "$superficial/case/case.json" "['parameters']['resection']")" = False ] || fail "the scenario's tumour is not in place"
  [ "$(json_value "$r" "['stages']['refine']['tumour_where_solved']['first_look_resected']")" = True ] ||
    fail "the first classification did not find the sunken tumour resected (the case no longer tests the look)"
  [ "$(json_value "$r" "['stages']['refine']['tumour_where_solved']['resected']")" = False ] ||
    fail "where the first solve put the tumour, it was not seen in place"
  float_check "$r" "['stages']['refine']['tumour_where_solved']['evidence']['air_like_share']" "< 0.05"
  [ "$(json_value "$r" "['stages']['classify']['tumour_resected']")" = False ] || fail "the tumour in place was left resected"
  [ "$(json_value "$r" "['stages']['classify']['tumour_evidence']['decided_by']")" = "the tumour where the first solve put it" ] ||
    fail "the classification did not take the decision made where the solve put the tumour"
  grep -q "warped by the first solve" "$r" || fail "the tumour in place was not classified on the labels warped by the first solve"
  grep -q "in place, not resected as its place through the rigid prior said" "$work/superficial-tumour.log" ||
    fail "the overturned decision was not said"
  grep -q "the tumour looks resected" "$r" && fail "report.json still warns that the tumour looks resected"
  # The surface fitted again replaces the first fit's warnings (both were listed, with their counts).
  refits=$(python3 -c "import json, sys; print(sum('surface nodes stayed farther' in w for w in json.load(open(sys.argv[1]))['warnings']))" "$r")
  [ "$refits" -le 1 ] || fail "report.json lists $refits fits' free surface nodes, the first pass's beside the decision pass's"
  [ "$(json_value "$r" "['stages']['simulate']['block_matching']['used']")" = True ] || fail "the pass in place did not match the blocks"
  e=$superficial/evaluation.json
  float_check "$e" "['transforms']['brainshift']['mean_mm']" "< 0.9"
  float_check "$e" "['transforms']['brainshift']['p95_mm']" "< 2.5"
  float_check "$e" "['transforms']['brainshift']['groups']['tumour-margin']['mean_mm']" "< 2.0"
  ;;

ImageDrivenInterior)
  # Block matching inside the brain and its matches in the solve (on by default), on a small case
  # with 8 % noise and a resection (blocks that disagree): the matches are used, the misfit falls,
  # and the update is never worse than the surface-driven one alone by more than 0.1 mm (measured
  # 0.61 against 0.73 mm); the confidence map is written and calls reliable what is (98 %).
  interior=$work/image-driven
  rm -rf "$interior" "$interior-surface-only"
  "$brainshift" demo --size small --scenario lf15-noise8 --output-dir "$interior" > "$work/image-driven.log" 2>&1 \
    || fail "demo --scenario lf15-noise8 failed: $(tail -n 3 "$work/image-driven.log")"
  r=$interior/report.json
  [ "$(json_value "$r" "['stages']['simulate']['block_matching']['used']")" = "True" ] || fail "block matching was not used"
  # (The rejection itself is shown on known outliers by FiniteElementSoftConstraintTest; here, at
  # the default stiffness, it drops a gross outlier or none: 1 of 2,809 measured.)
  float_check "$r" "['stages']['simulate']['block_matching']['kept']" "> 1000"
  # The blocks spread over 8 mm cubes: every cube holding candidates gets one before any gets two.
  float_check "$r" "['stages']['simulate']['block_matching']['selection']['cell_mm']" "== 8"
  cells=$(json_value "$r" "['stages']['simulate']['block_matching']['selection']['cells']")
  selected=$(json_value "$r" "['stages']['simulate']['block_matching']['selected']")
  float_check "$r" "['stages']['simulate']['block_matching']['selection']['cells_with_a_block']" "== min($cells, $selected)"
  constraints=$(json_value "$r" "['stages']['simulate']['block_matching']['constraints']")
  float_check "$r" "['stages']['simulate']['block_matching']['kept'] + d['stages']['simulate']['block_matching']['rejected']" "== $constraints"
  float_check "$r" "['stages']['simulate']['block_matching']['solves']" ">= 1"
  before=$(json_value "$r" "['stages']['simulate']['block_matching']['rms_misfit_surface_only_mm']")
  float_check "$r" "['stages']['simulate']['block_matching']['rms_misfit_per_solve_mm'][-1]" "< 0.7 * $before"
  [ -s "$interior/block_matches.vtp" ] || fail "block_matches.vtp not written"
  [ -s "$interior/displacement_uncertainty_mm.nii.gz" ] || fail "the confidence map was not written"
  grep -q "displacement_uncertainty_mm.nii.gz" "$interior/scene.mrml" || fail "the confidence map is not in the scene"
  float_check "$interior/evaluation.json" "['uncertainty']['called_below_1mm_truly_below_1_5mm']" ">= 0.9"
  printf '{"block_matching": {"enabled": false}}\n' > "$work/surface-only.json"
  c=$interior/case
  "$brainshift" register --preop-image "$c/preop_image.nii.gz" --preop-labels "$c/preop_labels.nii.gz" \
    --intraop-image "$c/intraop_image.nii.gz" --output-dir "$interior-surface-only" --config "$work/surface-only.json" >/dev/null \
    || fail "register without block matching exited $?"
  "$brainshift" evaluate --transform "$interior-surface-only/intraop_to_preop.h5" --landmarks "$c/landmarks.csv" \
    --json "$interior-surface-only/evaluation.json" >/dev/null || fail "evaluate exited $?"
  surface_only=$(json_value "$interior-surface-only/evaluation.json" "['mean_mm']")
  float_check "$interior/evaluation.json" "['transforms']['brainshift']['mean_mm']" "<= $surface_only + 0.1"
  [ "$(json_value "$interior-surface-only/report.json" "['stages']['simulate']['block_matching']['enabled']")" = "False" ] \
    || fail "block matching ran although disabled"
  ;;

SlabFieldOfView)
  # A partial field of view (issue 20): the small rf10-slab scenario, 15 axial slices of 5 mm around
  # the craniotomy, registered end to end (demo runs register on it). Measured: TRE 0.44 mm mean against 1.51 for the rigid
  # registration, p95 1.01 against 4.07; 4,862 of 8,972 surface nodes outside the slab, held.
  slab=$work/slab
  rm -rf "$slab"
  "$brainshift" demo --size small --scenario rf10-slab --output-dir "$slab/demo" > "$work/slab.log" 2>&1 \
    || fail "demo --scenario rf10-slab failed: $(tail -n 3 "$work/slab.log")"
  c=$slab/demo/case
  [ "$(json_value "$c/case.json" "['parameters']['field_of_view']")" = "slab" ] || fail "case.json: the field of view is not a slab"
  float_check "$c/case.json" "['figures']['intraop_grid_size'][2]" "== 15"
  r=$slab/demo # what demo's `register` wrote
  for t in rigid_intraop_to_preop.tfm intraop_to_preop.h5; do
    "$brainshift" evaluate --transform "$r/$t" --landmarks "$c/landmarks.csv" --json "$r/tre-${t%%.*}.json" >/dev/null \
      || fail "evaluate $t exited $?"
  done
  rigid_mean=$(json_value "$r/tre-rigid_intraop_to_preop.json" "['mean_mm']")
  rigid_p95=$(json_value "$r/tre-rigid_intraop_to_preop.json" "['p95_mm']")
  float_check "$r/tre-intraop_to_preop.json" "['mean_mm']" "< 0.75 * $rigid_mean"
  float_check "$r/tre-intraop_to_preop.json" "['mean_mm']" "< 1.2"
  float_check "$r/tre-intraop_to_preop.json" "['p95_mm']" "< 0.55 * $rigid_p95"
  [ "$(json_value "$r/report.json" "['trust']['nonrigid']")" = "trusted" ] || fail "the slab's update was not trusted"
  float_check "$r/report.json" "['stages']['surface']['held_outside_image']" "> 1000"
  float_check "$r/report.json" "['stages']['surface']['field_of_view']['surface_nodes_inside']" \
    "< 0.7 * $(json_value "$r/report.json" "['stages']['surface']['surface_nodes']")"
  # The dense field, the classification and the warped volumes lie on the slab's grid.
  python3 - "$c/intraop_image.nii.gz" "$r" <<'PY' || fail "an output is not on the slab's grid (see above)"
import gzip, struct, sys, re
def grid(path):
    h = gzip.open(path).read(348)
    dims = struct.unpack_from('<8h', h, 40)[1:4]
    pixdim = [round(v, 4) for v in struct.unpack_from('<8f', h, 76)[1:4]]
    srow = [round(v, 3) for r in range(3) for v in struct.unpack_from('<4f', h, 280 + 16 * r)]
    return dims, pixdim, srow
reference = grid(sys.argv[1])
assert reference[0][2] == 15, reference
bad = []
for name in ('warped_preop_image', 'warped_preop_labels', 'warped_fmri', 'intraop_labels', 'displacement_uncertainty_mm'):
    try:
        if grid('%s/%s.nii.gz' % (sys.argv[2], name)) != reference: bad.append(name)
    except FileNotFoundError:
        if name != 'displacement_uncertainty_mm': bad.append(name + ' (missing)')
header = open(sys.argv[2] + '/displacement_intraop_to_preop.nrrd', 'rb').read(2000).decode('latin-1')
sizes = re.search(r'sizes: 3 (\d+) (\d+) (\d+)', header)
if not sizes or tuple(int(v) for v in sizes.groups()) != reference[0]: bad.append('displacement_intraop_to_preop.nrrd')
if bad: print('not on the slab grid %s: %s' % (reference, bad), file=sys.stderr); sys.exit(1)
PY
  ;;

SlabTooThin)
  # A later scan that covers too little of the brain (4 axial slices of 5 mm through its middle,
  # started from the small case's earlier registration): refused as bad input, exit 2, with the
  # share of the brain surface and the brain volume inside the field of view in the message.
  thin=$work/slab-thin
  rm -rf "$thin" && mkdir -p "$thin"
  python3 - "$case_dir/intraop_image.nii.gz" "$thin/intraop_4_slices.nii.gz" 14 4 <<'PY' || fail "cannot cut the thin scan"
import gzip, struct, sys
src, dst, first, count = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
data = bytearray(gzip.open(src).read())
offset = int(struct.unpack_from('<f', data, 108)[0])
dims = list(struct.unpack_from('<8h', data, 40))
plane = dims[1] * dims[2] * struct.unpack_from('<h', data, 72)[0] // 8
header = bytearray(data[:offset])
dims[3] = count
struct.pack_into('<8h', header, 40, *dims)
srow = [list(struct.unpack_from('<4f', header, 280 + 16 * r)) for r in range(3)]
q = list(struct.unpack_from('<3f', header, 268))
for r in range(3):  # the origin moves with the first slice kept (sform and qform)
    q[r] += first * srow[r][2]
    srow[r][3] += first * srow[r][2]
    struct.pack_into('<4f', header, 280 + 16 * r, *srow[r])
struct.pack_into('<3f', header, 268, *q)
gzip.open(dst, 'wb').write(bytes(header + data[offset + first * plane: offset + (first + count) * plane]))
PY
  expect 2 "covers too little of the brain to match its surface" -- "$brainshift" register \
    --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --intraop-image "$thin/intraop_4_slices.nii.gz" --previous "$demo" --output-dir "$thin/out"
  "$brainshift" register --preop-image "$case_dir/preop_image.nii.gz" --preop-labels "$case_dir/preop_labels.nii.gz" \
    --intraop-image "$thin/intraop_4_slices.nii.gz" --previous "$demo" --output-dir "$thin/out" 2> "$thin/stderr" >/dev/null
  grep -qE "[0-9]+ % of the brain surface nodes \([0-9]+ of [0-9]+\) and [0-9]+ ml of the [0-9]+ ml brain" "$thin/stderr" \
    || fail "the refusal does not name the figures: $(cat "$thin/stderr")"
  [ -e "$thin/out/warped_preop_image.nii.gz" ] && fail "a refused update wrote warped volumes"
  ;;

OtherContrast)
  # The small case seen by a T2-weighted scanner (fluid bright, white matter dark, air dark under
  # the craniotomy and in the cavity), then by a T1 post-contrast one (enhancing cavity wall and
  # dura). T2: the classification finds the brain and the resection, the update is better than the
  # rigid registration and shown (not rejected); the same case's segmentation moved 7.5 mm gives an
  # update that is rejected. Measured: T2 update 1.16 mm mean against 1.53 rigid, brain Dice 0.954,
  # trust doubtful (eta^2 gain +0.005, W given I), the moved segmentation's gain -0.20; before
  # this work 1.91 against 1.53, Dice 0.885, rejected. T1 post-contrast: 0.78 against 1.63, trusted.
  other=$work/other-contrast
  rm -rf "$other"
  "$brainshift" demo --size small --scenario rf10-t2 --output-dir "$other/t2" > "$work/other-contrast-t2.log" 2>&1 ||
    fail "demo --scenario rf10-t2 exited $?: $(tail -n 3 "$work/other-contrast-t2.log")"
  e=$other/t2/evaluation.json r=$other/t2/report.json
  rigid_mean=$(json_value "$e" "['transforms']['brainshift_rigid']['mean_mm']")
  float_check "$e" "['transforms']['brainshift']['mean_mm']" "< 0.85 * $rigid_mean"
  [ "$(json_value "$r" "['trust']['nonrigid']")" != rejected ] || fail "T2: the update was rejected"
  [ "$(json_value "$r" "['trust']['rigid_fallback']")" = False ] || fail "T2: the files hold the rigid fallback"
  float_check "$e" "['classification']['brain_dice']" "> 0.93"
  [ "$(json_value "$r" "['stages']['classify']['tumour_resected']")" = True ] || fail "T2: the resection was not found"
  [ "$(json_value "$r" "['stages']['classify']['contrast']['fluid']")" = "brighter than the parenchyma" ] ||
    fail "T2: the classification did not learn that fluid is bright"
  float_check "$r" "['stages']['surface']['outside_sides']" "== 2"
  # The T2 segmentation draws the whole brain boundary inside the preoperative one (measured 1.78 mm
  # on the small case, its deep brain 1.06 mm off against rigid's 0.39): reported and warned of,
  # beyond a third of the scan's 3.15 mm voxel.
  float_check "$r" "['stages']['surface']['boundary_offset']['median_normal_mm']" "< -1.2"
  float_check "$r" "['stages']['surface']['boundary_offset']['warning_beyond_mm']" "> 1.0"
  offset_warned "$r" || fail "T2: no warning of the segmentation's offset at the brain boundary"
  # Fluid brighter than the parenchyma: one refine pass by default (refinement_passes "auto"),
  # which keeps the first classification's tumour decision.
  float_check "$r" "['stages']['refine']['passes']" "== 1"
  [ "$(json_value "$r" "['stages']['refine']['passes_from']")" = "auto: the scan's fluid is brighter than its parenchyma" ] ||
    fail "T2: the refine stage did not choose its pass from the contrast"
  [ "$(json_value "$r" "['stages']['classify']['tumour_evidence']['decided_by']")" = "the first classification (through the rigid prior)" ] ||
    fail "T2: the refine pass did not keep the first tumour decision"
  # The refine pass keeps the first solve's block matches (the same tumour decision), held against
  # its own classification: none matched anew, and some still in the brain.
  [ "$(json_value "$r" "['stages']['simulate']['block_matching']['matches_from']")" = \
    "this scan's earlier solve, held against this pass's classification" ] || fail "T2: the refine pass matched its blocks again"
  float_check "$r" "['stages']['simulate']['block_matching']['kept']" "> 100"
  # The T2 case's segmentation moved 3 voxels (7.5 mm) along the first grid axis: rejected.
  mkdir -p "$other/t2-moved"
  shift_labels_along_first_axis "$other/t2/intraop_labels.nii.gz" "$other/t2-moved/intraop_labels.nii.gz"
  c=$other/t2/case
  cp "$other/t2/rigid_intraop_to_preop.tfm" "$other/t2/mesh.vtu" "$other/t2-moved/"
  "$brainshift" surface --preop-labels "$c/preop_labels.nii.gz" --intraop-image "$c/intraop_image.nii.gz" --output-dir "$other/t2-moved" >/dev/null ||
    fail "T2 moved: surface exited $?"
  "$brainshift" simulate --output-dir "$other/t2-moved" >/dev/null || fail "T2 moved: simulate exited $?"
  expect 1 "the non-rigid update is rejected" -- "$brainshift" warp --preop-image "$c/preop_image.nii.gz" \
    --preop-labels "$c/preop_labels.nii.gz" --intraop-image "$c/intraop_image.nii.gz" --output-dir "$other/t2-moved"
  float_check "$other/t2-moved/report.json" "['trust']['moved']['gain']" "< -0.05"
  # T1 post-contrast.
  "$brainshift" demo --size small --scenario rf10-t1post --output-dir "$other/t1post" > "$work/other-contrast-t1post.log" 2>&1 ||
    fail "demo --scenario rf10-t1post exited $?: $(tail -n 3 "$work/other-contrast-t1post.log")"
  e=$other/t1post/evaluation.json
  [ "$(json_value "$other/t1post/case/case.json" "['parameters']['contrast']")" = "t1-post-contrast" ] || fail "case.json: not t1-post-contrast"
  rigid_mean=$(json_value "$e" "['transforms']['brainshift_rigid']['mean_mm']")
  float_check "$e" "['transforms']['brainshift']['mean_mm']" "< 0.6 * $rigid_mean"
  [ "$(json_value "$other/t1post/report.json" "['trust']['nonrigid']")" = "trusted" ] || fail "T1 post-contrast: the update was not trusted"
  float_check "$other/t1post/report.json" "['stages']['surface']['outside_sides']" "== 1"
  # Its segmentation's offset (measured -0.31 mm) is within a third of a voxel: no warning.
  float_check "$other/t1post/report.json" "['stages']['surface']['boundary_offset']['nodes']" "> 4000"
  ! offset_warned "$other/t1post/report.json" || fail "T1 post-contrast: warned of a segmentation offset"
  float_check "$other/t1post/report.json" "['stages']['refine']['passes']" "== 0"
  [ "$(json_value "$other/t1post/report.json" "['stages']['refine']['passes_from']")" = "auto: the scan's fluid is darker than its parenchyma" ] ||
    fail "T1 post-contrast: the refine stage did not choose no pass from the contrast"
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
