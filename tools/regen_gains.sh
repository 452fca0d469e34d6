#!/usr/bin/env bash
# Regenerate the committed tables of every shipped example (byte-for-byte reproducible), and the
# fixed-point (Q15, Q31) tables of the robot example (<name>_q15.*, <name>_q31.*).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
for f in examples/*.toml; do
  "$root/.venv/bin/stospline" design "$f" --out gains/
done
for arith in q15 q31; do
  "$root/.venv/bin/stospline" design examples/robot_corridor.toml --arith "$arith" --out gains/
done
