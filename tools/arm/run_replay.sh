#!/usr/bin/env bash
# QEMU replay test: the Cortex-M4F build of the firmware must reproduce, bit for bit, the
# commands the host build (cffi harness) computed on a closed-loop run of the robot example.
#
#   tools/arm/run_replay.sh [--no-setup] [--build-dir DIR] [--perturb RECORD]
#                           [--fp-contract off|fast]
#
# 1. tools/arm/make_replay.py writes DIR/replay_records.c (host x, u per recorded tick);
# 2. tools/arm/build.sh builds DIR/replay.elf (generic firmware + gains/robot_corridor.c +
#    records) and DIR/replay_fixed.elf (the firmware built for the robot's dimensions);
# 3. qemu-system-arm -M mps2-an386 runs each; semihosting prints the summary and returns the
#    exit status, 0 only if every command matched.
# --perturb moves one recorded u by one ulp (the test must then fail); --fp-contract fast
# lets GCC fuse multiply-adds on the target, with the law compiled as plain C instead of the
# VMLS/VNMLA asm that contraction cannot fuse (STSP_ARM_NO_VFP_MAC): the test then fails too.
# Without --no-setup, tools/setup.sh runs first (ctest passes --no-setup: it runs inside a
# configured build).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
build="$root/build/arm"
setup=1
perturb=()
contract=off
while [ $# -gt 0 ]; do
  case "$1" in
    --no-setup) setup=0; shift ;;
    --build-dir) build="$2"; shift 2 ;;
    --perturb) perturb=(--perturb "$2"); shift 2 ;;
    --fp-contract) contract="$2"; shift 2 ;;
    *) echo "run_replay: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ "$setup" -eq 0 ] || "$root/tools/setup.sh"
py="$root/.venv/bin/python"
[ -x "$py" ] || { echo "run_replay: $py missing: run tools/setup.sh" >&2; exit 2; }

mkdir -p "$build"
records="$build/replay_records.c"
"$py" "$root/tools/arm/make_replay.py" --out "$records" "${perturb[@]}"
"$root/tools/arm/build.sh" --cpu cortex-m4 --build-dir "$build" \
  -DSTSP_REPLAY_RECORDS="$records" -DSTSP_ARM_FP_CONTRACT="$contract" \
  -DSTSP_ARM_NO_VFP_MAC="$([ "$contract" = off ] && echo OFF || echo ON)" >/dev/null

# Both Cortex-M4F builds: the generic controller and the one compiled for the robot's
# dimensions (STSP_FIXED_NX/NU/N_LATCH, unrolled): each must match the host bit for bit.
fail=0
for image in replay replay_fixed; do
  log="$build/$image.log"
  status=0
  timeout 60 qemu-system-arm -M mps2-an386 -nographic -monitor none \
    -semihosting-config enable=on,target=native -kernel "$build/$image.elf" >"$log" 2>&1 || status=$?
  echo "== $image.elf"
  cat "$log"
  if [ "$status" -eq 124 ]; then
    echo "run_replay: FAIL: QEMU timed out ($image.elf)" >&2
    fail=1
  elif [ "$status" -ne 0 ] || ! grep -q '^replay: PASS' "$log"; then
    echo "run_replay: FAIL ($image.elf, exit status $status)" >&2
    fail=1
  fi
done
[ "$fail" -eq 0 ] || exit 1
echo "run_replay: OK"
