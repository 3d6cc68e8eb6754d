#!/usr/bin/env bash
# Calibration of the rigid registration's trust across intraoperative contrasts: every built-in
# scenario (T1, low-field T1, T2, FLAIR, T1 post-contrast, slabs) and the default case in each
# contrast, small and full size, then poses known to be wrong (the truth turned 5 to 20 degrees,
# as it is and after the finest level optimized from it). Each row: the normalized mutual
# information (NMI) at the result, the highest and mean NMI of the same samples at the 12 poses
# displaced 15 mm / 15 degrees, the gain (NMI - 1) / (displaced - 1) the trust reads, the head
# landmarks' TRE against the true rigid motion.
#
#   Testing/Benchmarks/rigid/contrast.sh [OUTPUT_DIR]
#
# OUTPUT_DIR defaults to Testing/Benchmarks/results/rigid. Writes contrast.md there. Needs the
# test driver BrainShiftRigidRegistrationTests (RigidRegistrationContrastTest's calibration modes).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=SCRIPTDIR/../common.sh
source "$here/../common.sh"
out=${1:-$root/Testing/Benchmarks/results/rigid}
driver=$build/bin/BrainShiftRigidRegistrationTests
[ -x "$driver" ] || die "$driver missing: build the target BrainShiftRigidRegistrationTests"
mkdir -p "$out"

table() { # MODE: the driver's table rows (the header and its rule included)
  "$driver" RigidRegistrationContrastTest "$1" | grep '^|'
}
tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
{
  echo "# Rigid registration trust across contrasts"
  echo
  echo "Produced by \`Testing/Benchmarks/rigid/contrast.sh\` ($(date -u '+%Y-%m-%d %H:%M UTC'), $("$brainshift" --version 2>/dev/null | head -n 1))."
  echo "Gain: (NMI - 1) / (highest displaced NMI - 1); untrustworthy below 2.5, a warning below 3.3."
  echo "Right: head landmarks within 1 mm and rotation within 0.5 degrees of the true rigid motion."
  echo
  echo "## Small case, every scenario"
  echo
  say "small case" >&2
  table small-all
  echo
  echo "## Full case, every scenario"
  echo
  say "full case" >&2
  table full
  echo
  echo "## Poses known to be wrong (small case)"
  echo
  echo "The truth turned about an axis through the intraoperative image's centre and moved half as many mm along it;"
  echo "'as is': not optimized; 'finest level optimized': 50 iterations of the 1 mm level from there (a nearby local optimum or a partial recovery)."
  echo
  say "wrong poses" >&2
  table wrong
} > "$tmp"
mv "$tmp" "$out/contrast.md"
trap - EXIT
say "done: $out/contrast.md"
