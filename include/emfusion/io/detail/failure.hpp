// A callable that throws the io/ error of one reader for one file
// ("where: 'path': problem"), declared [[noreturn]] so that code after a
// failed check needs no dummy return values.
#pragma once

#include <string>

#include "emfusion/io/detail/files.hpp"

namespace emfusion::detail::io {

struct Failure {
  const char* where;
  const std::string& path;
  [[noreturn]] void operator()(const std::string& problem) const { fail(where, path, problem); }
};

}  // namespace emfusion::detail::io
