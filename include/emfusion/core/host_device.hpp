// The project's host/device marker and the switch that says whether the CUDA
// backend exists in this translation unit.
//
// EMF_HD marks functions that run both on the CPU and in CUDA kernels. It is
// `__host__ __device__` only when nvcc compiles the unit, so the same headers
// build with a plain C++ compiler for the CPU backend.
//
// EMF_NOINLINE_ON_CUDA keeps a small function that many call sites share out
// of line where nvcc compiles the unit: a kernel that inlines it everywhere
// can outgrow the instruction cache (the sparse ray cast did: most of its
// stalls were instruction fetches; docs/benchmarks.md). Plain C++ builds
// inline as they see fit.
//
// EMF_INLINE_ON_HOST makes the host compiler inline a small hot function
// where its size heuristics would call it: a sparse volume's sample (the
// corner, the gather of eight voxels, the interpolation) came out of line
// under g++ -O3 in the system's hottest loops. Device code is left to nvcc.
//
// EMF_AVX2_CLONE compiles a vectorised CPU loop twice, for x86-64's baseline
// (SSE2, what a portable build may assume) and for AVX2 (twice the lanes),
// and picks one when the program loads (g++'s target_clones): the AVX2
// copy on processors that have it. Nothing else changes: without FMA the
// lanes round as the baseline's do. Only in g++'s x86-64 host code.
#pragma once

#if defined(__CUDACC__)
#define EMF_HD __host__ __device__
#define EMFUSION_HAS_CUDA 1
#define EMF_NOINLINE_ON_CUDA __noinline__
#else
#define EMF_HD
#define EMFUSION_HAS_CUDA 0
#define EMF_NOINLINE_ON_CUDA
#endif

#if defined(__CUDA_ARCH__)
#define EMF_INLINE_ON_HOST
#else
#define EMF_INLINE_ON_HOST __attribute__((always_inline))
#endif

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__CUDACC__)
#define EMF_AVX2_CLONE __attribute__((target_clones("avx2", "default")))
#else
#define EMF_AVX2_CLONE
#endif
