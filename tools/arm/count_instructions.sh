#!/usr/bin/env bash
# Report (not a test): instructions executed per stsp_step call under QEMU (Cortex-M4F on
# mps2-an386; the Cortex-M0+ code on mps2-an385, a Cortex-M3, as QEMU has no M0+ board), and
# flash/RAM of the controller alone and with the robot tables, for Cortex-M4F and Cortex-M0+,
# each for float32 (M4F images only), Q15 and Q31, generic (libstsp<_q15|_q31>.a) and built for
# the robot's dimensions (libstsp_fixed_robot_corridor<_q15|_q31>.a: STSP_FIXED_NX/NU/N_LATCH).
#   tools/arm/count_instructions.sh [--no-setup] [--json FILE]
# Builds build/arm-m4f and build/arm-m0plus (tools/arm/build.sh), then runs
# tools/arm/count_instructions.py (standard library only); see that file for the method.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
setup=1
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --no-setup) setup=0; shift ;;
    --json) extra+=(--json "$2"); shift 2 ;;
    *) echo "count_instructions: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ "$setup" -eq 0 ] || "$root/tools/setup.sh"
"$root/tools/arm/build.sh" --preset arm-m4f \
  -DSTSP_ARM_FP_CONTRACT=off -DSTSP_ARM_NO_VFP_MAC=OFF >/dev/null
"$root/tools/arm/build.sh" --preset arm-m0plus \
  -DSTSP_ARM_FP_CONTRACT=off -DSTSP_ARM_NO_VFP_MAC=OFF >/dev/null
exec python3 "$root/tools/arm/count_instructions.py" --m4 "$root/build/arm-m4f" \
  --m0plus "$root/build/arm-m0plus" "${extra[@]}"
