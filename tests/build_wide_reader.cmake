# Configures and builds examples/wide_reader as a user would, on its own (it must need
# nothing of bvhopt but the documented export format). Run by ctest as the setup of the
# tests that compare its hits with bvhopt's.
foreach(var SOURCE_DIR BINARY_DIR GENERATOR CXX)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "build_wide_reader.cmake: ${var} not set")
  endif()
endforeach()
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${BINARY_DIR} -G ${GENERATOR}
                        -DCMAKE_CXX_COMPILER=${CXX} -DCMAKE_BUILD_TYPE=Release
                RESULT_VARIABLE configured)
if(NOT configured EQUAL 0)
  message(FATAL_ERROR "examples/wide_reader: configure failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${BINARY_DIR} RESULT_VARIABLE built)
if(NOT built EQUAL 0)
  message(FATAL_ERROR "examples/wide_reader: build failed")
endif()
