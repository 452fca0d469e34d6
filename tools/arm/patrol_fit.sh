#!/usr/bin/env bash
# Report: flash of a Cortex-M0+ program that runs the 60 s patrol's spline table
# (gains/robot_patrol_60s_spline.c) through the generic float32 controller, linked with
# newlib's start-up code (nosys), -Os, --gc-sections: does it fit a 32 KB part?
#   tools/arm/patrol_fit.sh [--no-setup]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
[ "${1:-}" = "--no-setup" ] || "$root/tools/setup.sh"
"$root/tools/arm/build.sh" --preset arm-m0plus >/dev/null
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
arm-none-eabi-gcc -mcpu=cortex-m0plus -mthumb -Os -std=c99 -ffunction-sections -fdata-sections \
  -I"$root/firmware/include" -I"$root/gains" "$root/tools/arm/patrol_fit_main.c" \
  "$root/gains/robot_patrol_60s_spline.c" "$root/build/arm-m0plus/libstsp_float32.a" \
  -Wl,--gc-sections -specs=nosys.specs -o "$out/patrol.elf"
arm-none-eabi-size "$out/patrol.elf"
read -r text data _ < <(arm-none-eabi-size "$out/patrol.elf" | tail -1)
echo "flash (text + data): $((text + data)) B of 32768 B"
