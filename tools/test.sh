#!/usr/bin/env bash
# Every test: set-up, C tests through ctest, Python tests through pytest, each spread over all
# cores (ctest --parallel, pytest-xdist). Fails if either fails; pytest finding no tests (exit 5)
# is a failure too. Prints the wall time of each part and a closing summary line.
# The long fuzzing tier is separate: tools/fuzz.sh.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc)"

start=$SECONDS
"$root/tools/setup.sh" || exit 1
setup_s=$((SECONDS - start))
cd "$root"

start=$SECONDS
ctest --test-dir build --output-on-failure --no-tests=error --parallel "$jobs"
c_status=$?
c_s=$((SECONDS - start))
echo "ctest: exit ${c_status} in ${c_s} s"

# --dist loadfile: a test file's tests run in one worker, so its module fixtures are built once;
# --no-loadscope-reorder: the files in the order of tests/python/conftest.py, the longest first,
# so that both workers end together. ctest and pytest run one after the other: side by side
# they oversubscribe the cores and the QEMU sessions of both slow down several times.
start=$SECONDS
"$root/.venv/bin/python" -m pytest -q -p no:cacheprovider -n "$jobs" --dist loadfile \
  --no-loadscope-reorder --durations=15 tests/python
py_status=$?
py_s=$((SECONDS - start))
echo "pytest: exit ${py_status} in ${py_s} s"

echo "set-up ${setup_s} s; ctest exit ${c_status} (${c_s} s), pytest exit ${py_status} (${py_s} s)," \
     "${jobs} jobs; tests $((c_s + py_s)) s wall"
[ "$c_status" -eq 0 ] && [ "$py_status" -eq 0 ]
