#!/usr/bin/env bash
# Regenerate the committed tables of every shipped example (byte-for-byte reproducible), the
# fixed-point (Q15, Q31) tables of the robot example (<name>_q15.*, <name>_q31.*), and the spline
# tables (<name>_spline.*) beside the per-tick ones of the robots, robot_bands (its band dual
# re-solved for the spline's gains), investment (time-varying data), quadrotor (a one-tick
# delay), population (4-tick stages: its spline table is 1.47x larger than the per-tick one;
# the summary says so), coupled_axes (12 states, 20 latches: its re-solved lambda0 holds
# exact zeros as 1e-10 that the latch grid rounds to 0, spline_latch.latch_grid),
# robot_monotone (a region at every tick) and robot_narrow_corridor (bands beyond the 8 rows
# of a band dual; 2-tick stages: its spline table is 1.3x larger), both of which latch the
# state: their feed-forward is restored so that every constraint row holds for the design's
# x0 (host/stospline/table/spline/restore.py). robot_patrol_60s has only its spline table,
# its file's [design] table;
# and the robot's fixed-point spline tables (<name>_q15_spline.*, <name>_q31_spline.*).
# The examples with a [measurement] sensor (robot_position_sensor, robot_corridor_position_sensor,
# quadrotor_altimeter) get
# their filter's tables in <name>.{c,h} from the first loop (float32, per-tick: the estimator
# takes no spline table), and robot_position_sensor its Q15 and Q31 laws and filters
# (<name>_q15.*, <name>_q31.*: host/stospline/estimator/qformat.py); those with [[parameters]] (robot_goal) their
# sensitivity columns in <name>_params.{c,h}, from the same loop; robot_goal also its Q15/Q31
# parametric controllers (<name>_<arith>.* and <name>_<arith>_params.*, and with Q spline gains
# and spline columns <name>_<arith>_spline.* and <name>_<arith>_spline_params.*:
# tools/params_tables.py --fixed),
# and its spline parametric controller (<name>_spline.* and <name>_spline_params.*: the spline
# columns, tools/params_tables.py --spline).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
for f in examples/*.toml; do
  "$root/.venv/bin/stospline" design "$f" --out gains/
done
for arith in q15 q31; do
  "$root/.venv/bin/stospline" design examples/robot_corridor.toml --arith "$arith" --out gains/
done
for arith in q15 q31; do
  "$root/.venv/bin/stospline" design examples/robot_position_sensor.toml --arith "$arith" --out gains/
done
for f in robot_corridor robot_corridor_eps01 robot_bands investment quadrotor population \
         coupled_axes robot_monotone robot_narrow_corridor; do
  "$root/.venv/bin/stospline" design "examples/$f.toml" --table spline --out gains/
done
for arith in q15 q31; do
  "$root/.venv/bin/stospline" design examples/robot_corridor.toml --arith "$arith" --table spline \
    --out gains/
done
# (That was the per-tick filter.) The robot on its position sensor, spline tables: the law's and
# the filter's update gains as cubic B-splines (<name>_spline.*: stsp_est_init_spline(),
# host/stospline/estimator/gain_spline.py).
"$root/.venv/bin/stospline" design examples/robot_position_sensor.toml --table spline --out gains/
"$root/.venv/bin/python" tools/params_tables.py --fixed --out gains/
"$root/.venv/bin/python" tools/params_tables.py --spline --out gains/
