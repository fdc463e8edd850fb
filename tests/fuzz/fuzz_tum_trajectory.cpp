// Fuzz target: TUM trajectory files (groundtruth.txt, object trajectories,
// camera.txt) through parse_tum_trajectory. A parsed trajectory must have
// finite, strictly increasing timestamps, finite translations and the
// rotation of each line's quaternion (checked against an independent
// reading of the fields); what format_tum_trajectory writes must read back
// as the same trajectory.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "emfusion/io/tum.hpp"
#include "fuzz_check.hpp"

namespace fuzz_tum_trajectory {

using emfusion::fuzz::close;

/// A field read as the parser's rules say (a leading '+' allowed).
inline double field_value(const std::string& field) {
  const char* first = field.data();
  const char* last = first + field.size();
  if (first != last && *first == '+') ++first;
  double value = 0;
  std::from_chars(first, last, value);
  return value;
}

/// The rotation of quaternion (x, y, z, w), normalised after scaling by the
/// largest component (no overflow or underflow in the norm).
inline emfusion::Mat3<double> rotation_of(double x, double y, double z, double w) {
  const double scale = std::max({std::fabs(x), std::fabs(y), std::fabs(z), std::fabs(w)});
  x /= scale, y /= scale, z /= scale, w /= scale;
  const double n = std::sqrt(x * x + y * y + z * z + w * w);
  x /= n, y /= n, z /= n, w /= n;
  return emfusion::Mat3<double>{{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                                 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                                 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
}

inline bool same_rotation(const emfusion::Mat3<double>& a, const emfusion::Mat3<double>& b, double tolerance) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (!(std::fabs(a(r, c) - b(r, c)) <= tolerance)) return false;
  return true;
}

inline void check(const std::string& text) {
  const std::string name = "fuzz/groundtruth.txt";
  std::vector<emfusion::TimedPose> poses;
  if (!emfusion::fuzz::returns([&] { poses = emfusion::parse_tum_trajectory(text, name); }, name)) return;

  const std::vector<emfusion::detail::tum::Line> lines = emfusion::detail::tum::data_lines(text);
  EMF_FUZZ_CHECK(poses.size() == lines.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const emfusion::TimedPose& p = poses[i];
    EMF_FUZZ_CHECK(std::isfinite(p.timestamp));
    EMF_FUZZ_CHECK(i == 0 || p.timestamp > poses[i - 1].timestamp);
    for (int k = 0; k < 3; ++k) EMF_FUZZ_CHECK(std::isfinite(p.pose.translation()[k]));
    const std::vector<std::string>& f = lines[i].fields;
    EMF_FUZZ_CHECK(f.size() == 8);
    EMF_FUZZ_CHECK(p.timestamp == field_value(f[0]));
    for (int k = 0; k < 3; ++k) EMF_FUZZ_CHECK(p.pose.translation()[k] == field_value(f[std::size_t(k) + 1]));
    const emfusion::Mat3<double> expected =
        rotation_of(field_value(f[4]), field_value(f[5]), field_value(f[6]), field_value(f[7]));
    EMF_FUZZ_CHECK(same_rotation(p.pose.rotation(), expected, 1e-9));
  }

  // Round trip through the writer's text: refusing (timestamps equal with 6
  // decimals) is documented; what it writes must read back.
  std::string written;
  if (!emfusion::fuzz::returns([&] { written = emfusion::format_tum_trajectory(poses, name); }, name)) return;
  std::vector<emfusion::TimedPose> again;
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { again = emfusion::parse_tum_trajectory(written, name); }, name));
  EMF_FUZZ_CHECK(again.size() == poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    EMF_FUZZ_CHECK(close(again[i].timestamp, poses[i].timestamp, 5.1e-7, 1e-15));
    for (int k = 0; k < 3; ++k)
      EMF_FUZZ_CHECK(close(again[i].pose.translation()[k], poses[i].pose.translation()[k], 5.1e-10, 1e-15));
    EMF_FUZZ_CHECK(same_rotation(again[i].pose.rotation(), poses[i].pose.rotation(), 1e-8));
  }
}

}  // namespace fuzz_tum_trajectory

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_tum_trajectory::check(emfusion::fuzz::text_of(data, size));
  return 0;
}
