#!/usr/bin/env bash
# The long fuzzing tier: every libFuzzer target (tests/c/fuzz_*.c, built with clang, ASan and
# UBSan in build/clang) for SECONDS each (default 60), as many at once as there are cores.
#   bash tools/fuzz.sh [SECONDS]
# The test command (tools/test.sh) runs the short tier instead: a fixed number of inputs from a
# fixed seed per target (STSP_FUZZ_RUNS). Any finding fails the target's test; libFuzzer writes
# the input that found it to build/clang (crash-*, leak-*, timeout-*).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
seconds="${1:-60}"
if [ $# -gt 1 ] || ! [[ "$seconds" =~ ^[1-9][0-9]{0,5}$ ]]; then
  echo "fuzz.sh: SECONDS: must be one whole number of seconds in 1..999999, not '$*'" >&2
  exit 2
fi
"$root/tools/setup.sh"
cd "$root"
# The clang variant's build (the fuzzers come with it); fails when clang is missing.
ctest --test-dir build --output-on-failure --no-tests=error -R '^clang_build$'
cmake -S "$root" -B build/clang -DSTSP_FUZZ_LONG_SECONDS="$seconds" >/dev/null
ctest --test-dir build/clang --output-on-failure --no-tests=error --parallel "$(nproc)" -L fuzz-long
