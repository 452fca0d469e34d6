#!/usr/bin/env bash
# Every test: set-up, then the C tests through ctest and the Python tests through pytest at the
# same time, each spread over all cores (ctest --parallel, pytest-xdist): many of ctest's long
# tests use one core (QEMU, cppcheck, the fuzzers), and pytest fills the other. pytest prints
# as it runs; ctest's output, kept in build/ctest.log, is printed when both are done. Fails if
# either fails; pytest finding no tests (exit 5) is a failure too. Prints the wall time of each
# part and a closing summary line. The long fuzzing tier is separate: tools/fuzz.sh.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc)"

start=$SECONDS
"$root/tools/setup.sh" || exit 1
setup_s=$((SECONDS - start))
cd "$root"

ctest_log="$root/build/ctest.log"
start=$SECONDS
ctest --test-dir build --output-on-failure --no-tests=error --parallel "$jobs" >"$ctest_log" 2>&1 &
c_pid=$!
# Interrupted: ctest ends too (it stops the tests it runs).
trap 'kill "$c_pid" 2>/dev/null; exit 130' INT TERM

# --dist loadfile: a test file's tests run in one worker, so its module fixtures are built once;
# --no-loadscope-reorder: the files in the order of tests/python/conftest.py, the longest first.
"$root/.venv/bin/python" -m pytest -q -p no:cacheprovider -n "$jobs" --dist loadfile \
  --no-loadscope-reorder --durations=15 tests/python
py_status=$?
py_s=$((SECONDS - start))
echo "pytest: exit ${py_status} in ${py_s} s"

wait "$c_pid"
c_status=$?
trap - INT TERM
echo "== ctest (beside pytest; $ctest_log):"
cat "$ctest_log"
c_s="$(sed -n 's/^Total Test time (real) = *\([0-9]*\).*/\1/p' "$ctest_log")"
echo "ctest: exit ${c_status} in ${c_s:-?} s"

echo "set-up ${setup_s} s; ctest exit ${c_status} (${c_s:-?} s), pytest exit ${py_status}" \
     "(${py_s} s), side by side on ${jobs} jobs each; tests $((SECONDS - start)) s wall"
[ "$c_status" -eq 0 ] && [ "$py_status" -eq 0 ]
