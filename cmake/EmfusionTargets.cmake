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
  if(EMFUSION_SANITIZERS)
    # Host code only: nvcc does not take -fsanitize (the CUDA build is
    # checked with compute-sanitizer instead, docs/building.md). GCC's
    # -Wmaybe-uninitialized gives false positives under the sanitizers
    # (libstdc++'s <regex> with -fsanitize=address), so it is off there.
    # Every check stops the process, except `null`, which stays recoverable so
    # that tests/support/ubsan.supp can suppress thrust's own null-reference
    # idiom (UBSan suppresses only recoverable checks; halt_on_error=1 in the
    # test preset still stops on any other null report).
    # EMFUSION_SANITIZERS_EXCLUDE leaves checks out (-fno-sanitize=): the
    # asan-ubsan preset drops UBSan's alignment, null, vptr, pointer-overflow
    # and object-size checks, which made the unit tests' build half as long
    # again (docs/building.md); the fuzzers keep all of UBSan on the parsers.
    list(JOIN EMFUSION_SANITIZERS "," _emf_sanitizers)
    set(_emf_recover)
    if("undefined" IN_LIST EMFUSION_SANITIZERS)
      set(_emf_recover -fsanitize-recover=null)
    endif()
    set(_emf_exclude)
    if(EMFUSION_SANITIZERS_EXCLUDE)
      list(JOIN EMFUSION_SANITIZERS_EXCLUDE "," _emf_excluded)
      set(_emf_exclude -fno-sanitize=${_emf_excluded})
    endif()
    target_compile_options(${target} PRIVATE
      $<$<COMPILE_LANGUAGE:CXX>:-fsanitize=${_emf_sanitizers} ${_emf_exclude} -fno-sanitize-recover=all ${_emf_recover} -fno-omit-frame-pointer -g1>
      $<$<AND:$<COMPILE_LANGUAGE:CXX>,$<CXX_COMPILER_ID:GNU>>:-Wno-maybe-uninitialized>)
    target_link_options(${target} PRIVATE -fsanitize=${_emf_sanitizers} ${_emf_exclude})
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
