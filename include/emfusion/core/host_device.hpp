// The project's host/device marker and the switch that says whether the CUDA
// backend exists in this translation unit.
//
// EMF_HD marks functions that run both on the CPU and in CUDA kernels. It is
// `__host__ __device__` only when nvcc compiles the unit, so the same headers
// build with a plain C++ compiler for the CPU backend.
#pragma once

#if defined(__CUDACC__)
#define EMF_HD __host__ __device__
#define EMFUSION_HAS_CUDA 1
#else
#define EMF_HD
#define EMFUSION_HAS_CUDA 0
#endif
