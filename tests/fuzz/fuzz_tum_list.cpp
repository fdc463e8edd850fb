// Fuzz target: the "timestamp path" lists of a TUM sequence (rgb.txt,
// depth.txt) through parse_tum_list, as TumSequence::open reads them. A
// parsed list must have one entry per data line, finite and strictly
// increasing timestamps, increasing line numbers and paths without the
// separators that split fields.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "emfusion/io/tum.hpp"
#include "fuzz_check.hpp"

namespace fuzz_tum_list {

inline void check(const std::string& text) {
  const std::string name = "fuzz/depth.txt";
  std::vector<emfusion::TumListEntry> entries;
  if (!emfusion::fuzz::returns([&] { entries = emfusion::parse_tum_list(text, name); }, name)) return;
  EMF_FUZZ_CHECK(entries.size() == emfusion::detail::tum::data_lines(text).size());
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const emfusion::TumListEntry& e = entries[i];
    EMF_FUZZ_CHECK(std::isfinite(e.timestamp));
    EMF_FUZZ_CHECK(e.line >= 1);
    EMF_FUZZ_CHECK(i == 0 || (e.timestamp > entries[i - 1].timestamp && e.line > entries[i - 1].line));
    EMF_FUZZ_CHECK(!e.path.empty());
    EMF_FUZZ_CHECK(e.path.find_first_of(" \t,\r\n#") == std::string::npos);
  }
}

}  // namespace fuzz_tum_list

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_tum_list::check(emfusion::fuzz::text_of(data, size));
  return 0;
}
