// Fuzz target: config files ("key = value" per line) through parse_config,
// for SystemParams<float> and <double>, and the first line of the input as a
// --set override (apply_override). Parameters that parse must validate,
// print finite numbers, and read back unchanged from the "key = value" text
// of every parameter as printed (run.json records that text).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "emfusion/io/config.hpp"
#include "fuzz_check.hpp"

namespace fuzz_config {

template <class S>
void check_round_trip(const emfusion::SystemParams<S>& params) {
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { params.validate(); }, ""));
  const auto& table = emfusion::parameter_table<S>();
  std::string written;
  for (const auto& entry : table) written += std::string(entry.name) + " = " + entry.get(params) + "\n";
  emfusion::SystemParams<S> again;
  const std::string name = "fuzz/written.conf";
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { emfusion::parse_config(written, name, again); }, name));
  for (const auto& entry : table) EMF_FUZZ_CHECK(entry.get(again) == entry.get(params));
  EMF_FUZZ_CHECK(again.static_classes == params.static_classes);
}

template <class S>
void check(const std::string& text) {
  const std::string name = "fuzz/params.conf";
  emfusion::SystemParams<S> params;
  if (emfusion::fuzz::returns([&] { emfusion::parse_config(text, name, params); }, name)) check_round_trip(params);

  // The first line as "--set key=value": only std::invalid_argument, and a
  // value that is set prints as what reads back.
  const std::string assignment = text.substr(0, text.find('\n'));
  emfusion::SystemParams<S> overridden;
  bool threw_other = false;
  try {
    emfusion::apply_override(overridden, assignment);
  } catch (const std::invalid_argument&) {
    return;
  } catch (...) {
    threw_other = true;
  }
  EMF_FUZZ_CHECK(!threw_other);
  for (const auto& entry : emfusion::parameter_table<S>()) {
    emfusion::SystemParams<S> again;
    const std::string printed = entry.get(overridden);
    EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { entry.set(again, printed); }, ""));
    EMF_FUZZ_CHECK(entry.get(again) == printed);
  }
}

}  // namespace fuzz_config

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = emfusion::fuzz::text_of(data, size);
  fuzz_config::check<float>(text);
  fuzz_config::check<double>(text);
  return 0;
}
