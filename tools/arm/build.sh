#!/usr/bin/env bash
# Cross-build the top-level project for a Cortex-M preset, with the tables and QEMU images
# (STSP_BUILD_TESTS=ON: gains/*.c, tools/arm/images.cmake).
#   tools/arm/build.sh [--preset arm-m4f|arm-m0plus] [--build-dir DIR] [--target T]
#                      [CMAKE_ARGS...]
# Defaults: arm-m4f in build/arm-m4f (arm-m0plus: build/arm-m0plus), every target (--target:
# that target and what it needs). Needs the packages that tools/setup.sh installs
# (gcc-arm-none-eabi, libnewlib-arm-none-eabi, cmake, ninja-build).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
preset=arm-m4f
build=""
target=()
while [ $# -gt 0 ]; do
  case "$1" in
    --preset) preset="$2"; shift 2 ;;
    --build-dir) build="$2"; shift 2 ;;
    --target) target=(--target "$2"); shift 2 ;;
    *) break ;;
  esac
done
case "$preset" in
  arm-m4f|arm-m0plus) ;;
  *) echo "build.sh: --preset must be arm-m4f or arm-m0plus, not '$preset'" >&2; exit 2 ;;
esac
: "${build:=$root/build/$preset}"
cmake -S "$root" --preset "$preset" -B "$build" -DSTSP_BUILD_TESTS=ON "$@" >/dev/null
cmake --build "$build" "${target[@]}"
