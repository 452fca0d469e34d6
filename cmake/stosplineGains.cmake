# CMake functions for generated gain tables (`stospline design` writes <name>.c and <name>.h).
# Loaded by stospline's own CMakeLists.txt (so add_subdirectory/FetchContent users have them) and
# by the installed package config (find_package(stospline)). The one place that reads a
# generated header: the repository's builds (CMakeLists.txt, also cross-built) call
# stospline_read_gains_header() too.
include_guard(GLOBAL)

# stospline_read_gains_header(<table.c> <prefix>)
#
# Reads the header <table>.h that `stospline design` wrote next to <table.c> and sets, in the
# caller's scope:
#   <prefix>_NAME        the table's C prefix (<name>_table is the stsp_table_t)
#   <prefix>_HEADER      the header's path
#   <prefix>_ARITH       float32, q15 or q31 (a fixed-point header defines <NAME>_ARITH_Q15/Q31)
#   <prefix>_ARITH_DEFS  STSP_ARITH_Q15, STSP_ARITH_Q31 or nothing (float32)
#   <prefix>_NX, <prefix>_NU, <prefix>_N_LATCH   the table's dimensions
#   <prefix>_FIXED_DEFS  STSP_FIXED_NX=<nx>u;STSP_FIXED_NU=<nu>u;STSP_FIXED_N_LATCH=<n>u, the
#                        definitions of a controller built for this shape only
#   <prefix>_BAND_ROWS   rows of the table's band dual (<NAME>_BAND_ROWS; 0: none)
# A relative <table.c> is taken relative to the calling directory (CMAKE_CURRENT_SOURCE_DIR).
function(stospline_read_gains_header source prefix)
  get_filename_component(source "${source}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
  get_filename_component(dir "${source}" DIRECTORY)
  get_filename_component(name "${source}" NAME_WE)
  set(header "${dir}/${name}.h")
  if(NOT EXISTS "${header}")
    message(FATAL_ERROR "stospline: ${header} not found: the table ${source} needs the header "
                        "that `stospline design` writes next to it")
  endif()
  string(TOUPPER "${name}" uname)
  file(STRINGS "${header}" lines
       REGEX "^#define ${uname}_(NX|NU|N_LATCH|BAND_ROWS|ARITH_Q15|ARITH_Q31) ")
  set(arith float32)
  set(arith_defs "")
  set(band_rows 0)
  foreach(line IN LISTS lines)
    if(line MATCHES "^#define ${uname}_(NX|NU|N_LATCH) ([0-9]+)u$")
      set(dim_${CMAKE_MATCH_1} "${CMAKE_MATCH_2}")
    elseif(line MATCHES "^#define ${uname}_BAND_ROWS ([0-9]+)u$")
      set(band_rows "${CMAKE_MATCH_1}")
    elseif(line MATCHES "^#define ${uname}_ARITH_(Q15|Q31) 1$")
      string(TOLOWER "${CMAKE_MATCH_1}" arith)
      set(arith_defs "STSP_ARITH_${CMAKE_MATCH_1}")
    endif()
  endforeach()
  set(fixed_defs "")
  foreach(dim NX NU N_LATCH)
    if(NOT DEFINED dim_${dim})
      message(FATAL_ERROR "stospline: ${header} has no '#define ${uname}_${dim} <n>u': not a "
                          "header written by `stospline design` for ${name}.c")
    endif()
    set(${prefix}_${dim} "${dim_${dim}}" PARENT_SCOPE)
    list(APPEND fixed_defs "STSP_FIXED_${dim}=${dim_${dim}}u")
  endforeach()
  set(${prefix}_NAME "${name}" PARENT_SCOPE)
  set(${prefix}_HEADER "${header}" PARENT_SCOPE)
  set(${prefix}_ARITH "${arith}" PARENT_SCOPE)
  set(${prefix}_ARITH_DEFS "${arith_defs}" PARENT_SCOPE)
  set(${prefix}_FIXED_DEFS "${fixed_defs}" PARENT_SCOPE)
  set(${prefix}_BAND_ROWS "${band_rows}" PARENT_SCOPE)
endfunction()

# stospline_add_gains(<target> <path/to/name.c> [FIXED_SHAPE])
#
# A static library <target> holding the user's generated table <name>.c, built against the
# stospline::stsp library, which it links (PUBLIC): an executable links <target> only and gets
# the table, the controller, the include directories of both and the arithmetic's definitions.
# Fails at configure time when the table's arithmetic is not the library's (STSP_ARITH of
# stospline::stsp). FIXED_SHAPE: instead of stospline::stsp, link a controller compiled here from
# stospline's sources for this table's dimensions only (STSP_FIXED_NX/NU/N_LATCH, unrolled
# loops; the 78-instruction Cortex-M4F tick, docs/guide/firmware.md) as the library <target>_stsp;
# stsp_init() then refuses any other shape.
function(stospline_add_gains target source)
  cmake_parse_arguments(PARSE_ARGV 2 ARG "FIXED_SHAPE" "" "")
  if(ARG_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "stospline_add_gains: unknown argument(s) ${ARG_UNPARSED_ARGUMENTS} "
                        "(usage: stospline_add_gains(<target> <name>.c [FIXED_SHAPE]))")
  endif()
  if(NOT TARGET stospline::stsp)
    message(FATAL_ERROR "stospline_add_gains: no target stospline::stsp: call "
                        "find_package(stospline) or add_subdirectory(<stospline>) first")
  endif()
  get_filename_component(source "${source}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
  if(NOT EXISTS "${source}")
    message(FATAL_ERROR "stospline_add_gains: ${source} not found")
  endif()
  stospline_read_gains_header("${source}" table)
  get_target_property(lib_arith stospline::stsp STSP_ARITH)
  if(NOT table_ARITH STREQUAL lib_arith)
    message(FATAL_ERROR
            "stospline_add_gains: ${source} holds ${table_ARITH} tables, but stospline::stsp is "
            "the ${lib_arith} library (STSP_ARITH=${lib_arith}): generate the tables with "
            "`stospline design --arith ${lib_arith}` or build stospline with "
            "-DSTSP_ARITH=${table_ARITH}")
  endif()
  get_filename_component(dir "${source}" DIRECTORY)

  set(controller stospline::stsp)
  if(ARG_FIXED_SHAPE)
    set(controller ${target}_stsp)
    get_property(src_dir GLOBAL PROPERTY STOSPLINE_FIRMWARE_SOURCE_DIR)
    file(GLOB fw_sources "${src_dir}/*.c")
    if(NOT fw_sources)
      message(FATAL_ERROR "stospline_add_gains: FIXED_SHAPE needs stospline's sources, none in "
                          "'${src_dir}'")
    endif()
    add_library(${controller} STATIC ${fw_sources})
    target_include_directories(${controller}
      PUBLIC $<TARGET_PROPERTY:stospline::stsp,INTERFACE_INCLUDE_DIRECTORIES>
      PRIVATE "${src_dir}")
    target_compile_definitions(${controller}
      PUBLIC $<TARGET_PROPERTY:stospline::stsp,INTERFACE_COMPILE_DEFINITIONS> ${table_FIXED_DEFS})
    # The bit-exact contract's options that stospline::stsp carries (-fno-fast-math
    # -ffp-contract=off): after the project's own flags, whatever those are.
    target_compile_options(${controller}
      PUBLIC $<TARGET_PROPERTY:stospline::stsp,INTERFACE_COMPILE_OPTIONS>)
    target_link_options(${controller}
      INTERFACE $<TARGET_PROPERTY:stospline::stsp,INTERFACE_LINK_OPTIONS>)
    # ISO C99 too: GCC's -std=c99 keeps contraction off even without the option.
    set_target_properties(${controller} PROPERTIES C_STANDARD 99 C_STANDARD_REQUIRED ON
                          C_EXTENSIONS OFF STSP_ARITH "${lib_arith}")
  endif()

  add_library(${target} STATIC "${source}")
  target_include_directories(${target} PUBLIC "${dir}")
  target_link_libraries(${target} PUBLIC ${controller})
  set_target_properties(${target} PROPERTIES C_STANDARD 99 C_STANDARD_REQUIRED ON
                        C_EXTENSIONS OFF STSP_ARITH "${table_ARITH}")
endfunction()
