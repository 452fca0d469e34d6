# The library as other projects see it: the namespaced target stospline::stsp (in this build
# tree and after find_package), and the install rules (headers, the library for STSP_ARITH, the
# CMake package with stospline_add_gains(), stospline.pc, the ARM toolchain file, and the
# firmware sources for stospline_add_gains(... FIXED_SHAPE)). Included by CMakeLists.txt after
# the `stsp` target is defined.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

# The arithmetic travels with the target: a property (read by stospline_add_gains, exported
# into the package) and, for float32 too, a definition that every consumer compiles with
# (stsp_types.h refuses STSP_ARITH_FLOAT32 together with STSP_ARITH_Q15/Q31).
string(TOUPPER "STSP_ARITH_${STSP_ARITH}" _stsp_arith_def)
if(STSP_ARITH STREQUAL "float32")  # (Q15/Q31: stsp_add_controller gave `stsp` the definition)
  target_compile_definitions(stsp PUBLIC ${_stsp_arith_def})
endif()
target_include_directories(stsp PUBLIC $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
set_target_properties(stsp PROPERTIES STSP_ARITH "${STSP_ARITH}" EXPORT_PROPERTIES STSP_ARITH
                      EXPORT_NAME stsp)
add_library(stospline::stsp ALIAS stsp)
set_property(GLOBAL PROPERTY STOSPLINE_FIRMWARE_SOURCE_DIR "${CMAKE_CURRENT_SOURCE_DIR}/firmware/src")

option(STSP_INSTALL "Generate the install rules (cmake --install)" ${PROJECT_IS_TOP_LEVEL})
if(NOT STSP_INSTALL)
  return()
endif()

set(STSP_INSTALL_CMAKEDIR "${CMAKE_INSTALL_LIBDIR}/cmake/stospline" CACHE STRING
    "Where cmake --install puts stosplineConfig.cmake (relative to the prefix)")
set(STSP_INSTALL_DATADIR "${CMAKE_INSTALL_DATADIR}/stospline")
set(STSP_INSTALL_SRCDIR "${STSP_INSTALL_DATADIR}/src")
set(STSP_INSTALL_TOOLCHAINDIR "${STSP_INSTALL_DATADIR}/toolchains")

install(TARGETS stsp EXPORT stosplineTargets
        ARCHIVE DESTINATION "${CMAKE_INSTALL_LIBDIR}"
        LIBRARY DESTINATION "${CMAKE_INSTALL_LIBDIR}")
install(DIRECTORY "${CMAKE_CURRENT_SOURCE_DIR}/firmware/include/stospline"
        DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}")
file(GLOB _stsp_private_sources "${CMAKE_CURRENT_SOURCE_DIR}/firmware/src/*.[ch]")
install(FILES ${_stsp_private_sources} DESTINATION "${STSP_INSTALL_SRCDIR}")
install(FILES "${CMAKE_CURRENT_SOURCE_DIR}/tools/arm/arm-none-eabi.cmake"
        DESTINATION "${STSP_INSTALL_TOOLCHAINDIR}")
install(EXPORT stosplineTargets NAMESPACE stospline:: DESTINATION "${STSP_INSTALL_CMAKEDIR}")

configure_package_config_file(
  "${CMAKE_CURRENT_SOURCE_DIR}/cmake/stosplineConfig.cmake.in"
  "${CMAKE_CURRENT_BINARY_DIR}/stosplineConfig.cmake"
  INSTALL_DESTINATION "${STSP_INSTALL_CMAKEDIR}"
  PATH_VARS STSP_INSTALL_SRCDIR STSP_INSTALL_TOOLCHAINDIR)
# 0.x: a minor version may change the table format, so only the same minor version matches.
write_basic_package_version_file("${CMAKE_CURRENT_BINARY_DIR}/stosplineConfigVersion.cmake"
                                 COMPATIBILITY SameMinorVersion)
install(FILES "${CMAKE_CURRENT_BINARY_DIR}/stosplineConfig.cmake"
        "${CMAKE_CURRENT_BINARY_DIR}/stosplineConfigVersion.cmake"
        "${CMAKE_CURRENT_SOURCE_DIR}/cmake/stosplineGains.cmake"
        DESTINATION "${STSP_INSTALL_CMAKEDIR}")

# pkg-config: prefix relative to the .pc file, so the installed tree can be moved.
set(_stsp_pc_dir "${CMAKE_INSTALL_LIBDIR}/pkgconfig")
if(IS_ABSOLUTE "${CMAKE_INSTALL_LIBDIR}" OR IS_ABSOLUTE "${CMAKE_INSTALL_INCLUDEDIR}")
  set(STSP_PC_PREFIX "${CMAKE_INSTALL_PREFIX}")
  set(STSP_PC_LIBDIR "${CMAKE_INSTALL_FULL_LIBDIR}")
  set(STSP_PC_INCLUDEDIR "${CMAKE_INSTALL_FULL_INCLUDEDIR}")
else()
  file(RELATIVE_PATH _stsp_pc_up "/prefix/${_stsp_pc_dir}" "/prefix")
  string(REGEX REPLACE "/$" "" _stsp_pc_up "${_stsp_pc_up}")
  set(STSP_PC_PREFIX "\${pcfiledir}/${_stsp_pc_up}")
  set(STSP_PC_LIBDIR "\${prefix}/${CMAKE_INSTALL_LIBDIR}")
  set(STSP_PC_INCLUDEDIR "\${prefix}/${CMAKE_INSTALL_INCLUDEDIR}")
endif()
# The bit-exact contract's options, as stospline::stsp carries them (stsp_add_controller).
set(STSP_PC_CFLAGS "-D${_stsp_arith_def} -fno-fast-math -ffp-contract=off")
if(NOT CMAKE_CROSSCOMPILING)
  string(APPEND STSP_PC_CFLAGS " -DSTSP_HOST_MESSAGES")
endif()
configure_file("${CMAKE_CURRENT_SOURCE_DIR}/cmake/stospline.pc.in"
               "${CMAKE_CURRENT_BINARY_DIR}/stospline.pc" @ONLY)
install(FILES "${CMAKE_CURRENT_BINARY_DIR}/stospline.pc" DESTINATION "${_stsp_pc_dir}")
