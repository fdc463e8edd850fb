# Helpers for the project's own executables (tests, examples, benchmarks):
# warnings, and compiling the sources as CUDA in a CUDA build, so that every
# translation unit that includes emfusion sees one thrust device system.
include_guard(GLOBAL)

function(emfusion_use_project_settings target)
  target_link_libraries(${target} PRIVATE emfusion::emfusion)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic>
    $<$<COMPILE_LANGUAGE:CUDA>:-Xcompiler=-Wall,-Wextra>)
  if(EMFUSION_WERROR)
    target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Werror>
      $<$<COMPILE_LANGUAGE:CUDA>:-Werror=all-warnings>)
  endif()
  if(EMFUSION_WITH_CUDA)
    get_target_property(_srcs ${target} SOURCES)
    set_source_files_properties(${_srcs} TARGET_DIRECTORY ${target} PROPERTIES LANGUAGE CUDA)
    target_link_libraries(${target} PRIVATE CUDA::cudart)
  endif()
endfunction()

function(emfusion_add_executable name)
  add_executable(${name} ${ARGN})
  emfusion_use_project_settings(${name})
endfunction()

# A ctest entry that runs `target` with the arguments after EXPECT and passes
# only if it exits non-zero with output matching the regular expression
# `expect` (tests/support/expect_failure.cmake): bad input is refused with
# the message a user needs.
function(emfusion_add_failure_test name target expect)
  list(JOIN ARGN ";" args)
  add_test(NAME ${name} COMMAND ${CMAKE_COMMAND} "-DCOMMAND=$<TARGET_FILE:${target}>;${args}" "-DEXPECT=${expect}"
           -P ${PROJECT_SOURCE_DIR}/tests/support/expect_failure.cmake)
endfunction()
