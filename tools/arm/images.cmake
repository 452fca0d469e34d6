# Runnable Cortex-M images of the top-level project's cross build (presets arm-m4f, arm-m0plus
# with STSP_BUILD_TESTS=ON; tools/arm/build.sh). Included by CMakeLists.txt: the controller
# variants (stsp_float32, stsp_q15, stsp_q31), the table libraries (stsp_gains_<name>) and the
# builds for each table's shape (stsp_fixed_<name>, compiled once per shape and arithmetic) are
# the ones defined there, the same firmware definition as the host build.
#
# Semihosting for output and exit status: QEMU mps2-an386 (Cortex-M4F) runs the cortex-m4 build;
# the cortex-m0plus build runs on mps2-an385 (a Cortex-M3: QEMU has no M0+ board; ARMv6-M code
# is a subset of ARMv7-M, and the two boards share the memory map the linker script uses).
# Float32 images on cortex-m4 only; Q15/Q31 images on both.
#   bench<sfx>.elf, bench_fixed<sfx>.elf    tools/arm/bench_main.c (count_instructions.sh)
#   replay<sfx>.elf, replay_fixed<sfx>.elf  tests/arm/replay_main.c with the records file given
#                                           as STSP_REPLAY_RECORDS<_Q15|_Q31> (run_replay.sh)
#   replay_spline.elf, replay_spline_fixed.elf  the same on gains/robot_corridor_spline.c (float32;
#                                           on both cores, soft float on the M0+), records
#                                           STSP_REPLAY_RECORDS_SPLINE (make_replay.py --table
#                                           spline); STSP_REPLAY_PERTURB_COEF=<n> nudges a
#                                           coefficient (the test must then fail)
#   replay_<q15|q31>_spline[_fixed].elf  the same on gains/robot_corridor_<arith>_spline.c (the
#                                           fixed-point controller, both cores), records
#                                           STSP_REPLAY_RECORDS_<Q15|Q31>_SPLINE
#   bench_<q15|q31>_spline[_fixed].elf  bench_main.c on gains/robot_corridor_<arith>_spline.c
#   bench_spline.elf, bench_spline_fixed.elf  bench_main.c with BENCH_SPLINE: the spline table of
#                                           tools/arm/spline_bench_table.c (float32; on both
#                                           cores, soft float on the M0+)
#   shapes.elf                              tests/arm/shapes_main.c: the generic float32 law on
#                                           every shape up to nx 9, nu 5, n_latch 6 against the
#                                           documented order (cortex-m4 only; run_replay.sh)
if(NOT TARGET stsp_gains_robot_corridor)
  return()
endif()
set(arm_dir ${CMAKE_CURRENT_LIST_DIR})
set(STSP_LINKER_SCRIPT "${arm_dir}/mps2-an386.ld")
add_library(stsp_startup OBJECT ${arm_dir}/startup.c)
target_compile_options(stsp_startup PRIVATE ${STSP_WARNINGS})

# stsp_add_image(<name> <controller library> <tables library> <sources...>)
function(stsp_add_image name controller tables)
  add_executable(${name} ${ARGN} $<TARGET_OBJECTS:stsp_startup>)
  set_target_properties(${name} PROPERTIES SUFFIX ".elf" LINK_DEPENDS "${STSP_LINKER_SCRIPT}")
  # the tables first: a table refers to the controller's optional code (stsp_internal.h)
  target_link_libraries(${name} PRIVATE ${tables} ${controller})
  target_compile_options(${name} PRIVATE ${STSP_WARNINGS})
  target_include_directories(${name} PRIVATE "${PROJECT_SOURCE_DIR}/tests/arm")  # robot_variant.h
  target_link_options(${name} PRIVATE --specs=rdimon.specs -T "${STSP_LINKER_SCRIPT}"
                      -Wl,--gc-sections -Wl,-Map=$<TARGET_FILE_DIR:${name}>/${name}.map)
endfunction()

# stsp_add_image_pair(<name> <generic controller> <shaped controller> <tables library>
#                     SOURCES <sources...> [DEFINES <definitions...>]): the images <name> (the
# generic controller) and <name>_fixed (the controller built for the table's shape) of the
# same sources and definitions.
function(stsp_add_image_pair name generic shaped tables)
  cmake_parse_arguments(arg "" "" "SOURCES;DEFINES" ${ARGN})
  stsp_add_image(${name} ${generic} ${tables} ${arg_SOURCES})
  stsp_add_image(${name}_fixed ${shaped} ${tables} ${arg_SOURCES})
  if(arg_DEFINES)
    target_compile_definitions(${name} PRIVATE ${arg_DEFINES})
    target_compile_definitions(${name}_fixed PRIVATE ${arg_DEFINES})
  endif()
endfunction()
set(replay_main "${PROJECT_SOURCE_DIR}/tests/arm/replay_main.c")
set(STSP_REPLAY_PERTURB_COEF "" CACHE STRING
    "test the test: the spline replay images move this coefficient by one ulp (empty: none)")
set(perturb "")
if(NOT STSP_REPLAY_PERTURB_COEF STREQUAL "")
  set(perturb REPLAY_PERTURB_COEF=${STSP_REPLAY_PERTURB_COEF}u)
endif()

set(STSP_REPLAY_RECORDS "" CACHE FILEPATH "float32 records (tools/arm/make_replay.py)")
set(STSP_REPLAY_RECORDS_Q15 "" CACHE FILEPATH "Q15 records (make_replay.py --arith q15)")
set(STSP_REPLAY_RECORDS_Q31 "" CACHE FILEPATH "Q31 records (make_replay.py --arith q31)")
foreach(arith float32 q15 q31)
  set(sfx "_${arith}")
  if(arith STREQUAL "float32")
    set(sfx "")
    if(NOT STSP_ARM_CPU STREQUAL "cortex-m4")
      continue()
    endif()
  endif()
  set(tables stsp_gains_robot_corridor${sfx})
  set(shaped stsp_fixed_robot_corridor${sfx})
  if(NOT TARGET ${tables})
    continue()
  endif()
  stsp_add_image(bench${sfx} stsp_${arith} ${tables} ${arm_dir}/bench_main.c)
  if(arith STREQUAL "float32")
    stsp_add_image(shapes stsp_float32 ${tables} "${PROJECT_SOURCE_DIR}/tests/arm/shapes_main.c")
  endif()
  stsp_add_image(bench_fixed${sfx} ${shaped} ${tables} ${arm_dir}/bench_main.c)
  string(TOUPPER "STSP_REPLAY_RECORDS${sfx}" records_var)
  set(records "${${records_var}}")
  if(records)
    stsp_add_image(replay${sfx} stsp_${arith} ${tables} "${replay_main}" "${records}")
    stsp_add_image(replay_fixed${sfx} ${shaped} ${tables} "${replay_main}" "${records}")
  endif()
endforeach()

# The replay of the robot's spline table (float32 controller, generic and built for the robot's
# shape; the M0+ runs it in soft float).
set(STSP_REPLAY_RECORDS_SPLINE "" CACHE FILEPATH "spline records (make_replay.py --table spline)")
if(STSP_REPLAY_RECORDS_SPLINE AND TARGET stsp_gains_robot_corridor_spline)
  stsp_add_image_pair(replay_spline stsp_float32 stsp_fixed_robot_corridor_spline
                      stsp_gains_robot_corridor_spline
                      SOURCES "${replay_main}" "${STSP_REPLAY_RECORDS_SPLINE}"
                      DEFINES ROBOT_SPLINE ${perturb})
endif()

# The replay of robot_bands' spline table (its band dual re-solved for the spline's gains: the
# band solver's Gaussian-elimination path at the t0 latch), generic and shaped.
set(STSP_REPLAY_RECORDS_BANDS_SPLINE "" CACHE FILEPATH
    "robot_bands spline records (make_replay.py --table spline --problem examples/robot_bands.toml)")
if(STSP_REPLAY_RECORDS_BANDS_SPLINE AND TARGET stsp_gains_robot_bands_spline)
  stsp_add_image_pair(replay_bands_spline stsp_float32 stsp_fixed_robot_bands_spline
                      stsp_gains_robot_bands_spline
                      SOURCES "${replay_main}" "${STSP_REPLAY_RECORDS_BANDS_SPLINE}"
                      DEFINES ROBOT_SPLINE ROBOT_BANDS_SPLINE)
endif()

# The replay of the robot's Q15/Q31 spline tables (gains/robot_corridor_<arith>_spline.c; the
# fixed-point controller, generic and built for the robot's shape), records
# STSP_REPLAY_RECORDS_<ARITH>_SPLINE (make_replay.py --arith <arith> --table spline).
foreach(arith q15 q31)
  string(TOUPPER "${arith}" ARITH)
  set(STSP_REPLAY_RECORDS_${ARITH}_SPLINE "" CACHE FILEPATH
      "${ARITH} spline records (make_replay.py --arith ${arith} --table spline)")
  set(records "${STSP_REPLAY_RECORDS_${ARITH}_SPLINE}")
  if(records AND TARGET stsp_gains_robot_corridor_${arith}_spline)
    stsp_add_image_pair(replay_${arith}_spline stsp_${arith}
                        stsp_fixed_robot_corridor_${arith}_spline
                        stsp_gains_robot_corridor_${arith}_spline
                        SOURCES "${replay_main}" "${records}" DEFINES ROBOT_SPLINE ${perturb})
  endif()
endforeach()
# The instruction-count bench (bench_main.c) on the robot's Q15/Q31 spline tables
# (count_instructions.sh), generic and built for the robot's shape.
foreach(arith q15 q31)
  if(TARGET stsp_gains_robot_corridor_${arith}_spline)
    stsp_add_image_pair(bench_${arith}_spline stsp_${arith}
                        stsp_fixed_robot_corridor_${arith}_spline
                        stsp_gains_robot_corridor_${arith}_spline
                        SOURCES ${arm_dir}/bench_main.c DEFINES ROBOT_SPLINE)
  endif()
endforeach()
# The spline bench: a hand-made spline table of the robot's shape (make_spline_bench_table.py)
# with the float32 controller, generic and built for the robot's shape.
add_library(stsp_spline_bench_table STATIC ${arm_dir}/spline_bench_table.c)
target_include_directories(stsp_spline_bench_table PUBLIC ${arm_dir}
                           ${PROJECT_SOURCE_DIR}/firmware/include)
target_compile_options(stsp_spline_bench_table PRIVATE ${STSP_WARNINGS})
stsp_add_image_pair(bench_spline stsp_float32 stsp_fixed_robot_corridor stsp_spline_bench_table
                    SOURCES ${arm_dir}/bench_main.c DEFINES BENCH_SPLINE)
