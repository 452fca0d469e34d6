#!/usr/bin/env bash
# The main demo: the robot corridor from problem file to C tables to Monte Carlo and figure.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/tools/setup.sh"
cd "$root"
out=build/demo
mkdir -p "$out"
st="$root/.venv/bin/stospline"
echo "== design: examples/robot_corridor.toml -> $out/"
"$st" design examples/robot_corridor.toml --out "$out"
echo "== firmware built by CMake against gains/robot_corridor.c (libstsp_gains_robot_corridor.a)"
cmake --build build --target stsp_gains_robot_corridor >/dev/null
echo "== Monte Carlo through the compiled C controller"
"$st" simulate examples/robot_corridor.toml --paths 10000 --seed 1
echo "== figure"
"$st" plot examples/robot_corridor.toml --out "$out/robot_corridor.png"
echo "== report: one self-contained HTML page (design, Monte Carlo, verdict, figures)"
"$st" report examples/robot_corridor.toml --out "$out/robot_corridor.html"
