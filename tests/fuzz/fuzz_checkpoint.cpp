// Fuzz target: checkpoints (parse_checkpoint, io/checkpoint.hpp) of float
// or double maps, by the scalar size the input's header claims. A
// checkpoint that parses must hold a map whose objects' volumes and
// foreground counts share their grid and have records, and writing it
// again must give a checkpoint that parses to the same bytes (the reader
// keeps everything the writer writes). Each input is tried as it is and
// with its checksum made to fit, so that mutations reach the payload.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "emfusion/io/checkpoint.hpp"
#include "fuzz_check.hpp"

namespace fuzz_checkpoint {

template <class S>
void check_as(const std::string& text) {
  using namespace emfusion;
  const std::string name = "fuzz.emfckpt";
  std::optional<Checkpoint<S, Host>> parsed;
  if (!fuzz::returns([&] { parsed.emplace(parse_checkpoint<S, Host>(text, name)); }, name)) return;
  const Map<S, Host>& map = parsed->map;
  EMF_FUZZ_CHECK(map.frames >= 0);
  for (const auto& o : map.objects) {
    const Vec3i &d = o->volume().dims(), &f = o->foreground().dims();
    EMF_FUZZ_CHECK(d[0] == f[0] && d[1] == f[1] && d[2] == f[2]);
    EMF_FUZZ_CHECK(o->existence_count() + o->non_existence_count() > 0);
  }
  const std::string again = checkpoint_bytes(map, parsed->camera);
  std::optional<Checkpoint<S, Host>> reparsed;
  EMF_FUZZ_CHECK(fuzz::returns([&] { reparsed.emplace(parse_checkpoint<S, Host>(again, name)); }, name));
  EMF_FUZZ_CHECK(checkpoint_bytes(reparsed->map, reparsed->camera) == again);
  EMF_FUZZ_CHECK(reparsed->map.objects.size() == map.objects.size() && reparsed->map.lost.size() == map.lost.size());
}

inline void check_text(const std::string& text) {
  if (text.size() > 12 && text[12] == 8) check_as<double>(text);
  else check_as<float>(text);
}

inline void check(const std::uint8_t* data, std::size_t size) {
  const std::string text = emfusion::fuzz::text_of(data, size);
  check_text(text);
  // Almost every mutation breaks the checksum; the same input with the
  // header's payload size and the checksum made to fit reaches the payload's
  // parser.
  if (size < 28) return;
  std::string fixed = text.substr(0, 16);
  emfusion::detail::bytes::put_u64(fixed, size - 28);
  fixed.append(text, 24, size - 28);
  emfusion::detail::bytes::put_u32(fixed, emfusion::detail::checkpoint::crc32_of(data + 24, size - 28));
  check_text(fixed);
}

}  // namespace fuzz_checkpoint

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_checkpoint::check(data, size);
  return 0;
}
