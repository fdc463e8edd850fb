// Command-line helpers shared by the demo and the benchmarks: strict number
// parsing with messages that name the flag and the bad value.
#pragma once

#include <cmath>
#include <cstdlib>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

namespace emfusion::examples {

/// The value of `flag` as an integer in [min, max]; throws std::invalid_argument
/// naming the flag otherwise.
inline int parse_int(const std::string& flag, const std::string& value, long min, long max) {
  char* end = nullptr;
  const long v = std::strtol(value.c_str(), &end, 10);
  if (value.empty() || *end != '\0' || v < min || v > max)
    throw std::invalid_argument(flag + " expects an integer from " + std::to_string(min) + " to " +
                                std::to_string(max) + ", got '" + value + "'");
  return int(v);
}

/// The value of `flag` as an integer in [1, max].
inline int parse_positive_int(const std::string& flag, const std::string& value, long max = 100000) {
  return parse_int(flag, value, 1, max);
}

/// The value of `flag` as a finite number (any sign); throws naming the flag.
inline double parse_double(const std::string& flag, const std::string& value) {
  char* end = nullptr;
  const double v = std::strtod(value.c_str(), &end);
  if (value.empty() || *end != '\0' || !std::isfinite(v))
    throw std::invalid_argument(flag + " expects a number, got '" + value + "'");
  return v;
}

/// The value of `flag` as a finite positive number; throws naming the flag.
inline double parse_positive_double(const std::string& flag, const std::string& value) {
  char* end = nullptr;
  const double v = std::strtod(value.c_str(), &end);
  if (value.empty() || *end != '\0' || !(v > 0) || !std::isfinite(v))
    throw std::invalid_argument(flag + " expects a positive number, got '" + value + "'");
  return v;
}

/// Calls f(flag, value) for every "--flag value" pair of the command line;
/// throws std::invalid_argument for a last argument without a value.
template <class F>
void for_each_option(int argc, char** argv, F&& f) {
  for (int i = 1; i < argc; i += 2) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) throw std::invalid_argument("option '" + flag + "' needs a value (or is unknown)");
    f(flag, std::string(argv[i + 1]));
  }
}

/// Splits a command line into its positional arguments (returned, in order)
/// and its options: f(flag, value) for every "--flag value", and f(flag, "")
/// for every flag listed in `switches` (options without a value). Throws
/// std::invalid_argument for a last option that needs a value and has none.
template <class F>
std::vector<std::string> parse_command_line(int argc, char** argv, std::initializer_list<std::string> switches,
                                            F&& f) {
  std::vector<std::string> positional;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("--", 0) != 0) {
      positional.push_back(a);
      continue;
    }
    bool is_switch = false;
    for (const std::string& s : switches) is_switch = is_switch || a == s;
    if (is_switch) {
      f(a, std::string());
      continue;
    }
    if (i + 1 >= argc) throw std::invalid_argument("missing value after '" + a + "'");
    f(a, std::string(argv[++i]));
  }
  return positional;
}

}  // namespace emfusion::examples
