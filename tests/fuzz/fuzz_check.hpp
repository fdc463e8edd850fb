// What every fuzz target of tests/fuzz/ checks: a parser either returns (and
// then its result must satisfy the target's invariants, EMF_FUZZ_CHECK) or
// throws one of io/'s documented exception types (std::invalid_argument,
// std::out_of_range, std::runtime_error) with a message naming the input.
// Anything else (another exception type, a broken invariant) stops the run
// with __builtin_trap(), which libFuzzer and the replay driver report as a
// crash.
#pragma once

#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <new>
#include <stdexcept>
#include <string>

namespace emfusion::fuzz {

[[noreturn]] inline void violated(const char* what, const char* file, int line) {
  std::fprintf(stderr, "%s:%d: fuzz invariant violated: %s\n", file, line, what);
  std::fflush(stderr);
  __builtin_trap();
}

#define EMF_FUZZ_CHECK(condition) \
  ((condition) ? void(0) : ::emfusion::fuzz::violated(#condition, __FILE__, __LINE__))

/// The fuzz input as text (it may hold any byte, NUL included).
inline std::string text_of(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

[[noreturn]] inline void bad_exception(const char* kind, const char* what) {
  std::fprintf(stderr, "fuzz: undocumented exception %s: %s\n", kind, what);
  std::fflush(stderr);
  __builtin_trap();
}

/// Runs `parse()`. Returns true when it returns, false when it throws a
/// documented exception whose message holds `source` (when not empty) and
/// not `never` (when given: a message that only a reader's internal
/// inconsistency produces); traps on anything else.
///
/// With EMFUSION_FUZZ_VERBOSE set in the environment it prints each
/// outcome (to see what the seeds of a corpus reach).
template <class F>
bool returns(F&& parse, const std::string& source, const char* never = nullptr) {
  static const bool verbose = std::getenv("EMFUSION_FUZZ_VERBOSE") != nullptr;
  const auto check_message = [&](const char* kind, const char* what) {
    const std::string message = what;
    if (verbose) std::fprintf(stderr, "  throws %s: %s\n", kind, what);
    if (message.empty() || (!source.empty() && message.find(source) == std::string::npos)) {
      std::fprintf(stderr, "fuzz: %s message does not name '%s': %s\n", kind, source.c_str(), what);
      std::fflush(stderr);
      __builtin_trap();
    }
    if (never && message.find(never) != std::string::npos) {
      std::fprintf(stderr, "fuzz: %s message shows an internal inconsistency ('%s'): %s\n", kind, never, what);
      std::fflush(stderr);
      __builtin_trap();
    }
  };
  try {
    parse();
    if (verbose) std::fprintf(stderr, "  returns\n");
    return true;
  } catch (const std::invalid_argument& e) {
    check_message("std::invalid_argument", e.what());
  } catch (const std::out_of_range& e) {
    check_message("std::out_of_range", e.what());
  } catch (const std::bad_alloc& e) {
    bad_exception("std::bad_alloc (an allocation driven by the input?)", e.what());
  } catch (const std::runtime_error& e) {
    check_message("std::runtime_error", e.what());
  } catch (const std::exception& e) {
    bad_exception("std::exception", e.what());
  } catch (...) {
    bad_exception("of unknown type", "");
  }
  return false;
}

/// A per-process file name for targets whose reader needs a file: in
/// /dev/shm when there is one (memory: on a disk, writing the input each run
/// cost the .klg target 40 times its runs), else in the temporary directory.
inline std::string scratch_file(const std::string& stem) {
  std::error_code ec;
  const std::filesystem::path shm = "/dev/shm";
  const std::filesystem::path dir =
      std::filesystem::is_directory(shm, ec) && ::access(shm.c_str(), W_OK) == 0 ? shm
                                                                                  : std::filesystem::temp_directory_path();
  return (dir / ("emfusion-fuzz-" + std::to_string(::getpid()) + "-" + stem)).string();
}

/// |a - b| within `absolute` plus `relative` times the larger magnitude.
inline bool close(double a, double b, double absolute, double relative = 0) {
  return std::fabs(a - b) <= absolute + relative * std::fmax(std::fabs(a), std::fabs(b));
}

}  // namespace emfusion::fuzz
