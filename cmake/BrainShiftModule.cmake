# Helpers shared by every library of the project.

# brainshift_add_library(NAME <target> SOURCES ... [PUBLIC_LIBS ...] [PRIVATE_LIBS ...])
# A static library whose headers are found from its own folder.
function(brainshift_add_library)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;PUBLIC_LIBS;PRIVATE_LIBS" ${ARGN})
  add_library(${ARG_NAME} STATIC ${ARG_SOURCES})
  target_include_directories(${ARG_NAME} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR})
  target_link_libraries(${ARG_NAME} PUBLIC ${ARG_PUBLIC_LIBS} PRIVATE ${ARG_PRIVATE_LIBS})
  target_compile_options(${ARG_NAME} PRIVATE -Wall -Wextra -Wno-deprecated-copy)
endfunction()

# brainshift_add_test_driver(NAME <driver> TESTS <TestName>... [LIBS ...] [LABELS ...])
# One driver per library (VTK/Slicer style): each test is a function `int TestName(int, char*[])`
# in TestName.cxx beside the caller; every function becomes one CTest test.
function(brainshift_add_test_driver)
  cmake_parse_arguments(ARG "" "NAME" "TESTS;LIBS;LABELS;ENVIRONMENT" ${ARGN})
  if(NOT BRAINSHIFT_BUILD_TESTING)
    return()
  endif()
  set(sources)
  foreach(test ${ARG_TESTS})
    list(APPEND sources ${test}.cxx)
  endforeach()
  create_test_sourcelist(driver_sources ${ARG_NAME}.cxx ${sources})
  add_executable(${ARG_NAME} ${driver_sources})
  target_link_libraries(${ARG_NAME} PRIVATE BrainShiftTesting ${ARG_LIBS})
  target_compile_options(${ARG_NAME} PRIVATE -Wall -Wextra -Wno-deprecated-copy)
  # VTK's object factories (readers, writers, data objects) register only with autoinit.
  vtk_module_autoinit(TARGETS ${ARG_NAME} MODULES ${VTK_LIBRARIES})
  foreach(test ${ARG_TESTS})
    add_test(NAME ${test} COMMAND ${ARG_NAME} ${test})
    set_tests_properties(${test} PROPERTIES
      LABELS "${ARG_LABELS}"
      ENVIRONMENT "BRAINSHIFT_TEST_TEMP=${PROJECT_BINARY_DIR}/Testing/Temporary;${ARG_ENVIRONMENT}")
  endforeach()
endfunction()
