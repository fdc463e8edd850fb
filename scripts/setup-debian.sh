#!/usr/bin/env bash
# Makes sure what a step of emfusion's build needs is there, and installs
# only what is missing:
#   bash scripts/setup-debian.sh [run|test|cuda]
#     run   build the app and the examples on the CPU (scripts/run.sh)
#     test  run: plus OpenEXR and OpenCV (optional elsewhere), Catch2, and clang with
#           libFuzzer and LLVM's OpenMP for the fuzz build (scripts/test.sh;
#           the default)
#     cuda  run, built with the CUDA toolkit's nvcc and its thrust
#           (scripts/run.sh --backend cuda)
# Each need is checked by what it is (a command on PATH, a header the
# compiler finds, a library file), not by a package name, so tools that came
# another way (a cmake from pip or a tarball, Eigen in /usr/local, thrust
# with the CUDA toolkit) count. What is missing is installed with apt-get
# (one `apt-get update`, then only the missing packages; sudo when not root)
# on Debian and derivatives; without apt-get the script names exactly what
# is missing and which Debian package would provide it, and fails.
set -euo pipefail

purpose="${1:-test}"
case "$purpose" in
  run | test | cuda) ;;
  *) echo "[setup-debian] unknown step '$purpose' (run, test or cuda)" >&2; exit 2 ;;
esac

log() { echo "[setup-debian] $*"; }

cuda_include=""
for dir in "${CUDA_HOME:-}" /usr/local/cuda; do
  [[ -n "$dir" && -d "$dir/include" ]] && { cuda_include="$dir/include"; break; }
done

# A C++ header the compiler finds (with Eigen's and the CUDA toolkit's include folders).
have_header() {
  local flags=(-I/usr/include/eigen3 -I/usr/local/include/eigen3 -I/usr/include/opencv4 -I/usr/local/include/opencv4)
  [[ -n "$cuda_include" ]] && flags+=("-I$cuda_include/cccl" "-I$cuda_include")
  command -v g++ >/dev/null 2>&1 || return 1
  # <cstdio> first: jpeglib.h uses FILE without including it.
  printf '#include <cstdio>\n#include <%s>\n' "$1" | g++ -std=c++20 -x c++ -E "${flags[@]}" - -o /dev/null >/dev/null 2>&1
}
have_command() { command -v "$1" >/dev/null 2>&1; }
# CMake 3.24 or newer (CMakePresets.json version 5).
have_cmake() {
  have_command cmake || return 1
  local v
  v="$(cmake --version | head -n 1 | sed 's/[^0-9]*\([0-9]*\)\.\([0-9]*\).*/\1 \2/')"
  read -r major minor <<<"$v"
  ((major > 3 || (major == 3 && minor >= 24)))
}
have_fuzzer_runtime() { compgen -G '/usr/lib/llvm-*/lib/clang/*/lib/linux/libclang_rt.fuzzer-x86_64.a' >/dev/null; }

# need <description> <Debian package> <check command...>
missing_packages=()
missing_text=()
need() {
  local what=$1 package=$2
  shift 2
  if ! "$@"; then
    missing_packages+=("$package")
    missing_text+=("$what (Debian package $package)")
  fi
}

need "a C++20 compiler (g++)" build-essential have_command g++
need "CMake 3.24 or newer" cmake have_cmake
need "Eigen 3.4 headers" libeigen3-dev have_header Eigen/Core
need "fmt headers" libfmt-dev have_header fmt/core.h
need "nlohmann-json headers" nlohmann-json3-dev have_header nlohmann/json.hpp
need "CLI11 headers" libcli11-dev have_header CLI/CLI.hpp
need "zlib headers" zlib1g-dev have_header zlib.h
need "libpng headers" libpng-dev have_header png.h
need "libjpeg headers" libjpeg-dev have_header jpeglib.h
# OpenEXR is optional for building (without it, reading .exr depth fails
# with an error saying so); the tests want it, to test that reader.
if [[ "$purpose" == test ]]; then
  need "OpenEXR headers" libopenexr-dev have_header OpenEXR/ImfInputFile.h
elif ! have_header OpenEXR/ImfInputFile.h; then
  log "note: no OpenEXR headers (Debian libopenexr-dev): the build will not read .exr depth (Co-Fusion folders)"
fi
# OpenCV is optional too (without it, interop/opencv.hpp, its tests and the
# opencv_sequence example are not built); the tests want it, to test them.
if [[ "$purpose" == test ]]; then
  need "OpenCV headers (core, imgcodecs)" libopencv-dev have_header opencv2/imgcodecs.hpp
elif [[ "$purpose" == run ]] && ! have_header opencv2/imgcodecs.hpp; then
  log "note: no OpenCV headers (Debian libopencv-dev): interop/opencv.hpp and the opencv_sequence example are left out"
fi
if [[ "$purpose" == cuda ]]; then
  # thrust comes with the toolkit; nvcc itself is not a Debian package here.
  if ! have_command nvcc && [[ ! -x "${cuda_include%/include}/bin/nvcc" ]]; then
    log "nvcc not found on PATH, in \$CUDA_HOME/bin or /usr/local/cuda/bin: install the CUDA toolkit (12.4 or newer)" >&2
    exit 1
  fi
else
  need "thrust headers" libthrust-dev have_header thrust/version.h
fi
if [[ "$purpose" == test ]]; then
  need "Catch2 headers (v2 or v3)" catch2 bash -c 'printf "#include <catch2/catch.hpp>\n" | g++ -x c++ -E - -o /dev/null 2>/dev/null ||
                                                  printf "#include <catch2/catch_all.hpp>\n" | g++ -std=c++17 -x c++ -E - -o /dev/null 2>/dev/null'
  need "Python 3 (app tests read run.json with it)" python3 have_command python3
  need "numpy for Debian's python3 (the generalisation benchmark's selftest)" python3-numpy \
    bash -c '/usr/bin/python3 -c "import numpy" 2>/dev/null || python3 -c "import numpy" 2>/dev/null'
  need "Chromium (the report test)" chromium have_command chromium
  need "clang (the fuzz build)" clang have_command clang
  need "LLVM's OpenMP (the fuzz build)" libomp-dev bash -c 'compgen -G "/usr/lib/llvm-*/include/omp.h" >/dev/null || compgen -G "/usr/lib/llvm-*/lib/clang/*/include/omp.h" >/dev/null'
  need "libFuzzer's runtime (the fuzz build)" libclang-rt-14-dev have_fuzzer_runtime
fi

if [[ ${#missing_packages[@]} -eq 0 ]]; then
  log "everything the '$purpose' step needs is there; nothing to install."
  exit 0
fi

log "missing for the '$purpose' step:"
for text in "${missing_text[@]}"; do log "  - $text"; done
if ! command -v apt-get >/dev/null 2>&1; then
  log "apt-get not found: install the above by hand and run this again." >&2
  exit 1
fi
as_root=()
if [[ "$(id -u)" -ne 0 ]]; then
  if command -v sudo >/dev/null 2>&1; then
    as_root=(sudo)
  else
    log "not root and sudo is not available; as root, run: apt-get install ${missing_packages[*]}" >&2
    exit 1
  fi
fi
# One package may provide several needs (build-essential).
mapfile -t packages < <(printf '%s\n' "${missing_packages[@]}" | sort -u)
log "running: ${as_root[*]:+${as_root[*]} }apt-get update"
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update
log "running: ${as_root[*]:+${as_root[*]} }apt-get install -y --no-install-recommends ${packages[*]}"
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${packages[@]}"
log "done."
