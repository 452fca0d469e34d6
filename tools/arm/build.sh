#!/usr/bin/env bash
# Configure and build the Cortex-M cross project (tools/arm/CMakeLists.txt).
#   tools/arm/build.sh [--cpu cortex-m4|cortex-m0plus] [--build-dir DIR] [CMAKE_ARGS...]
# Defaults: cortex-m4 in build/arm (cortex-m0plus: build/arm-m0plus). Needs the packages that
# tools/setup.sh installs (gcc-arm-none-eabi, libnewlib-arm-none-eabi, cmake, ninja-build).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cpu=cortex-m4
build=""
while [ $# -gt 0 ]; do
  case "$1" in
    --cpu) cpu="$2"; shift 2 ;;
    --build-dir) build="$2"; shift 2 ;;
    *) break ;;
  esac
done
if [ -z "$build" ]; then
  case "$cpu" in
    cortex-m4) build="$root/build/arm" ;;
    *) build="$root/build/arm-${cpu#cortex-}" ;;
  esac
fi
cmake -S "$root/tools/arm" -B "$build" -G Ninja \
  -DCMAKE_TOOLCHAIN_FILE="$root/tools/arm/arm-none-eabi.cmake" -DSTSP_ARM_CPU="$cpu" "$@" >/dev/null
cmake --build "$build"
