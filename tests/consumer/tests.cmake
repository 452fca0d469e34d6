# The consumer tests (included by CMakeLists.txt on the host, top-level, tests on): the project
# in tests/consumer built against stospline as a user would, through tests/consumer/run.sh, each
# run compared with the cffi harness bit for bit. consumer_install installs stospline to a
# temporary prefix (build/consumer/install/prefix) for the tests that need the package.
set(STSP_VENV_PYTHON ${CMAKE_CURRENT_SOURCE_DIR}/.venv/bin/python)
find_program(STSP_PKG_CONFIG pkg-config)
if(NOT EXISTS ${STSP_VENV_PYTHON} OR NOT STSP_PKG_CONFIG)
  message(STATUS "consumer tests skipped: .venv or pkg-config missing (tools/setup.sh makes them)")
  return()
endif()
set(consumer_dir ${CMAKE_CURRENT_BINARY_DIR}/consumer)
set(consumer_modes install find_package find_package_fixed add_subdirectory two_arith fetchcontent_fixed
    hostile_flags
    pkg_config wrong_arith)
find_program(STSP_ARM_READELF arm-none-eabi-readelf)
if(STSP_ARM_GCC AND STSP_ARM_READELF)
  list(APPEND consumer_modes presets)
endif()
if(STSP_ARM_GCC AND STSP_QEMU_ARM AND IS_ABSOLUTE "${STSP_ARM_NEWLIB}")
  list(APPEND consumer_modes qemu_nano)
endif()
foreach(mode ${consumer_modes})
  add_test(NAME consumer_${mode}
           COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/tests/consumer/run.sh ${mode} ${consumer_dir}/${mode}
                   --cmake ${CMAKE_COMMAND} --cc ${CMAKE_C_COMPILER} --python ${STSP_VENV_PYTHON}
                   --generator ${CMAKE_GENERATOR})
  set_tests_properties(consumer_${mode} PROPERTIES LABELS consumer TIMEOUT 180)
endforeach()
if(TEST consumer_presets)
  # Cortex-M builds of the library: the longest consumer test, started before the others under
  # `ctest -j` (COST), with room for sharing the cores with the other tests.
  set_tests_properties(consumer_presets PROPERTIES COST 25 TIMEOUT 600)
endif()
set_tests_properties(consumer_install PROPERTIES FIXTURES_SETUP stsp_prefix)
set_tests_properties(consumer_find_package consumer_find_package_fixed consumer_pkg_config
                     consumer_hostile_flags
                     consumer_wrong_arith PROPERTIES FIXTURES_REQUIRED stsp_prefix)
