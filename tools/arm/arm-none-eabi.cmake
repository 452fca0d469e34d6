# CMake toolchain file: arm-none-eabi-gcc for bare-metal Cortex-M (Debian's gcc-arm-none-eabi
# + libnewlib-arm-none-eabi, installed by tools/setup.sh).
#
#   cmake --preset arm-m4f       (CMakePresets.json: this file, -O2, STSP_ARM_CPU=cortex-m4)
#   cmake --preset arm-m0plus    (soft-float ARMv6-M)
#   cmake --preset arm-m0        (soft-float ARMv6-M, the Cortex-M0 of the nRF51 / micro:bit)
# or, in a firmware project: -DCMAKE_TOOLCHAIN_FILE=<this file> [-DSTSP_ARM_CPU=cortex-m0plus]
#
# Only the CPU/ABI flags live here; warnings and -ffp-contract=off are set by CMakeLists.txt.
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)

set(STSP_ARM_CPU "cortex-m4" CACHE STRING
    "Target core: cortex-m4 (hard-float FPv4-SP), cortex-m0plus or cortex-m0")
set_property(CACHE STSP_ARM_CPU PROPERTY STRINGS cortex-m4 cortex-m0plus cortex-m0)
# try_compile projects re-read this file and need the CPU too.
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES STSP_ARM_CPU)

find_program(CMAKE_C_COMPILER arm-none-eabi-gcc REQUIRED)
find_program(CMAKE_AR arm-none-eabi-ar REQUIRED)
find_program(CMAKE_RANLIB arm-none-eabi-ranlib REQUIRED)
find_program(CMAKE_OBJCOPY arm-none-eabi-objcopy)
find_program(CMAKE_SIZE arm-none-eabi-size)
find_program(CMAKE_NM arm-none-eabi-nm)

if(STSP_ARM_CPU STREQUAL "cortex-m4")
  set(_stsp_cpu_flags "-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard")
elseif(STSP_ARM_CPU MATCHES "^cortex-m0(plus)?$")
  set(_stsp_cpu_flags "-mcpu=${STSP_ARM_CPU} -mthumb -mfloat-abi=soft")
else()
  message(FATAL_ERROR
          "STSP_ARM_CPU must be cortex-m4, cortex-m0plus or cortex-m0, not '${STSP_ARM_CPU}'")
endif()
set(CMAKE_C_FLAGS_INIT "${_stsp_cpu_flags}")
set(CMAKE_ASM_FLAGS_INIT "${_stsp_cpu_flags}")
# Images are linked by the project with its own script and --specs; the compiler check must not
# try to link a hosted executable.
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
