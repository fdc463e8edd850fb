// A simulated instance-segmentation detector (a stand-in for Mask R-CNN) on
// a DynamicScene: it runs every `period` frames and turns the exact visible
// instance labels into detections with the errors the EM-Fusion pipeline has
// to cope with: imprecise mask boundaries, missed objects, false positives,
// small objects dropped, instance ids that change from frame to frame.
//
// Every random choice is a hash of (seed, frame, object, purpose) (see
// noise.hpp), so a frame's detections do not depend on which frames were
// asked for before, and the decisions can be queried without rendering
// (misses(), has_false_positive()).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/sim/dynamic_scene.hpp"
#include "emfusion/sim/noise.hpp"

namespace emfusion::sim {

/// Lengths and areas in pixels are given for 640x480 images and scale with
/// the image (lengths with width / 640, areas with the pixel count / 640x480),
/// so a scene rendered small for a test sees the same detector.
struct SimulatedDetectorParams {
  int period = 30;                           ///< runs on frames 0, period, 2 period, ...
  double miss_probability = 0.1;             ///< per visible object and detector frame
  double false_positive_probability = 0.05;  ///< per detector frame: one spurious blob
  int min_area = 1600;                       ///< px: smaller masks are not reported (40 x 40)
  double min_offset = 1, max_offset = 4;     ///< px: masks are eroded or dilated by this much
  double jitter = 1.5;                       ///< px: amplitude of the smooth boundary jitter
  double jitter_cell = 12;                   ///< px: spatial scale of the jitter
  double min_score = 0.8, max_score = 1.0;   ///< scores of true detections
  double false_positive_min_score = 0.5, false_positive_max_score = 0.7;
  bool shuffle_labels = true;  ///< else object k gets label k + 1 and a false positive the next free one
  std::uint64_t seed = 1;

  /// The ground truth as a detector: every visible object large enough, exact
  /// masks, labels k + 1, no misses, no false positives.
  static SimulatedDetectorParams exact() {
    SimulatedDetectorParams p;
    p.miss_probability = p.false_positive_probability = 0;
    p.min_offset = p.max_offset = p.jitter = 0;
    p.shuffle_labels = false;
    return p;
  }

  void validate(const char* where) const {
    // Shortest form of a number for messages ("1.5", not "1.500000").
    auto str = [](double v) {
      std::ostringstream s;
      s << v;
      return s.str();
    };
    emfusion::detail::require(period >= 1, where, "period must be >= 1, got " + std::to_string(period));
    emfusion::detail::require(miss_probability >= 0 && miss_probability <= 1, where,
                              "miss_probability must be in [0, 1], got " + str(miss_probability));
    emfusion::detail::require(false_positive_probability >= 0 && false_positive_probability <= 1, where,
                              "false_positive_probability must be in [0, 1], got " + str(false_positive_probability));
    emfusion::detail::require(min_area >= 1, where, "min_area must be >= 1, got " + std::to_string(min_area));
    emfusion::detail::require(min_offset >= 0 && max_offset >= min_offset && max_offset <= 16, where,
                              "need 0 <= min_offset <= max_offset <= 16");
    emfusion::detail::require(jitter >= 0 && jitter <= 8 && jitter_cell > 0, where,
                              "need 0 <= jitter <= 8 and jitter_cell > 0");
    emfusion::detail::require(min_score >= 0 && max_score <= 1 && min_score <= max_score &&
                                  false_positive_min_score >= 0 && false_positive_max_score <= 1 &&
                                  false_positive_min_score <= false_positive_max_score,
                              where, "score ranges must lie in [0, 1] with min <= max");
  }
};

namespace detail {

// Purposes of the detector's random draws (the last hash counter).
enum DetectorStream : std::uint64_t {
  detect_miss = 11,
  detect_sign = 12,
  detect_offset = 13,
  detect_score = 14,
  detect_false_positive = 15,
  detect_shuffle = 16,
  detect_jitter = 17,
};

/// One mask being built: object `object`'s visible region eroded (offset < 0)
/// or dilated (offset > 0), or, for object < 0, an elliptic false positive.
struct MaskSlot {
  int object = -1;
  double offset = 0;
  int u0 = 0, u1 = -1, v0 = 0, v1 = -1;            // pixels the mask can reach
  double cx = 0, cy = 0, a = 1, b = 1, angle = 0;  // false-positive ellipse
  std::uint64_t key = 0;                           // jitter field of this mask
};

constexpr int max_mask_slots = Scene<float>::capacity + 1;

/// Random value in [-1, 1] at a node of the jitter grid.
EMF_HD inline double jitter_node(std::uint64_t seed, std::uint64_t key, long long x, long long y) {
  const std::uint64_t node = (std::uint64_t(y) << 32) ^ std::uint64_t(x);
  return 2 * uniform01(seed, key, node, detect_jitter) - 1;
}

/// Smooth noise in [-1, 1]: random values on a grid of `cell` pixels,
/// interpolated with a smoothstep, so a boundary wobbles instead of fraying.
/// `key` selects the field (one per mask and frame).
EMF_HD inline double jitter_field(std::uint64_t seed, std::uint64_t key, double cell, int u, int v) {
  const double x = u / cell, y = v / cell;
  const double fx = std::floor(x), fy = std::floor(y);
  const long long ix = (long long)fx, iy = (long long)fy;
  double tx = x - fx, ty = y - fy;
  tx = tx * tx * (3 - 2 * tx), ty = ty * ty * (3 - 2 * ty);
  const double n00 = jitter_node(seed, key, ix, iy), n10 = jitter_node(seed, key, ix + 1, iy);
  const double n01 = jitter_node(seed, key, ix, iy + 1), n11 = jitter_node(seed, key, ix + 1, iy + 1);
  const double top = n00 + (n10 - n00) * tx, bottom = n01 + (n11 - n01) * tx;
  return top + (bottom - top) * ty;
}

struct ComposeMasks {
  ImageView<const int> truth;  // 0 static or none, k + 1 object k
  ImageView<int> slot_image;   // out: slot index or -1
  MaskSlot slots[max_mask_slots];
  int slot_count = 0;
  int slot_of_object[Scene<float>::capacity];  // -1 where the object is not detected
  std::uint64_t seed = 0, frame = 0;
  double jitter = 0, cell = 1;

  EMF_HD double radius_at(const MaskSlot& s, int u, int v) const {
    return jitter > 0 ? s.offset + jitter * jitter_field(seed, s.key, cell, u, v) : s.offset;
  }

  EMF_HD bool inside(int s_index, int u, int v) const {
    const MaskSlot& s = slots[s_index];
    if (u < s.u0 || u > s.u1 || v < s.v0 || v > s.v1) return false;
    if (s.object < 0) {
      const double c = std::cos(s.angle), sn = std::sin(s.angle);
      const double dx = u - s.cx, dy = v - s.cy;
      const double x = (c * dx + sn * dy) / s.a, y = (-sn * dx + c * dy) / s.b;
      const double grow = 1 + radius_at(s, u, v) / (0.5 * (s.a + s.b));
      return x * x + y * y <= grow * grow;
    }
    const int label = s.object + 1;
    const double rho = radius_at(s, u, v);
    const bool own = truth(u, v) == label;
    const double r = std::fabs(rho);
    const int w = int(r);
    if (rho >= 0) {  // dilation: some mask pixel within rho
      if (own) return true;
      for (int dy = -w; dy <= w; ++dy)
        for (int dx = -w; dx <= w; ++dx)
          if (dx * dx + dy * dy <= r * r && truth.contains(u + dx, v + dy) && truth(u + dx, v + dy) == label)
            return true;
      return false;
    }
    // Erosion: every pixel within |rho| belongs to the mask. Pixels outside
    // the image do not erode: the object may continue there.
    if (!own) return false;
    for (int dy = -w; dy <= w; ++dy)
      for (int dx = -w; dx <= w; ++dx)
        if (dx * dx + dy * dy <= r * r && truth.contains(u + dx, v + dy) && truth(u + dx, v + dy) != label)
          return false;
    return true;
  }

  EMF_HD void operator()(int i) const {
    const int u = i % truth.width, v = i / truth.width;
    int found = -1;
    // A false positive (always the last slot) lies on top; then an object's
    // own pixels go to its mask; dilated borders go to the first mask that
    // reaches them.
    if (slot_count > 0 && slots[slot_count - 1].object < 0 && inside(slot_count - 1, u, v)) found = slot_count - 1;
    const int g = truth[i];
    if (found < 0 && g > 0 && slot_of_object[g - 1] >= 0 && inside(slot_of_object[g - 1], u, v))
      found = slot_of_object[g - 1];
    for (int s = 0; s < slot_count && found < 0; ++s)
      if (slots[s].object >= 0 && slots[s].object != g - 1 && inside(s, u, v)) found = s;
    slot_image[i] = found;
  }
};

/// Area and bounding box of the pixels with one value.
struct Extent {
  int area = 0, u0 = 1 << 30, u1 = -1, v0 = 1 << 30, v1 = -1;
};

/// Extents of the values 0..count-1 within one row each: one parallel pass
/// for all values (parallel regions are costly on the host, see DESIGN.md).
struct RowExtents {
  ImageView<const int> image;
  int count;
  Extent* rows;  // height x count
  EMF_HD void operator()(int v) const {
    Extent* out = rows + v * count;
    for (int u = 0; u < image.width; ++u) {
      const int value = image(u, v);
      if (value < 0 || value >= count) continue;
      Extent& e = out[value];
      if (e.area++ == 0) e.u0 = u, e.v0 = v, e.v1 = v;
      e.u1 = u;
    }
  }
};

/// Area and bounding box of each value 0..count-1 of an image.
inline std::vector<Extent> extents_of(const ImageView<const int>& image, int count) {
  std::vector<Extent> result(static_cast<std::size_t>(count));
  if (count <= 0) return result;
  std::vector<Extent> rows(std::size_t(count) * std::size_t(image.height));
  for_each_index(Host{}, image.height, RowExtents{image, count, rows.data()});
  for (int v = 0; v < image.height; ++v)
    for (int k = 0; k < count; ++k) {
      const Extent& r = rows[std::size_t(v * count + k)];
      Extent& e = result[std::size_t(k)];
      if (r.area == 0) continue;
      e.area += r.area;
      e.u0 = std::min(e.u0, r.u0), e.u1 = std::max(e.u1, r.u1);
      e.v0 = std::min(e.v0, r.v0), e.v1 = std::max(e.v1, r.v1);
    }
  return result;
}

struct WriteLabels {
  ImageView<const int> slot_image;
  ImageView<std::uint16_t> labels;
  std::uint16_t label_of_slot[max_mask_slots];
  EMF_HD void operator()(int i) const {
    const int s = slot_image[i];
    labels[i] = s < 0 ? std::uint16_t(0) : label_of_slot[s];
  }
};

}  // namespace detail

/// A Segmenter over a DynamicScene (it keeps its own copy of the scene).
template <class S = float>
class SimulatedDetector {
 public:
  explicit SimulatedDetector(DynamicScene<S> scene, const SimulatedDetectorParams& params = {})
      : scene_(std::move(scene)), params_(params) {
    params_.validate("SimulatedDetector");
    emfusion::detail::require(scene_.object_count() <= Scene<S>::capacity, "SimulatedDetector", "too many objects");
  }

  /// Detections for a frame the detector runs on (frame % period == 0), else
  /// nothing. `timestamp` is copied into the result.
  std::optional<Detections> detect(int frame_index, double timestamp) {
    check_frame(frame_index, "SimulatedDetector::detect");
    if (!runs_on(frame_index)) return std::nullopt;
    const int w = scene_.camera().width, h = scene_.camera().height;
    const double scale = w / 640.0;
    const double min_area = params_.min_area * (double(w) * h) / (640.0 * 480.0);

    Image<S, Host> depth;
    Image<int, Host> truth;
    scene_.render(frame_index, depth, &truth, false);
    const ImageView<const int> truth_view = truth.view();

    detail::ComposeMasks compose{};
    compose.truth = truth_view;
    compose.seed = params_.seed;
    compose.frame = std::uint64_t(frame_index);
    compose.jitter = params_.jitter * scale;
    compose.cell = std::fmax(2.0, params_.jitter_cell * scale);
    std::vector<std::string> classes;
    std::vector<double> scores;
    const int reach = int(std::ceil((params_.max_offset + params_.jitter) * scale)) + 1;
    for (int k = 0; k < Scene<S>::capacity; ++k) compose.slot_of_object[k] = -1;
    // Labels are k + 1: value 0 (static) gets an extent too, unused.
    const std::vector<detail::Extent> objects = detail::extents_of(truth_view, scene_.object_count() + 1);
    for (int k = 0; k < scene_.object_count(); ++k) {
      const detail::Extent& e = objects[std::size_t(k) + 1];
      if (e.area < min_area || misses(frame_index, k)) continue;
      detail::MaskSlot& s = compose.slots[compose.slot_count];
      s.object = k;
      s.offset = scale * draw(frame_index, k, detail::detect_offset, params_.min_offset, params_.max_offset);
      if (draw(frame_index, k, detail::detect_sign, 0, 1) < 0.5) s.offset = -s.offset;
      s.u0 = e.u0 - reach, s.u1 = e.u1 + reach, s.v0 = e.v0 - reach, s.v1 = e.v1 + reach;
      s.key = hash64(params_.seed, std::uint64_t(frame_index), std::uint64_t(k) + 1, detail::detect_jitter);
      compose.slot_of_object[k] = compose.slot_count++;
      classes.push_back(scene_.object_class(k));
      scores.push_back(draw(frame_index, k, detail::detect_score, params_.min_score, params_.max_score));
    }
    if (has_false_positive(frame_index)) {
      detail::MaskSlot& s = compose.slots[compose.slot_count++];
      HashRng rng(params_.seed, hash64(params_.seed, std::uint64_t(frame_index), 0, detail::detect_false_positive));
      // Semi-axes of at least 28 px keep the blob above 1600 px (scaled)
      // after the jitter; the margin keeps it inside the image.
      s.a = scale * rng.uniform(28, 45), s.b = scale * rng.uniform(28, 45), s.angle = rng.uniform(0, 3.14159265);
      const double margin = std::fmax(s.a, s.b) + (params_.jitter + 2) * scale;
      s.cx = centre_in(rng.uniform(), margin, w), s.cy = centre_in(rng.uniform(), margin, h);
      s.u0 = int(s.cx - margin) - 1, s.u1 = int(s.cx + margin) + 1;
      s.v0 = int(s.cy - margin) - 1, s.v1 = int(s.cy + margin) + 1;
      s.key = hash64(params_.seed, std::uint64_t(frame_index), 0, detail::detect_jitter);
      static const char* const plausible[] = {"person", "chair",        "tv",       "bottle",  "cup",
                                              "book",   "potted_plant", "keyboard", "handbag", "bowl"};
      classes.emplace_back(plausible[rng.integer(0, 9)]);
      scores.push_back(rng.uniform(params_.false_positive_min_score, params_.false_positive_max_score));
    }

    Image<int, Host> slot_image(w, h, -1);
    compose.slot_image = slot_image.view();
    for_each_index(Host{}, w * h, compose);

    // Keep the masks that are still large enough; give them their labels.
    std::vector<int> kept;
    const ImageView<const int> slot_view = std::as_const(slot_image).view();
    const std::vector<detail::Extent> masks = detail::extents_of(slot_view, compose.slot_count);
    for (int s = 0; s < compose.slot_count; ++s)
      if (masks[std::size_t(s)].area >= min_area) kept.push_back(s);
    std::vector<int> labels(kept.size());
    for (std::size_t i = 0; i < kept.size(); ++i) {
      const detail::MaskSlot& s = compose.slots[kept[i]];
      labels[i] = s.object >= 0 ? s.object + 1 : scene_.object_count() + 1;
    }
    if (params_.shuffle_labels) {
      HashRng rng(params_.seed, hash64(params_.seed, std::uint64_t(frame_index), 0, detail::detect_shuffle));
      for (std::size_t i = 0; i < labels.size(); ++i) labels[i] = int(i) + 1;
      for (std::size_t i = labels.size(); i > 1; --i)
        std::swap(labels[i - 1], labels[std::size_t(rng.integer(0, int(i) - 1))]);
    }

    detail::WriteLabels write{slot_view, {}, {}};
    for (int s = 0; s < detail::max_mask_slots; ++s) write.label_of_slot[s] = 0;
    Detections out;
    out.timestamp = timestamp;
    for (std::size_t i = 0; i < kept.size(); ++i) {
      write.label_of_slot[kept[i]] = std::uint16_t(labels[i]);
      out.instances.push_back(Instance{labels[i], classes[std::size_t(kept[i])], scores[std::size_t(kept[i])]});
    }
    std::sort(out.instances.begin(), out.instances.end(),
              [](const Instance& a, const Instance& b) { return a.label < b.label; });
    out.labels = Image<std::uint16_t, Host>(w, h, 0);
    write.labels = out.labels.view();
    for_each_index(Host{}, w * h, write);
    return out;
  }

  bool runs_on(int frame) const { return frame % params_.period == 0; }
  /// Whether the detector misses object k on a frame (if it runs and the
  /// object is visible).
  bool misses(int frame, int k) const { return draw(frame, k, detail::detect_miss, 0, 1) < params_.miss_probability; }
  /// Whether a frame's detections include a false positive (if it runs).
  bool has_false_positive(int frame) const {
    return uniform01(params_.seed, std::uint64_t(frame), 0, detail::detect_false_positive) <
           params_.false_positive_probability;
  }

  const DynamicScene<S>& scene() const { return scene_; }
  const SimulatedDetectorParams& params() const { return params_; }

 private:
  double draw(int frame, int k, std::uint64_t purpose, double lo, double hi) const {
    return lo + (hi - lo) * uniform01(params_.seed, std::uint64_t(frame), std::uint64_t(k) + 1, purpose);
  }
  /// A coordinate in [margin, size - 1 - margin], or the middle if that is empty.
  static double centre_in(double t, double margin, int size) {
    const double lo = margin, hi = size - 1 - margin;
    return lo <= hi ? lo + t * (hi - lo) : 0.5 * (size - 1);
  }
  void check_frame(int frame, const char* where) const {
    emfusion::detail::require(
        frame >= 0 && frame < scene_.frame_count(), where,
        "frame " + std::to_string(frame) + " is not in 0.." + std::to_string(scene_.frame_count() - 1));
  }

  DynamicScene<S> scene_;
  SimulatedDetectorParams params_;
};

static_assert(Segmenter<SimulatedDetector<float>>);

}  // namespace emfusion::sim
