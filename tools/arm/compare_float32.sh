#!/usr/bin/env bash
# Check that the float32 build is unchanged against another revision (default ac05a77, the
# commit before the fixed-point variants): the Cortex-M4F machine code of stsp_step and
# stsp_step_cold (generic and fixed 4/2/4 builds, addresses stripped) and the host build's
# closed-loop commands (tools/arm/make_replay.py records) must be identical.
#   tools/arm/compare_float32.sh [REV]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
rev="${1:-ac05a77}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/old"
git -C "$root" archive "$rev" | tar -x -C "$tmp/old"
py="$root/.venv/bin/python"
status=0
for tree in old new; do
  src="$tmp/old"; [ "$tree" = new ] && src="$root"
  "$src/tools/arm/build.sh" --cpu cortex-m4 --build-dir "$tmp/arm-$tree" >/dev/null
  for lib in libstsp.a libstsp_fixed_robot_corridor.a; do
    for fn in stsp_step stsp_step_cold; do
      arm-none-eabi-objdump -d --no-show-raw-insn "$tmp/arm-$tree/$lib" \
        | awk "/<$fn>:/,/^\$/" | sed 's/^ *[0-9a-f]*://' >"$tmp/$tree.$lib.$fn.s"
    done
  done
  (cd "$src" && PYTHONPATH="$src/host" STOSPLINE_BUILD="$tmp/cffi-$tree" \
     "$py" "$src/tools/arm/make_replay.py" --out "$tmp/records-$tree.c" >/dev/null)
done
for f in "$tmp"/old.*.s; do
  name="${f#"$tmp"/old.}"
  if cmp -s "$f" "$tmp/new.$name"; then
    echo "same machine code: ${name%.s} ($(wc -l <"$f") lines)"
  else
    echo "DIFFERENT machine code: ${name%.s}"; status=1
  fi
done
if cmp -s "$tmp/records-old.c" "$tmp/records-new.c"; then
  echo "same host commands: $(grep -c '^    {' "$tmp/records-new.c") closed-loop records identical"
else
  echo "DIFFERENT host commands"; status=1
fi
exit "$status"
