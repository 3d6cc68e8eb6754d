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

checksums() { find "$@" -type f -print0 | sort -z | xargs -0 sha256sum; }
