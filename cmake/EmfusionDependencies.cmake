# Finds what the core headers need (Eigen 3.4, thrust, optionally OpenMP) and
# attaches it to a target. Used by the build and by the installed package
# config, so that a consumer gets the same set-up as the library's own tests.
include_guard(GLOBAL)

find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(OpenMP COMPONENTS CXX)

# Thrust comes from the CUDA toolkit's CCCL when a toolkit is present, else
# from the system (Debian: libthrust-dev).
find_path(EMFUSION_THRUST_INCLUDE_DIR thrust/version.h
  HINTS ${CUDAToolkit_INCLUDE_DIRS}/cccl $ENV{CUDA_PATH}/include/cccl
        /usr/local/cuda/include/cccl /usr/local/cuda/include
  DOC "Directory that holds thrust/version.h")
if(NOT EMFUSION_THRUST_INCLUDE_DIR)
  message(FATAL_ERROR "thrust was not found: install the CUDA toolkit or "
                      "Debian's libthrust-dev (scripts/setup-debian.sh does)")
endif()

# Attaches the dependencies to TARGET (an INTERFACE library or imported target).
function(emfusion_link_dependencies target)
  target_link_libraries(${target} INTERFACE Eigen3::Eigen)
  target_include_directories(${target} SYSTEM INTERFACE $<BUILD_INTERFACE:${EMFUSION_THRUST_INCLUDE_DIR}>)
  # One thrust device system per translation unit kind: host-compiled units
  # use OpenMP (or the serial C++ system); CUDA units keep thrust's CUDA default.
  if(OpenMP_CXX_FOUND)
    target_link_libraries(${target} INTERFACE OpenMP::OpenMP_CXX)
    target_compile_definitions(${target} INTERFACE EMFUSION_HAS_OPENMP=1
      $<$<COMPILE_LANGUAGE:CXX>:THRUST_DEVICE_SYSTEM=THRUST_DEVICE_SYSTEM_OMP>)
    target_compile_options(${target} INTERFACE $<$<COMPILE_LANGUAGE:CUDA>:-Xcompiler=-fopenmp>)
  else()
    target_compile_definitions(${target} INTERFACE
      $<$<COMPILE_LANGUAGE:CXX>:THRUST_DEVICE_SYSTEM=THRUST_DEVICE_SYSTEM_CPP>)
  endif()
  target_compile_options(${target} INTERFACE
    $<$<COMPILE_LANGUAGE:CUDA>:--extended-lambda --expt-relaxed-constexpr>)
endfunction()
