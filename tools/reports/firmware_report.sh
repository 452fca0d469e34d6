#!/usr/bin/env bash
# Firmware report (not a test): for each target (Cortex-M4F, Cortex-M0+), arithmetic (float32,
# Q15, Q31) and build (generic dimensions, built for the robot's dimensions 4/2/4):
#   * flash and RAM (arm-none-eabi-size; controller alone and with the robot tables),
#   * instructions per stsp_step call under QEMU (Cortex-M4F: mps2-an386; the Cortex-M0+ code
#     on mps2-an385, a Cortex-M3, as QEMU has no M0+ board; float32 on the M4F only), and the
#     ratio to the multiply-accumulates the law needs (tools/arm/count_instructions.sh),
#   * host nanoseconds per tick, median over whole 6000-tick plans, against a naive
#     generic-loop controller (tools/bench/bench_host.c, built by the host CMake project).
#   tools/reports/firmware_report.sh [--no-setup]
# Writes build/firmware_report/counts.json and prints everything to stdout.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
setup=1
[ "${1:-}" = "--no-setup" ] && setup=0
[ "$setup" -eq 0 ] || "$root/tools/setup.sh"
out="$root/build/firmware_report"
mkdir -p "$out"

echo "######## Cortex-M: instructions per tick, flash, RAM"
"$root/tools/arm/count_instructions.sh" --no-setup --json "$out/counts.json" | tee "$out/counts.txt"

echo
echo "######## Host: ns per tick (robot table, 6000-tick plans, median of 301 plans)"
cmake --build "$root/build" --target bench_host bench_host_fixed >/dev/null
cc_line="$(sed -n 's/^CMAKE_C_COMPILER:[A-Z]*=//p' "$root/build/CMakeCache.txt")"
type_line="$(sed -n 's/^CMAKE_BUILD_TYPE:[A-Z]*=//p' "$root/build/CMakeCache.txt")"
echo "   compiler: $("$cc_line" --version | head -1), CMake build type ${type_line:-none}," \
     "CPU: $(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -1)"
"$root/build/bench_host" | tee "$out/bench_host.txt"
"$root/build/bench_host_fixed" | tee "$out/bench_host_fixed.txt"

echo
echo "######## Summary"
python3 - "$out" <<'PY'
import json, re, sys
from pathlib import Path
out = Path(sys.argv[1])
counts = json.loads((out / "counts.json").read_text())
def name(key):
    cpu, image = key.split("/")
    arith = "q15" if "_q15" in image else "q31" if "_q31" in image else "float32"
    dims = "fixed 4/2/4" if "bench_fixed" in image else "generic"
    return f"{'M4F' if cpu == 'cortex-m4' else 'M0+':3s} {arith:7s} {dims:11s}"
print("   Instructions per stsp_step (median; MACs needed; instructions per MAC); M0+ code run "
      "on mps2-an385:")
for image, rows in counts["instructions"].items():
    for r in rows:
        if r["table"] in ("no limits", "limits +-1000 (inactive)"):
            print(f"     {name(image)} {r['table']:26s} {r['ticks']:26s} {r['median']:5.0f}"
                  f"  MACs {r['macs']:2d}  {r['median'] / r['macs']:5.1f}/MAC")
print("   Flash / static RAM (bytes):")
for key, rows in counts["sizes"].items():
    ctl = rows.get("controller linked (API roots)")
    tab = rows.get("controller + tables linked")
    st = rows.get("stack", {})
    print(f"     {key:46s} controller {ctl['flash']:5d} B flash, {ctl['ram']} B RAM;"
          f" with robot tables {tab['flash']} B flash; stack stsp_step {st.get('stsp_step')} B,"
          f" cold path {st.get('stsp_step_cold')} B")
sizes = {}
for key, v in counts.get("sizeof_ctrl_by_image", {}).items():
    sizes.setdefault(v, []).append(name(key).split()[1])
print("     per instance: sizeof(stsp_ctrl_t) = "
      + "; ".join(f"{v} B ({', '.join(sorted(set(a)))})" for v, a in sizes.items()))
print("   Host ns per tick (median over plans; the naive controller timed in the same binary):")
for f in ("bench_host.txt", "bench_host_fixed.txt"):
    res = {}
    for line in (out / f).read_text().splitlines():
        m = re.match(r"bench (\S+) ns_per_tick_median (\S+)", line)
        if m:
            res[m.group(1)] = float(m.group(2))
    naive = res.pop("naive_generic_loops")
    for name, ns in res.items():
        print(f"     {name:24s} {ns:7.2f} ns   naive generic loops {naive:7.2f} ns"
              f"   naive/stsp {naive / ns:4.2f}x")
PY
