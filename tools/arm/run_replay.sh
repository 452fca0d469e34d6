#!/usr/bin/env bash
# QEMU replay test: the Cortex-M4F build of the firmware must reproduce, bit for bit, the
# commands the host build (cffi harness) computed on a closed-loop run of the robot example.
#
#   tools/arm/run_replay.sh [--no-setup] [--build-dir DIR] [--perturb RECORD]
#                           [--fp-contract off|fast]
#
# 1. tools/arm/make_replay.py writes DIR/replay_records.c (host x, u per recorded tick);
# 2. tools/arm/build.sh builds DIR/replay.elf (firmware + gains/robot_corridor.c + records);
# 3. qemu-system-arm -M mps2-an386 runs it; semihosting prints the summary and returns the
#    exit status, 0 only if every command matched.
# --perturb moves one recorded u by one ulp (the test must then fail); --fp-contract fast
# lets GCC fuse multiply-adds on the target (the test then fails too). Without --no-setup,
# tools/setup.sh runs first (ctest passes --no-setup: it runs inside a configured build).
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
  -DSTSP_REPLAY_RECORDS="$records" -DSTSP_ARM_FP_CONTRACT="$contract" >/dev/null

log="$build/replay.log"
status=0
timeout 60 qemu-system-arm -M mps2-an386 -nographic -monitor none \
  -semihosting-config enable=on,target=native -kernel "$build/replay.elf" >"$log" 2>&1 || status=$?
cat "$log"
if [ "$status" -eq 124 ]; then
  echo "run_replay: FAIL: QEMU timed out" >&2
  exit 1
fi
if [ "$status" -ne 0 ] || ! grep -q '^replay: PASS' "$log"; then
  echo "run_replay: FAIL (exit status $status)" >&2
  exit 1
fi
echo "run_replay: OK"
