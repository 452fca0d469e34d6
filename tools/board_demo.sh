#!/usr/bin/env bash
# On a board, from a fresh clone: cross-build and install the stospline package for the board's
# core, generate the board's firmware project for the robot corridor, cross-build it under
# -Werror, boot it in QEMU and run HIL paths over its serial line, each compared bit for bit
# with the host-compiled controller (docs/guide/board.md).
#
#   tools/board_demo.sh [BOARD [PATHS]]     BOARD netduinoplus2 (default, float32) or
#                                           microbit (Q15); PATHS 2..512 (default 100)
#
# Exit status: 0 when every path is bit-identical, 1 when not, 2 on a bad argument.
# Everything goes under build/board-demo/BOARD ($STSP_BOARD_DEMO_DIR/BOARD if set).
# STOSPLINE overrides the command that runs stospline (default: .venv/bin/stospline, set up
# by tools/setup.sh when missing).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
board="${1:-netduinoplus2}"
paths="${2:-100}"
case "$board" in
  netduinoplus2) cpu=cortex-m4; arith=float32 ;;
  microbit) cpu=cortex-m0; arith=q15 ;;
  *) echo "board_demo.sh: BOARD must be netduinoplus2 or microbit, got '$board'" >&2; exit 2 ;;
esac
if ! [[ "$paths" =~ ^[0-9]+$ ]] || ((10#$paths < 2 || 10#$paths > 512)); then
  echo "board_demo.sh: PATHS must be an integer in 2..512, got '$paths'" >&2
  exit 2
fi
if [[ -n "${STOSPLINE:-}" ]]; then
  read -ra st <<<"$STOSPLINE"
else
  [[ -x "$root/.venv/bin/stospline" ]] || "$root/tools/setup.sh"
  st=("$root/.venv/bin/stospline")
fi
out="${STSP_BOARD_DEMO_DIR:-$root/build/board-demo}/$board"
lib="$out/lib"
prefix="$out/stsp"
proj="$out/project"
problem="$root/examples/robot_corridor.toml"

echo "== stospline cross-built for $cpu ($arith) and installed into $prefix"
cmake -S "$root" -B "$lib" -G Ninja -DCMAKE_TOOLCHAIN_FILE="$root/tools/arm/arm-none-eabi.cmake" \
  -DSTSP_ARM_CPU="$cpu" -DSTSP_ARITH="$arith" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_C_FLAGS_RELEASE=-O2 -DSTSP_BUILD_TESTS=OFF -DSTSP_INSTALL=ON >/dev/null
cmake --build "$lib" >/dev/null
cmake --install "$lib" --prefix "$prefix" >/dev/null

echo "== the $board project for examples/robot_corridor.toml"
"${st[@]}" board "$problem" --board "$board" --arith "$arith" --out "$proj"

echo "== cross-built with the project's qemu preset (-Werror)"
(cd "$proj" && export STOSPLINE_PREFIX="$prefix" && cmake --preset qemu >/dev/null &&
  cmake --build --preset qemu | tail -n 2)

echo "== $paths HIL paths: the plant on this host, the controller in QEMU's $board"
"${st[@]}" hil "$problem" --board "$board" --arith "$arith" \
  --elf "$proj/build/qemu/firmware.elf" --paths "$paths" --seed 1
