#!/usr/bin/env bash
# QEMU replay test: the Cortex-M builds of the firmware must reproduce, bit for bit, the
# statuses and commands the host build (cffi harness) of the same arithmetic variant computed
# on closed-loop runs of the robot example.
#
#   tools/arm/run_replay.sh [--no-setup] [--preset arm-m4f|arm-m0plus] [--build-dir DIR]
#                           [--arith LIST] [--perturb RECORD] [--perturb-coef N]
#                           [--fp-contract off|fast] [--records-only | --records RDIR]
#
# 1. tools/arm/make_replay.py writes DIR/replay_records[_q15|_q31|_spline].c (per call: tick,
#    host x, status, u, instance fields) for each variant of LIST (default:
#    float32,q15,q31,spline,bands_spline,q15_spline,q31_spline on arm-m4f; the same but float32
#    on arm-m0plus, which has no per-tick float32 images); `spline` is the robot's spline table
#    (float32, make_replay.py --table spline: every call of two closed-loop runs, with skips,
#    repeats, non-finite states and limits), `bands_spline` the same calls on the spline table
#    of examples/robot_bands.toml (gains/robot_bands_spline.c: the band dual's t0 latch),
#    `q15_spline`/`q31_spline` the robot's Q15/Q31 spline tables (make_replay.py --arith
#    q15|q31 --table spline: the same two runs, states at the ends of the Q range instead of
#    non-finite ones);
# 2. tools/arm/build.sh builds DIR/replay<sfx>.elf (generic firmware + gains/robot_corridor<sfx>.c
#    + records) and DIR/replay_fixed<sfx>.elf (the firmware built for the robot's dimensions;
#    for spline: replay_spline.elf, replay_spline_fixed.elf; for bands_spline:
#    replay_bands_spline.elf, replay_bands_spline_fixed.elf; for q15_spline:
#    replay_q15_spline.elf, replay_q15_spline_fixed.elf);
# 3. qemu-system-arm runs each: -M mps2-an386 (Cortex-M4F) for arm-m4f; for arm-m0plus
#    -M mps2-an385, a Cortex-M3 (QEMU has no Cortex-M0+ board; the -mcpu=cortex-m0plus code is
#    ARMv6-M, a subset of what the M3 runs). Semihosting prints the summary and returns the
#    exit status, 0 only if every command matched.
# --perturb moves one recorded u by one ulp / one unit (the test must then fail);
# --perturb-coef N builds the spline images with spline coefficient N one ulp (Q: one unit)
# larger (and the
# table's CRC recomputed on the target), so that their commands differ from the host's (the
# spline test must then fail); --fp-contract fast lets GCC fuse multiply-adds on the target,
# with the float law compiled as plain C instead of the VMLS/VNMLA asm that contraction cannot
# fuse (STSP_ARM_NO_VFP_MAC): the float32 and spline tests then fail too.
# --records-only stops after step 1 (the records in DIR, nothing built or run); --records RDIR
# skips step 1 and takes them from RDIR, where a --records-only run with the same --arith
# variants wrote them (the records are the host's, the same for both presets: ctest's
# arm_replay_records writes them once for arm_qemu_replay and arm_m0plus_qemu_replay).
# Without --no-setup,
# tools/setup.sh runs first (ctest passes --no-setup: it runs inside a configured build). The
# host side imports this checkout's host/ package (PYTHONPATH), whose harness compiles this
# checkout's firmware/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
build=""
preset=arm-m4f
setup=1
perturb=()
perturb_coef=""
contract=off
ariths=""
records_only=0
records_dir=""
while [ $# -gt 0 ]; do
  case "$1" in
    --no-setup) setup=0; shift ;;
    --preset) preset="$2"; shift 2 ;;
    --build-dir) build="$2"; shift 2 ;;
    --arith) ariths="$2"; shift 2 ;;
    --perturb) perturb=(--perturb "$2"); shift 2 ;;
    --perturb-coef) perturb_coef="$2"; shift 2 ;;
    --fp-contract) contract="$2"; shift 2 ;;
    --records-only) records_only=1; shift ;;
    --records) records_dir="$2"; shift 2 ;;
    *) echo "run_replay: unknown argument $1" >&2; exit 2 ;;
  esac
done
case "$preset" in
  arm-m4f) machine=mps2-an386; : "${ariths:=float32,q15,q31,spline,bands_spline,q15_spline,q31_spline}" ;;
  arm-m0plus) machine=mps2-an385; : "${ariths:=q15,q31,spline,bands_spline,q15_spline,q31_spline}" ;;
  *) echo "run_replay: --preset must be arm-m4f or arm-m0plus" >&2; exit 2 ;;
esac
: "${build:=$root/build/$preset}"
if [ -n "$records_dir" ] && { [ "$records_only" -eq 1 ] || [ "${#perturb[@]}" -gt 0 ]; }; then
  echo "run_replay: --records takes recorded files as they are: not with --records-only or --perturb" >&2
  exit 2
fi
[ "$setup" -eq 0 ] || "$root/tools/setup.sh"
py="$root/.venv/bin/python"
[ -x "$py" ] || { echo "run_replay: $py missing: run tools/setup.sh" >&2; exit 2; }
# The host package of this checkout (and so its firmware/, which the harness compiles), even
# when the virtual environment is shared with another checkout.
export PYTHONPATH="$root/host${PYTHONPATH:+:$PYTHONPATH}"

mkdir -p "$build"
defs=()
images=()
for arith in ${ariths//,/ }; do
  gen=(--arith "$arith")
  case "$arith" in
    float32) sfx=""; var=STSP_REPLAY_RECORDS ;;
    q15|q31) sfx="_$arith"; var="STSP_REPLAY_RECORDS_${arith^^}" ;;
    spline) sfx="_spline"; var=STSP_REPLAY_RECORDS_SPLINE; gen=(--table spline) ;;
    bands_spline) sfx="_bands_spline"; var=STSP_REPLAY_RECORDS_BANDS_SPLINE
                  gen=(--table spline --problem "$root/examples/robot_bands.toml") ;;
    q15_spline|q31_spline)
      sfx="_$arith"; var="STSP_REPLAY_RECORDS_${arith^^}"
      gen=(--arith "${arith%_spline}" --table spline) ;;
    *) echo "run_replay: unknown variant $arith" >&2; exit 2 ;;
  esac
  [ "$preset" = arm-m4f ] || [ "$arith" != float32 ] || {
    echo "run_replay: no float32 images for $preset" >&2; exit 2; }
  if [ -n "$records_dir" ]; then
    records="$records_dir/replay_records$sfx.c"
    [ -f "$records" ] || { echo "run_replay: $records missing (run_replay.sh --records-only)" >&2
                           exit 2; }
  else
    records="$build/replay_records$sfx.c"
    "$py" "$root/tools/arm/make_replay.py" "${gen[@]}" --out "$records" "${perturb[@]}"
  fi
  defs+=("-D$var=$records")
  if [ "$arith" = spline ] || [ "$arith" = bands_spline ]; then
    images+=("replay$sfx" "replay${sfx/_spline/}_spline_fixed")
  elif [ "$arith" != "${arith%_spline}" ]; then
    images+=("replay_$arith" "replay_${arith}_fixed")
  else
    images+=("replay$sfx" "replay_fixed$sfx")
  fi
  # float32: also the generic law on every small shape (tests/arm/shapes_main.c).
  [ "$arith" != float32 ] || images+=(shapes)
done
[ "$records_only" -eq 0 ] || { echo "run_replay: records in $build"; exit 0; }
"$root/tools/arm/build.sh" --preset "$preset" --build-dir "$build" \
  "${defs[@]}" -DSTSP_REPLAY_PERTURB_COEF="$perturb_coef" -DSTSP_ARM_FP_CONTRACT="$contract" \
  -DSTSP_ARM_NO_VFP_MAC="$([ "$contract" = off ] && echo OFF || echo ON)" >/dev/null

# Both builds of each variant: the generic controller and the one compiled for the robot's
# dimensions (STSP_FIXED_NX/NU/N_LATCH, unrolled): each must match the host bit for bit.
fail=0
for image in "${images[@]}"; do
  log="$build/$image.log"
  status=0
  timeout 60 qemu-system-arm -M "$machine" -nographic -monitor none \
    -semihosting-config enable=on,target=native -kernel "$build/$image.elf" >"$log" 2>&1 || status=$?
  echo "== $image.elf ($preset code on $machine)"
  cat "$log"
  if [ "$status" -eq 124 ]; then
    echo "run_replay: FAIL: QEMU timed out ($image.elf)" >&2
    fail=1
  elif [ "$status" -ne 0 ] || ! grep -q '^\(replay\|shapes\): PASS' "$log"; then
    echo "run_replay: FAIL ($image.elf, exit status $status)" >&2
    fail=1
  fi
done
[ "$fail" -eq 0 ] || exit 1
echo "run_replay: OK"
