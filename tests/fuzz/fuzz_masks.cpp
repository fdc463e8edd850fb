// Fuzz target: masks.txt of a mask directory ("timestamp label_png
// [id:class:score ...]") through MaskDirectory::parse, which checks the text
// as MaskDirectory::open does without looking for the label images. A parsed
// directory must have finite, strictly increasing timestamps, ids in
// [1, 65535] without repeats on a line, class names that masks.txt can hold
// and scores in [0, 1]; nearest() must find entries within its window; and
// the entries written back as masks.txt text must read back unchanged.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "emfusion/io/masks.hpp"
#include "fuzz_check.hpp"

namespace fuzz_masks {

const std::string dir = "fuzzmasks";

inline void check(const std::string& text) {
  namespace masks = emfusion::detail::masks;
  namespace tum = emfusion::detail::tum;
  const std::string list = tum::join(dir, "masks.txt");
  std::optional<emfusion::MaskDirectory> parsed;
  if (!emfusion::fuzz::returns([&] { parsed = emfusion::MaskDirectory::parse(text, dir); }, list)) return;
  const emfusion::MaskDirectory& m = *parsed;
  EMF_FUZZ_CHECK(m.list_path() == list && m.dir() == dir);
  EMF_FUZZ_CHECK(m.size() == tum::data_lines(text).size());

  std::string written;
  const std::string prefix = dir + "/";
  for (std::size_t i = 0; i < m.size(); ++i) {
    const double t = m.timestamp(i);
    EMF_FUZZ_CHECK(std::isfinite(t));
    EMF_FUZZ_CHECK(i == 0 || t > m.timestamp(i - 1));
    const std::string& path = m.label_path(i);
    EMF_FUZZ_CHECK(path.size() > prefix.size() && path.compare(0, prefix.size(), prefix) == 0);
    const std::string label_name = path.substr(prefix.size());
    EMF_FUZZ_CHECK(masks::file_name_problem(label_name).empty());
    written += tum::format(t) + " " + label_name;
    const std::vector<emfusion::Instance>& instances = m.instances(i);
    for (std::size_t k = 0; k < instances.size(); ++k) {
      const emfusion::Instance& instance = instances[k];
      EMF_FUZZ_CHECK(instance.label >= 1 && instance.label <= masks::max_id);
      for (std::size_t j = 0; j < k; ++j) EMF_FUZZ_CHECK(instances[j].label != instance.label);
      EMF_FUZZ_CHECK(masks::class_name_problem(instance.class_name).empty());
      EMF_FUZZ_CHECK(instance.score >= 0.0 && instance.score <= 1.0);
      written += ' ';
      written += std::to_string(instance.label);
      written += ':';
      written += instance.class_name;
      written += ':';
      written += tum::format(instance.score);
    }
    written += "\n";

    // The entry is its own nearest; a time well outside every window finds nothing.
    const std::optional<std::size_t> self = m.nearest(t);
    EMF_FUZZ_CHECK(self && *self == i);
    const std::optional<std::size_t> near = m.nearest(t + 0.015);
    EMF_FUZZ_CHECK(!near || std::fabs(m.timestamp(*near) - (t + 0.015)) <= 0.0201 + 1e-12 * std::fabs(t));
  }
  EMF_FUZZ_CHECK(!m.nearest(std::nan("")));
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { (void)m.timestamp(m.size()); }, "") == false);

  std::optional<emfusion::MaskDirectory> again;
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { again = emfusion::MaskDirectory::parse(written, dir); }, list));
  EMF_FUZZ_CHECK(again->size() == m.size());
  for (std::size_t i = 0; i < m.size(); ++i) {
    EMF_FUZZ_CHECK(again->timestamp(i) == m.timestamp(i) && again->label_path(i) == m.label_path(i));
    const std::vector<emfusion::Instance>& a = again->instances(i);
    const std::vector<emfusion::Instance>& b = m.instances(i);
    EMF_FUZZ_CHECK(a.size() == b.size());
    for (std::size_t k = 0; k < a.size(); ++k)
      EMF_FUZZ_CHECK(a[k].label == b[k].label && a[k].class_name == b[k].class_name && a[k].score == b[k].score);
  }
}

}  // namespace fuzz_masks

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_masks::check(emfusion::fuzz::text_of(data, size));
  return 0;
}
