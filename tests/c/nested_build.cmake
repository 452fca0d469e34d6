# Configure and build the project again with another C compiler (the `clang_build` test):
#   cmake -DSRC=<repo> -DBIN=<dir> -DCC=<compiler> [-DGENERATOR=Ninja] -P nested_build.cmake
# The nested build has STSP_NESTED=ON (no ARM tests, no further nesting, no MISRA run) and
# STSP_FUZZ=ON (the libFuzzer target when the compiler links -fsanitize=fuzzer).
foreach(var SRC BIN CC)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "nested_build.cmake: -D${var}=... missing")
  endif()
endforeach()
if(NOT DEFINED GENERATOR)
  set(GENERATOR "Ninja")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SRC} -B ${BIN} -G ${GENERATOR}
                        -DCMAKE_C_COMPILER=${CC} -DCMAKE_BUILD_TYPE=Release
                        -DSTSP_NESTED=ON -DSTSP_FUZZ=ON
                RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "nested_build: configuring ${BIN} with ${CC} failed (${rc})")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${BIN} RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "nested_build: building ${BIN} with ${CC} failed (${rc})")
endif()
