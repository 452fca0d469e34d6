#!/usr/bin/env bash
# Regenerate the committed tables of every shipped example (byte-for-byte reproducible), the
# fixed-point (Q15, Q31) tables of the robot example (<name>_q15.*, <name>_q31.*), the spline
# tables of the robot examples (<name>_spline.*; robot_patrol_60s has only its spline table,
# its file's [design] table), and the robot's fixed-point spline tables (<name>_q15_spline.*,
# <name>_q31_spline.*).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
for f in examples/*.toml; do
  "$root/.venv/bin/stospline" design "$f" --out gains/
done
for arith in q15 q31; do
  "$root/.venv/bin/stospline" design examples/robot_corridor.toml --arith "$arith" --out gains/
done
for f in robot_corridor robot_corridor_eps01; do
  "$root/.venv/bin/stospline" design "examples/$f.toml" --table spline --out gains/
done
for arith in q15 q31; do
  "$root/.venv/bin/stospline" design examples/robot_corridor.toml --arith "$arith" --table spline \
    --out gains/
done
