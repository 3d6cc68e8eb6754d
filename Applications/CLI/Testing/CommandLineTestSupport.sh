# shellcheck shell=bash
# What the command-line test scripts share (BrainShiftCommandLineTest.sh, BrainShiftReliabilityTest.sh,
# InteropCommandLineTest.sh source it): failures counted in `failures`, a command's exit status and
# one-line stderr checked, values read from JSON files.

failures=0

fail() { echo "FAILED: $*" >&2; failures=$((failures + 1)); }

# expect STATUS STDERR_FRAGMENT -- command...: runs the command, checks the exit status, that
# stderr is one line (when the status is not 0) and that it contains the fragment.
expect() {
  local status=$1 fragment=$2
  shift 3
  local err
  err=$(mktemp)
  "$@" >/dev/null 2>"$err"
  local got=$?
  if [ "$got" -ne "$status" ]; then
    fail "exit $got, expected $status: $* (stderr: $(cat "$err"))"
  elif [ "$status" -ne 0 ] && [ "$(grep -c . "$err")" -ne 1 ]; then
    fail "stderr is not one line: $* -> $(cat "$err")"
  elif [ -n "$fragment" ] && ! grep -qF -- "$fragment" "$err"; then
    fail "stderr lacks '$fragment': $* -> $(cat "$err")"
  fi
  rm -f "$err"
}

json_value() { python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(eval('d'+sys.argv[2]))" "$1" "$2"; }
# float_check FILE PYTHON_EXPR CONDITION: e.g. float_check x.json "['mean_mm']" "< 0.02"
float_check() {
  local value
  value=$(json_value "$1" "$2") || { fail "cannot read $2 from $1"; return; }
  python3 -c "import sys; sys.exit(0 if float('$value') $3 else 1)" || fail "$1 $2 = $value, expected $3"
}

# offset_warned REPORT: whether the surface stage warned of the segmentation's offset at the brain boundary.
offset_warned() {
  python3 - "$1" <<'PY'
import json, sys
sys.exit(0 if any("intraoperative brain boundary lies" in w for w in json.load(open(sys.argv[1]))["warnings"]) else 1)
PY
}

checksums() { find "$@" -type f -print0 | sort -z | xargs -0 sha256sum; }

# shift_labels_along_first_axis IN.nii.gz OUT.nii.gz: a damaged segmentation, the label map moved
# 3 voxels along its first grid axis (what enters at the edge is 0). For uncompressed-header NIfTI-1
# label maps as the classify stage writes them.
shift_labels_along_first_axis() {
  python3 - "$1" "$2" <<'PY'
import gzip, struct, sys
raw = gzip.open(sys.argv[1], 'rb').read()
dims = struct.unpack_from('<8h', raw, 40)
size = struct.unpack_from('<h', raw, 72)[0] // 8
offset = int(struct.unpack_from('<f', raw, 108)[0])
nx, rows, k = dims[1], dims[2] * dims[3], 3
data = bytearray(raw[offset:])
out = bytearray(len(data))
row = nx * size
for r in range(rows):
    out[r * row + k * size:(r + 1) * row] = data[r * row:(r + 1) * row][: row - k * size]
with gzip.open(sys.argv[2], 'wb') as f:
    f.write(raw[:offset] + bytes(out))
PY
}
