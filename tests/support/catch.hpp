// Includes Catch2 whichever major version is installed: v3 on the GPU machine,
// v2 (Debian 12) on the CPU machines. Tests use only what both provide, plus
// the two spellings below that differ between them:
//   emfusion::test::Approx(x) approximate comparison
//   EMF_CONTAINS("text")      substring matcher for CHECK_THROWS_WITH
#pragma once

#if __has_include(<catch2/catch_all.hpp>)
#include <catch2/catch_all.hpp>
#define EMF_CONTAINS(text) Catch::Matchers::ContainsSubstring(text)
namespace emfusion::test {
using Approx = Catch::Approx;
}
#else
#include <catch2/catch.hpp>
#define EMF_CONTAINS(text) Catch::Matchers::Contains(text)
namespace emfusion::test {
using Approx = Catch::Detail::Approx;
}
#endif
