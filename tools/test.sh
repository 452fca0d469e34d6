#!/usr/bin/env bash
# Every test: set-up, C tests through ctest, Python tests through pytest. Fails if either fails.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/tools/setup.sh" || exit 1
cd "$root"
ctest --test-dir build --output-on-failure
c_status=$?
"$root/.venv/bin/python" -m pytest -q -p no:cacheprovider tests/python
py_status=$?
echo "ctest exit ${c_status}, pytest exit ${py_status}"
[ "$c_status" -eq 0 ] && [ "$py_status" -eq 0 ]
