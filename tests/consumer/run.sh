#!/usr/bin/env bash
# Builds and runs the consumer project (tests/consumer) as a user outside the repository would;
# the ctest tests consumer_* (tests/consumer/tests.cmake) call it, one mode each:
#
#   tests/consumer/run.sh MODE WORK [--cmake CMAKE] [--cc CC] [--python PY] [--generator G]
#
#   install           configure stospline with STSP_BUILD_TESTS=OFF in WORK/build, build it,
#                     `cmake --install --prefix WORK/prefix`; checks what was built, that cmocka
#                     was not looked for, and what was installed
#   find_package      the consumer with find_package(stospline) from WORK/../install/prefix
#   find_package_fixed      the same with stospline_add_gains(... FIXED_SHAPE)
#   add_subdirectory  the consumer with add_subdirectory(<this checkout>); checks that only the
#                     library was built and cmocka was not looked for, and that a parent
#                     project can call stsp_add_controller()
#   two_arith         add_subdirectory, plus a Q15 controller (stsp_add_controller) and the Q15
#                     table in one program with the float32 ones (two_arith.c, q15_robot.c)
#   fetchcontent_fixed      FetchContent (FETCHCONTENT_SOURCE_DIR_STOSPLINE = this checkout),
#                     FIXED_SHAPE
#   hostile_flags     the consumer compiled with flags of its own that break bit-exactness
#                     (-O3 -march=native -mfma -ffp-contract=fast -ffast-math: fused
#                     multiply-adds, fast math), twice: add_subdirectory and find_package
#                     FIXED_SHAPE (the controller compiled in the consumer's build both times);
#                     the options stospline::stsp carries must give the harness's bits anyway;
#                     with arm-none-eabi-gcc, the FIXED_SHAPE controller cross-compiled for the
#                     Cortex-M4F under -O3 -ffp-contract=fast -ffast-math has no vfma
#   qemu_nano         main.c, the robot's table and the firmware cross-compiled for the
#                     Cortex-M4F with newlib-nano (--specs=nano.specs, semihosting), linked with
#                     tools/arm's start-up and linker script, run on QEMU's mps2-an386: its
#                     output must be the host's (compare_harness.py), printf without %a or %f
#   pkg_config        cc main.c robot_corridor.c $(pkg-config --cflags --libs stospline), with
#                     PKG_CONFIG_PATH into the installed prefix
#   wrong_arith       a Q15 table against the float32 package must fail: stospline_add_gains at
#                     configure time, the generated header and stsp_controller.h at compile time
#   presets           CMakePresets.json: the host presets configure; the Cortex-M4F and M0+
#                     presets build and install the library for the right core and float ABI,
#                     the same machine code as the preset's full build of that arithmetic, and a
#                     cross-compiled consumer finds the installed package and toolchain file
#
# Every mode that runs main.c compares its output with the cffi harness bit for bit
# (tests/consumer/compare_harness.py). Exit status 0 on success.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
src="$(cd "$here/../.." && pwd)"
mode="$1"
work="$2"
shift 2
cmake=cmake
cc=cc
python="$src/.venv/bin/python"
generator=Ninja
while [ $# -gt 0 ]; do
  case "$1" in
    --cmake) cmake="$2"; shift 2 ;;
    --cc) cc="$2"; shift 2 ;;
    --python) python="$2"; shift 2 ;;
    --generator) generator="$2"; shift 2 ;;
    *) echo "run.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done
prefix="$(dirname "$work")/install/prefix"
table="$src/gains/robot_corridor.c"
# The host package of this checkout (and so its firmware/, which the harness compiles), even
# when the virtual environment is shared with another checkout (a git worktree).
export PYTHONPATH="$src/host${PYTHONPATH:+:$PYTHONPATH}"

fail() { echo "run.sh ($mode): FAIL: $*" >&2; exit 1; }

# configure_consumer ARGS...: configure tests/consumer in WORK/build.
configure_consumer() {
  "$cmake" -S "$here" -B "$work/build" -G "$generator" -DCMAKE_C_COMPILER="$cc" \
    -DCMAKE_BUILD_TYPE=Release "$@"
}

# build_run_compare: build the consumer, run it, compare with the harness.
build_run_compare() {
  "$cmake" --build "$work/build"
  run_compare "$work/build/robot"
}

run_compare() {
  "$1" >"$work/commands.txt"
  echo "main.c: $(wc -l <"$work/commands.txt") lines; last: $(tail -n 1 "$work/commands.txt")"
  "$python" "$here/compare_harness.py" "$work/commands.txt"
}

# no_tests_built DIR: stospline's build directory DIR holds the library only, and the
# configuration did not look for cmocka.
no_tests_built() {
  local libs
  libs="$(cd "$1" && find . -name '*.a' -printf '%f\n' | sort | tr '\n' ' ')"
  [ "$libs" = "libstsp.a " ] || fail "built in $1: $libs(expected libstsp.a only)"
  if find "$1" -maxdepth 1 -name CTestTestfile.cmake | grep -q .; then
    fail "$1 registers tests"
  fi
  if grep -q '^CMOCKA' "$2/CMakeCache.txt"; then
    fail "cmocka was looked for ($2/CMakeCache.txt)"
  fi
}

rm -rf "$work"
mkdir -p "$work"
case "$mode" in
  install)
    "$cmake" -S "$src" -B "$work/build" -G "$generator" -DCMAKE_C_COMPILER="$cc" \
      -DCMAKE_BUILD_TYPE=Release -DSTSP_BUILD_TESTS=OFF
    "$cmake" --build "$work/build"
    no_tests_built "$work/build" "$work/build"
    "$cmake" --install "$work/build" --prefix "$prefix"
    (cd "$prefix" && find . -type f | sort) | tee "$work/installed.txt"
    for f in include/stospline/stsp_controller.h include/stospline/stsp_bandqp.h \
             include/stospline/stsp_types.h include/stospline/stsp_table.h \
             include/stospline/stsp_spline.h include/stospline/stsp_private.h lib/libstsp.a \
             lib/cmake/stospline/stosplineConfig.cmake \
             lib/cmake/stospline/stosplineConfigVersion.cmake \
             lib/cmake/stospline/stosplineTargets.cmake lib/cmake/stospline/stosplineGains.cmake \
             lib/pkgconfig/stospline.pc share/stospline/toolchains/arm-none-eabi.cmake \
             share/stospline/src/stsp_controller.c share/stospline/src/stsp_crc32.h; do
      [ -f "$prefix/$f" ] || fail "not installed: $f"
    done
    grep -q 'set(STOSPLINE_ARITH "float32")' "$prefix/lib/cmake/stospline/stosplineConfig.cmake" \
      || fail "stosplineConfig.cmake does not record the arithmetic"
    grep -q 'INTERFACE_COMPILE_DEFINITIONS "STSP_HOST_MESSAGES;STSP_ARITH_FLOAT32"' \
      "$prefix/lib/cmake/stospline/stosplineTargets.cmake" \
      || fail "stospline::stsp does not carry STSP_ARITH_FLOAT32"
    grep -q 'INTERFACE_COMPILE_OPTIONS ".*-fno-fast-math;-ffp-contract=off' \
      "$prefix/lib/cmake/stospline/stosplineTargets.cmake" \
      || fail "stospline::stsp does not carry -fno-fast-math -ffp-contract=off"
    ;;
  find_package|find_package_fixed)
    fixed=OFF
    [ "$mode" = find_package ] || fixed=ON
    configure_consumer -DCMAKE_PREFIX_PATH="$prefix" -DCONSUMER_TABLE="$table" \
      -DCONSUMER_FIXED_SHAPE="$fixed"
    build_run_compare
    ;;
  add_subdirectory)
    configure_consumer -DSTOSPLINE_FROM=subdirectory -DSTOSPLINE_SOURCE_DIR="$src" \
      -DCONSUMER_TABLE="$table"
    build_run_compare
    no_tests_built "$work/build/stospline" "$work/build"
    # The repository's internal helper also works from a parent project (it finds its sources).
    mkdir -p "$work/parent"
    printf '%s\n' 'cmake_minimum_required(VERSION 3.21)' 'project(parent C)' \
      "add_subdirectory(\"$src\" stospline)" \
      'stsp_add_controller(ctrl_4_2_4 DEFINES STSP_FIXED_NX=4u STSP_FIXED_NU=2u STSP_FIXED_N_LATCH=4u)' \
      >"$work/parent/CMakeLists.txt"
    "$cmake" -S "$work/parent" -B "$work/parent/build" -G "$generator" -DCMAKE_C_COMPILER="$cc" \
      >/dev/null
    "$cmake" --build "$work/parent/build" --target ctrl_4_2_4
    ;;
  two_arith)
    # A float32 and a Q15 controller linked into one program (two_arith.c, q15_robot.c): the
    # float32 commands are the harness's, the Q15 lines those of the Q15 controller alone.
    configure_consumer -DSTOSPLINE_FROM=subdirectory -DSTOSPLINE_SOURCE_DIR="$src" \
      -DCONSUMER_TABLE="$table" -DCONSUMER_Q15_TABLE="$src/gains/robot_corridor_q15.c"
    "$cmake" --build "$work/build" --target robot_two_arith robot_q15
    "$work/build/robot_two_arith" "$work/q15_two_arith.txt" >"$work/commands.txt"
    echo "robot_two_arith: $(wc -l <"$work/commands.txt") float32 lines, $(wc -l \
      <"$work/q15_two_arith.txt") Q15 lines"
    "$python" "$here/compare_harness.py" "$work/commands.txt"
    "$work/build/robot_q15" >"$work/q15_alone.txt"
    cmp "$work/q15_two_arith.txt" "$work/q15_alone.txt" \
      || fail "the Q15 commands differ when the float32 controller is linked too"
    nm "$work/build/robot_two_arith" >"$work/symbols.txt"
    for sym in stsp_step_f32 stsp_step_q15 stsp_init_f32 stsp_init_q15; do
      grep -q " T $sym\$" "$work/symbols.txt" || fail "$sym not in the program"
    done
    echo "two_arith: float32 and Q15 controllers in one program, both bit for bit"
    ;;
  fetchcontent_fixed)
    # The override is FetchContent's documented way to use a local checkout; the URL below
    # would fail if anything tried to download it.
    configure_consumer -DSTOSPLINE_FROM=fetchcontent \
      -DSTOSPLINE_GIT_REPOSITORY="file:///nonexistent/stospline.git" \
      -DFETCHCONTENT_SOURCE_DIR_STOSPLINE="$src" -DCONSUMER_TABLE="$table" \
      -DCONSUMER_FIXED_SHAPE=ON
    build_run_compare
    no_tests_built "$work/build/_deps/stospline-build" "$work/build"
    ;;
  hostile_flags)
    # FMA where the machine has it (x86-64 with fma): contraction then changes bits for real.
    hostile="-O3 -march=native -ffp-contract=fast -ffast-math"
    if [ "$(uname -m)" = x86_64 ] && grep -qw fma /proc/cpuinfo; then
      hostile="$hostile -mfma"
      # The flags do fuse: a*b+c alone compiles to a fused multiply-add.
      printf 'double f(double a, double b, double c) { return a * b + c; }\n' >"$work/probe.c"
      # shellcheck disable=SC2086 # the flags are words
      "$cc" $hostile -c "$work/probe.c" -o "$work/probe.o"
      objdump -d "$work/probe.o" | grep -q vfmadd || fail "$hostile does not fuse a*b+c"
    else
      echo "hostile_flags: no FMA on this machine; -ffast-math and -O3 only"
    fi
    for how in subdirectory package; do
      if [ "$how" = subdirectory ]; then
        from=(-DSTOSPLINE_FROM=subdirectory -DSTOSPLINE_SOURCE_DIR="$src")
      else
        from=(-DCMAKE_PREFIX_PATH="$prefix" -DCONSUMER_FIXED_SHAPE=ON)
      fi
      rm -rf "$work/build"
      configure_consumer "${from[@]}" -DCONSUMER_TABLE="$table" -DCMAKE_C_FLAGS="$hostile"
      build_run_compare
      # The controller's objects carry no fused multiply-add.
      find "$work/build" -name 'stsp_*.c.o' -exec objdump -d {} + >"$work/controller.dis"
      [ -s "$work/controller.dis" ] || fail "no controller objects in $work/build"
      if grep -Eq 'vf(n)?m(add|sub)' "$work/controller.dis"; then
        fail "$how: the controller was compiled with fused multiply-adds"
      fi
      echo "hostile_flags ($how): '$hostile' on the consumer, the harness's bits"
    done
    # The same on the Cortex-M4F (FPv4-SP has vfma): a cross-compiled consumer (add_subdirectory,
    # FIXED_SHAPE) whose flags fuse; its controller must have no fused multiply-add.
    if command -v arm-none-eabi-gcc >/dev/null; then
      # (CMAKE_C_FLAGS replaces the toolchain file's CPU flags: they are spelled out here.)
      arm_cpu="-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard"
      arm_hostile="-O3 -ffp-contract=fast -ffast-math"
      printf 'float f(float a, float b, float c) { return a * b + c; }\n' >"$work/probe.c"
      # shellcheck disable=SC2086 # the flags are words
      arm-none-eabi-gcc $arm_cpu $arm_hostile -c "$work/probe.c" -o "$work/probe_arm.o"
      arm-none-eabi-objdump -d "$work/probe_arm.o" | grep -q vfma \
        || fail "$arm_hostile does not fuse a*b+c on the Cortex-M4F"
      rm -rf "$work/arm"
      "$cmake" -S "$here" -B "$work/arm" -G "$generator" \
        -DCMAKE_TOOLCHAIN_FILE="$src/tools/arm/arm-none-eabi.cmake" -DCMAKE_BUILD_TYPE=Release \
        -DSTOSPLINE_FROM=subdirectory -DSTOSPLINE_SOURCE_DIR="$src" -DCONSUMER_TABLE="$table" \
        -DCONSUMER_FIXED_SHAPE=ON -DCMAKE_C_FLAGS="$arm_cpu $arm_hostile" >/dev/null
      "$cmake" --build "$work/arm" --target robot_gains_stsp robot_gains >/dev/null
      arm-none-eabi-objdump -d "$work/arm/librobot_gains_stsp.a" >"$work/arm/controller.dis"
      grep -q vmls "$work/arm/controller.dis" || fail "no Cortex-M4F controller code found"
      if grep -Eq 'vfn?m[as]' "$work/arm/controller.dis"; then
        fail "cortex-m4: the controller was compiled with fused multiply-adds"
      fi
      echo "hostile_flags (cortex-m4): '$arm_hostile' on the consumer, no fused multiply-add"
    fi
    ;;
  qemu_nano)
    cpu=(-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard)
    arm-none-eabi-gcc "${cpu[@]}" -std=c99 -O2 -Wall -Wextra -Wpedantic -Wconversion -Werror \
      -fno-fast-math -ffp-contract=off -DSTSP_ARITH_FLOAT32 -I"$src/firmware/include" \
      -I"$src/firmware/src" -I"$src/gains" "$here/main.c" "$table" "$src"/firmware/src/*.c \
      "$src/tools/arm/startup.c" --specs=nano.specs --specs=rdimon.specs \
      -T "$src/tools/arm/mps2-an386.ld" -Wl,--gc-sections -o "$work/robot.elf"
    status=0
    timeout 300 qemu-system-arm -M mps2-an386 -nographic -monitor none \
      -semihosting-config enable=on,target=native -kernel "$work/robot.elf" \
      >"$work/commands.txt" 2>"$work/stderr.txt" || status=$?
    [ "$status" -eq 0 ] || { cat "$work/stderr.txt"; fail "QEMU: exit status $status"; }
    echo "main.c on QEMU: $(wc -l <"$work/commands.txt") lines; last: $(tail -n 1 "$work/commands.txt")"
    grep -q "^final state (micro-units) -1000000 0 5000000 0$" "$work/stderr.txt" \
      || { cat "$work/stderr.txt"; fail "the final state line"; }
    "$python" "$here/compare_harness.py" "$work/commands.txt"
    ;;
  pkg_config)
    export PKG_CONFIG_PATH="$prefix/lib/pkgconfig"
    [ "$(pkg-config --variable=arith stospline)" = float32 ] || fail "arith variable"
    flags="$(pkg-config --cflags --libs stospline)"
    echo "pkg-config --cflags --libs stospline: $flags"
    # shellcheck disable=SC2086 # the flags are words
    "$cc" -std=c99 -O2 -Wall -Wextra -Werror -I"$src/gains" "$here/main.c" "$table" $flags \
      -o "$work/robot"
    run_compare "$work/robot"
    ;;
  wrong_arith)
    q15="$src/gains/robot_corridor_q15.c"
    if configure_consumer -DCMAKE_PREFIX_PATH="$prefix" -DCONSUMER_TABLE="$q15" \
         >"$work/configure.log" 2>&1; then
      fail "a Q15 table configured against the float32 package"
    fi
    # CMake wraps the message: compare with the line breaks and indentation folded.
    tr -s ' \n' ' ' <"$work/configure.log" | grep -q "holds q15 tables, but stospline::stsp is" \
      || { cat "$work/configure.log"; fail "configure failed, but not on the arithmetic"; }
    echo "stospline_add_gains refused the Q15 table against the float32 library"
    export PKG_CONFIG_PATH="$prefix/lib/pkgconfig"
    read -r -a flags <<<"$(pkg-config --cflags stospline)"
    # The generated Q15 header under the float32 flags.
    if "$cc" -std=c99 -c "$q15" "${flags[@]}" -o "$work/q15.o" 2>"$work/q15.log"; then
      fail "the Q15 table compiled with the float32 library's flags"
    fi
    grep -q "holds Q15 tables" "$work/q15.log" || { cat "$work/q15.log"; fail "wrong error"; }
    # A fixed-point definition added to the float32 library's flags.
    if "$cc" -std=c99 -c "$here/main.c" -I"$src/gains" "${flags[@]}" -DSTSP_ARITH_Q15 \
         -o "$work/main.o" 2>"$work/main.log"; then
      fail "main.c compiled with STSP_ARITH_Q15 added to the float32 library's flags"
    fi
    grep -q "one arithmetic per build" "$work/main.log" || { cat "$work/main.log"; fail "wrong error"; }
    echo "the compiler refused both mixes"
    ;;
  presets)
    (cd "$src" && "$cmake" --list-presets=all)
    for preset in host-gcc host-clang; do
      compiler="$(sed -n "/\"name\": \"$preset\"/,/}/s/.*\"CMAKE_C_COMPILER\": \"\([^\"]*\)\".*/\1/p" \
                  "$src/CMakePresets.json")"
      if command -v "$compiler" >/dev/null; then
        "$cmake" -S "$src" --preset "$preset" -B "$work/$preset" -DSTSP_BUILD_TESTS=OFF >/dev/null
        echo "preset $preset: configured"
      else
        echo "preset $preset: $compiler not installed, not configured"
      fi
    done
    # name : Tag_CPU_arch : hard float? : toolchain CPU : arithmetic of the preset's library :
    # table of that arithmetic : FIXED_SHAPE
    for preset in arm-m4f:v7E-M:VFP:cortex-m4:float32:robot_corridor:ON \
                  arm-m0plus:v6S-M::cortex-m0plus:q15:robot_corridor_q15:OFF; do
      IFS=: read -r name arch vfp cpu arith gains fixed <<<"$preset"
      "$cmake" -S "$src" --preset "$name" -B "$work/$name" >/dev/null
      "$cmake" --build "$work/$name"
      # The same machine code as that arithmetic's library in the preset's full build
      # (tools/arm/build.sh: STSP_BUILD_TESTS=ON), which the QEMU replay test and the
      # instruction counts of docs/evidence/firmware-figures.md measure (that library alone).
      "$src/tools/arm/build.sh" --preset "$name" --build-dir "$work/$name-full" \
        --target "stsp_$arith" >/dev/null
      for lib in "$work/$name/libstsp.a" "$work/$name-full/libstsp_$arith.a"; do
        arm-none-eabi-objdump -d "$lib" | grep -v "file format\|^In archive" >"$lib.dis"
      done
      cmp "$work/$name/libstsp.a.dis" "$work/$name-full/libstsp_$arith.a.dis" \
        || fail "$name: the preset's libstsp.a differs from the full build's libstsp_$arith.a"
      no_tests_built "$work/$name" "$work/$name"
      "$cmake" --install "$work/$name" --prefix "$work/$name-prefix" >/dev/null
      attrs="$(arm-none-eabi-readelf -A "$work/$name-prefix/lib/libstsp.a")"
      grep -q "Tag_CPU_arch: $arch\$" <<<"$attrs" || fail "$name: not $arch code"
      if [ -n "$vfp" ]; then
        grep -q "Tag_ABI_VFP_args: VFP registers" <<<"$attrs" || fail "$name: not hard float"
      elif grep -q "Tag_ABI_VFP_args" <<<"$attrs"; then
        fail "$name: not soft float"
      fi
      if grep -q STSP_HOST_MESSAGES "$work/$name-prefix/lib/pkgconfig/stospline.pc"; then
        fail "$name: host messages in a target build"
      fi
      # A cross-compiled firmware project: find_package and the installed toolchain file; the
      # table library only (an image needs the project's own startup code and linker script).
      "$cmake" -S "$here" -B "$work/$name-consumer" -G "$generator" \
        -DCMAKE_TOOLCHAIN_FILE="$work/$name-prefix/share/stospline/toolchains/arm-none-eabi.cmake" \
        -DSTSP_ARM_CPU="$cpu" -DCMAKE_PREFIX_PATH="$work/$name-prefix" \
        -DCONSUMER_TABLE="$src/gains/$gains.c" -DCONSUMER_FIXED_SHAPE="$fixed" >/dev/null
      "$cmake" --build "$work/$name-consumer" --target robot_gains >/dev/null
      arm-none-eabi-readelf -A "$work/$name-consumer/librobot_gains.a" | grep -q "Tag_CPU_arch: $arch\$" \
        || fail "$name: the consumer's table library is not $arch code"
      echo "preset $name: libstsp.a is $arch code$([ -n "$vfp" ] && echo ", hard float")," \
           "$(wc -l <"$work/$name/libstsp.a.dis") lines of disassembly identical to the full build's;" \
           "$gains.c built against it by find_package (FIXED_SHAPE $fixed)"
    done
    ;;
  *)
    echo "run.sh: unknown mode $mode" >&2
    exit 2
    ;;
esac
echo "run.sh ($mode): OK"
