#!/usr/bin/env bash
# Regenerate the committed tables of every shipped example (byte-for-byte reproducible), the
# fixed-point (Q15, Q31) tables of the robot example (<name>_q15.*, <name>_q31.*), and the spline
# tables of the robot examples (<name>_spline.*; robot_bands_spline carries its band dual
# re-solved for the spline's gains; robot_patrol_60s has only its spline table, its file's
# [design] table).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
for f in examples/*.toml; do
  "$root/.venv/bin/stospline" design "$f" --out gains/
done
for arith in q15 q31; do
  "$root/.venv/bin/stospline" design examples/robot_corridor.toml --arith "$arith" --out gains/
done
for f in robot_corridor robot_corridor_eps01 robot_bands; do
  "$root/.venv/bin/stospline" design "examples/$f.toml" --table spline --out gains/
done
