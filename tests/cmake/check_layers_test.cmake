# The layers hold by construction: cmake/check_layers.cmake passes on the tree as it is and fails,
# naming the file and the include, on a copy of src/ where the lowest layer includes the scheduler.
#   cmake -DSOURCE=<repo> -DTABLE=<build>/microbsdf_layers.cmake -DWORK=<scratch dir> -P check_layers_test.cmake
cmake_minimum_required(VERSION 3.25)
set(check ${SOURCE}/cmake/check_layers.cmake)
execute_process(COMMAND ${CMAKE_COMMAND} -DSRC=${SOURCE}/src -DTABLE=${TABLE} -P ${check}
                RESULT_VARIABLE clean_rc ERROR_VARIABLE clean_err)
if(NOT clean_rc EQUAL 0)
  message(FATAL_ERROR "the tree breaks its own layers:\n${clean_err}")
endif()
file(REMOVE_RECURSE ${WORK})
file(COPY ${SOURCE}/src DESTINATION ${WORK})
file(APPEND ${WORK}/src/core/vecmath.h "\n#include \"cluster/runner.h\"\n")
execute_process(COMMAND ${CMAKE_COMMAND} -DSRC=${WORK}/src -DTABLE=${TABLE} -P ${check}
                RESULT_VARIABLE bad_rc ERROR_VARIABLE bad_err)
file(REMOVE_RECURSE ${WORK})
if(bad_rc EQUAL 0)
  message(FATAL_ERROR "an upward include (core -> cluster) passed the layer check")
endif()
if(NOT bad_err MATCHES "src/core/vecmath.h: #include \"cluster/runner.h\"")
  message(FATAL_ERROR "the layer check failed without naming the file and include:\n${bad_err}")
endif()
message(STATUS "layers hold; an upward include is refused:\n${bad_err}")
