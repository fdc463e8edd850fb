# Decides whether the CUDA backend is built (EMFUSION_CUDA = AUTO | ON | OFF)
# and, if so, enables the CUDA language with the project's defaults.
include(CheckLanguage)
set(EMFUSION_WITH_CUDA OFF)
if(NOT EMFUSION_CUDA STREQUAL "OFF")
  check_language(CUDA)
  if(CMAKE_CUDA_COMPILER)
    if(NOT DEFINED CMAKE_CUDA_ARCHITECTURES)
      # Build for the GPU in this machine when there is one; otherwise for
      # Hopper (the project's GPU machines), so that CI can compile without one.
      execute_process(COMMAND nvidia-smi -L RESULT_VARIABLE _emf_smi OUTPUT_QUIET ERROR_QUIET)
      if(_emf_smi EQUAL 0)
        set(CMAKE_CUDA_ARCHITECTURES native)
      else()
        set(CMAKE_CUDA_ARCHITECTURES 90)
      endif()
    endif()
    # CMake < 3.25.2 (Debian 12 has 3.25.1) does not know nvcc's C++20 flag.
    if(CMAKE_VERSION VERSION_LESS 3.25.2)
      set(CMAKE_CUDA20_STANDARD_COMPILE_OPTION "-std=c++20")
      set(CMAKE_CUDA20_EXTENSION_COMPILE_OPTION "-std=c++20")
    endif()
    enable_language(CUDA)
    set(CMAKE_CUDA_STANDARD 20)
    set(CMAKE_CUDA_STANDARD_REQUIRED ON)
    set(CMAKE_CUDA_EXTENSIONS OFF)
    find_package(CUDAToolkit REQUIRED)
    # The batched solves loop on the device through a CUDA graph's
    # conditional while node (core/grouped_loop.hpp), new in CUDA 12.4.
    if(CUDAToolkit_VERSION VERSION_LESS 12.4)
      message(FATAL_ERROR "emfusion's CUDA backend needs CUDA 12.4 or newer (conditional graph nodes); "
                          "found CUDA ${CUDAToolkit_VERSION} at ${CUDAToolkit_BIN_DIR}. "
                          "Install a newer toolkit, or build without CUDA (-DEMFUSION_CUDA=OFF).")
    endif()
    set(EMFUSION_WITH_CUDA ON)
  elseif(EMFUSION_CUDA STREQUAL "ON")
    message(FATAL_ERROR "EMFUSION_CUDA=ON but no CUDA compiler was found: "
                        "install the CUDA toolkit or set CUDACXX to nvcc")
  endif()
endif()
