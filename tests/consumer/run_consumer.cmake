# Script of the `consumer` ctest test (cmake -P). Steps, each failing loudly:
#   1. cmake --install <emfusion build dir> --prefix <EMF_PREFIX>  (fresh prefix)
#   2. configure <EMF_CONSUMER_SOURCE> with CMAKE_PREFIX_PATH=<EMF_PREFIX>
#   3. build it, 4. run the consumer executable (non-zero exit = wrong result).
cmake_minimum_required(VERSION 3.24)

foreach(var EMF_INSTALL_FROM EMF_PREFIX EMF_CONSUMER_SOURCE EMF_CONSUMER_BUILD EMF_CXX_COMPILER)
  if(NOT DEFINED ${var} OR "${${var}}" STREQUAL "")
    message(FATAL_ERROR "run_consumer.cmake: -D${var}=... is required")
  endif()
endforeach()
if(NOT EMF_BUILD_TYPE)
  set(EMF_BUILD_TYPE Release)
endif()

# Runs a command; on failure prints its output and stops with `what`.
function(emf_step what)
  string(REPLACE ";" " " _cmdline "${ARGN}")
  message(STATUS "consumer test: ${what}\n  $ ${_cmdline}")
  execute_process(COMMAND ${ARGN}
    RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _out)
  if(NOT _rc EQUAL 0)
    message(FATAL_ERROR "consumer test FAILED at step: ${what} (exit ${_rc})\n"
                        "command: ${_cmdline}\n--- output ---\n${_out}--- end of output ---")
  endif()
  message(STATUS "${_out}")
endfunction()

# Start from nothing so that stale files cannot hide a broken install.
file(REMOVE_RECURSE "${EMF_PREFIX}" "${EMF_CONSUMER_BUILD}")

emf_step("installing emfusion from ${EMF_INSTALL_FROM} into ${EMF_PREFIX}"
  ${CMAKE_COMMAND} --install "${EMF_INSTALL_FROM}" --prefix "${EMF_PREFIX}" --config "${EMF_BUILD_TYPE}")

if(NOT EXISTS "${EMF_PREFIX}/include/emfusion/core/se3.hpp")
  message(FATAL_ERROR "consumer test FAILED: the install did not put the headers in "
                      "${EMF_PREFIX}/include/emfusion")
endif()
file(GLOB_RECURSE _emf_configs "${EMF_PREFIX}/*/emfusionConfig.cmake")
if(NOT _emf_configs)
  message(FATAL_ERROR "consumer test FAILED: no emfusionConfig.cmake under ${EMF_PREFIX}")
endif()

set(_generator_args)
if(EMF_GENERATOR)
  set(_generator_args -G "${EMF_GENERATOR}")
endif()
emf_step("configuring the consumer project with find_package(emfusion)"
  ${CMAKE_COMMAND} -S "${EMF_CONSUMER_SOURCE}" -B "${EMF_CONSUMER_BUILD}" ${_generator_args}
    "-DCMAKE_PREFIX_PATH=${EMF_PREFIX}"
    "-DCMAKE_BUILD_TYPE=${EMF_BUILD_TYPE}"
    "-DCMAKE_CXX_COMPILER=${EMF_CXX_COMPILER}"
    "-DCONSUMER_WERROR=${EMF_WERROR}")

emf_step("building the consumer"
  ${CMAKE_COMMAND} --build "${EMF_CONSUMER_BUILD}" --config "${EMF_BUILD_TYPE}")

# Single-config generators put the executable at the top of the build dir,
# multi-config ones in a per-config folder.
set(_exe "${EMF_CONSUMER_BUILD}/emfusion_consumer")
if(NOT EXISTS "${_exe}")
  set(_exe "${EMF_CONSUMER_BUILD}/${EMF_BUILD_TYPE}/emfusion_consumer")
endif()
if(NOT EXISTS "${_exe}")
  message(FATAL_ERROR "consumer test FAILED: the build made no emfusion_consumer executable in ${EMF_CONSUMER_BUILD}")
endif()
emf_step("running the consumer (checks SE3 exp/log and a host reduction)" "${_exe}")

message(STATUS "consumer test passed")
