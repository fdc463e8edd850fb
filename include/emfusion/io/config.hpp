// SystemParams by name: config files ("key = value" per line, '#' comments)
// and command-line overrides ("key=value") set parameters by the names
// listed in docs/parameters.md; run.json records every value used.
// parse_config takes a config file's text in memory (as tests/fuzz/ does).
#pragma once

#include <charconv>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/tum.hpp"
#include "emfusion/slam/params.hpp"

namespace emfusion {

/// One named parameter: how to set it from text and how to print it.
template <class S>
struct ParameterEntry {
  const char* name;
  const char* meaning;
  std::function<void(SystemParams<S>&, const std::string&)> set;  // throws std::invalid_argument("...")
  std::function<std::string(const SystemParams<S>&)> get;
};

namespace detail::config {

inline double to_number(const std::string& text, const char* name) {
  double v = 0;
  const char* first = text.data();
  const char* last = first + text.size();
  const auto r = std::from_chars(first, last, v);
  if (text.empty() || r.ec != std::errc() || r.ptr != last || !std::isfinite(v))
    throw std::invalid_argument(std::string(name) + ": '" + text + "' is not a number");
  return v;
}
/// A number for a field of type T: one beyond T's range (1e39 for a float)
/// is an error, not infinity.
template <class T>
T to_scalar(const std::string& text, const char* name) {
  const double v = to_number(text, name);
  if (std::fabs(v) > double(std::numeric_limits<T>::max()))
    throw std::invalid_argument(std::string(name) + ": '" + text + "' is out of range (larger than " +
                                detail::tum::format(double(std::numeric_limits<T>::max())) + ")");
  return T(v);
}
inline int to_integer(const std::string& text, const char* name) {
  const double v = to_number(text, name);
  if (v != std::floor(v) || std::fabs(v) > 1e9)
    throw std::invalid_argument(std::string(name) + ": '" + text + "' is not an integer");
  return int(v);
}
inline bool to_bool(const std::string& text, const char* name) {
  if (text == "true" || text == "1" || text == "on" || text == "yes") return true;
  if (text == "false" || text == "0" || text == "off" || text == "no") return false;
  throw std::invalid_argument(std::string(name) + ": '" + text + "' is not true or false");
}
/// A float or double as its shortest text that reads back as the same
/// value of its type ("0.04" for a float, not the widened double's
/// "0.03999999910593033").
template <class T>
std::string print(T v) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), v);
  return std::string(buffer, result.ptr);
}

}  // namespace detail::config

/// Every parameter that config files and --set can change.
template <class S>
const std::vector<ParameterEntry<S>>& parameter_table() {
  using P = SystemParams<S>;
  using namespace detail::config;
#define EMF_NUMBER(name, field, meaning)                                                                \
  ParameterEntry<S> {                                                                                   \
    name, meaning, [](P& p, const std::string& v) { p.field = to_scalar<decltype(p.field)>(v, name); }, \
        [](const P& p) { return print(p.field); }                                                       \
  }
#define EMF_INTEGER(name, field, meaning)                                                                       \
  ParameterEntry<S> {                                                                                           \
    name, meaning, [](P& p, const std::string& v) { p.field = to_integer(v, name); },                           \
        [](const P& p) { return std::to_string(p.field); }                                                      \
  }
#define EMF_BOOL(name, field, meaning)                                                                          \
  ParameterEntry<S> {                                                                                           \
    name, meaning, [](P& p, const std::string& v) { p.field = to_bool(v, name); },                              \
        [](const P& p) { return std::string(p.field ? "true" : "false"); }                                      \
  }
  static const std::vector<ParameterEntry<S>> table{
      EMF_NUMBER("bilateral_sigma_depth", bilateral.sigma_depth, "bilateral filter range sigma (m)"),
      EMF_NUMBER("bilateral_sigma_space", bilateral.sigma_space, "bilateral filter spatial sigma (px)"),
      EMF_INTEGER("bilateral_radius", bilateral.radius, "bilateral filter half window (px)"),
      EMF_BOOL("sparse_background", sparse_background,
               "background in sparse voxel blocks, unbounded (else a dense cube)"),
      EMF_INTEGER("background_blocks", background_blocks, "most 8^3-voxel blocks of the sparse background"),
      EMF_INTEGER("background_voxels", background_voxels, "dense background volume voxels per axis"),
      EMF_NUMBER("background_voxel_size", background_voxel_size, "background voxel size (m)"),
      EMF_NUMBER("truncation_voxels", truncation_voxels, "truncation of every volume (voxels)"),
      EMF_INTEGER("object_voxels", object_voxels, "initial object volume voxels per axis"),
      EMF_NUMBER("object_padding", object_padding, "object volume side / largest 10-90 % extent"),
      EMF_NUMBER("object_depth_gap", object_depth_gap, "metres: a detection's points split at depth gaps this wide"),
      EMF_INTEGER("max_object_voxels", max_object_voxels, "largest object volume per axis after resizing"),
      EMF_INTEGER("max_objects", max_objects, "cap on live objects"),
      EMF_NUMBER("huber_voxels", huber_voxels, "Huber delta (voxels of the tracked volume)"),
      EMF_NUMBER("object_colour_weight", object_colour_weight,
                 "colour terms in object solves: voxels of SDF residual per unit of gray value (0: depth alone)"),
      EMF_INTEGER("pixel_stride", pixel_stride, "track objects with every n-th pixel in x and y"),
      EMF_INTEGER("pyramid_levels", pyramid_levels, "coarse-to-fine levels of every object solve (1: one level)"),
      EMF_INTEGER("camera_pixel_stride", camera_pixel_stride,
                  "track the camera with every n-th pixel in x and y (0: 2 where >= 50000 pixels remain)"),
      EMF_INTEGER("camera_pyramid_levels", camera_pyramid_levels, "coarse-to-fine levels of the camera's solve"),
      EMF_NUMBER("camera_converged_step", camera_converged_step,
                 "the camera's solve stops when the undamped step is shorter (0 = off)"),
      EMF_NUMBER("camera_converged_gain", camera_converged_gain,
                 "the camera's solve stops when a step lowers the cost by at most this fraction (0 = off)"),
      EMF_BOOL("predict_motion", predict_motion, "start pose solves at the constant-velocity prediction"),
      EMF_BOOL("retry_tracking", retry_tracking, "re-run an untracked solve from the other start"),
      EMF_NUMBER("object_pose_prior", object_pose_prior,
                 "pull of each object's solve towards its start, in surface points per direction (0: off)"),
      EMF_NUMBER("depth_noise_reference", depth_noise_reference,
                 "metres; tracking terms deeper weigh (sigma(ref)/sigma(z))^2, 0 = off"),
      EMF_NUMBER("max_depth", max_depth, "metres; deeper pixels are holes (0 = no limit)"),
      EMF_INTEGER("min_camera_terms", min_camera_terms, "fewer camera tracking terms: pose kept, frame not mapped"),
      EMF_INTEGER("min_object_terms", min_object_terms, "fewer object tracking terms: the object keeps its pose"),
      EMF_NUMBER("max_camera_translation", max_camera_motion.translation,
                 "metres per frame; a camera solve moving further is refused"),
      EMF_NUMBER("max_camera_rotation_degrees", max_camera_motion.rotation_degrees,
                 "degrees per frame; a camera solve turning further is refused"),
      EMF_NUMBER("max_object_translation", max_object_motion.translation,
                 "metres per frame; an object solve moving further is refused"),
      EMF_NUMBER("max_object_rotation_degrees", max_object_motion.rotation_degrees,
                 "degrees per frame; an object solve turning further is refused"),
      EMF_INTEGER("confirm_jump_frames", confirm_jump_frames,
                  "an object solve refused by the motion bound is taken when this many consecutive frames' refused "
                  "solves agree (0: never)"),
      EMF_INTEGER("lm_max_iterations", lm.max_iterations, "Levenberg-Marquardt iterations"),
      EMF_NUMBER("lm_tau", lm.tau, "Levenberg-Marquardt initial damping factor"),
      EMF_NUMBER("lm_eps1", lm.eps1, "stop when the gradient falls below"),
      EMF_NUMBER("lm_eps2", lm.eps2, "stop when the step falls below"),
      EMF_NUMBER("lm_converged_step", lm.converged_step,
                 "stop when the undamped step is shorter (se(3) norm; 0 = off)"),
      EMF_NUMBER("lm_converged_gain", lm.converged_gain,
                 "stop when a step lowers the cost by at most this fraction (0 = off)"),
      EMF_NUMBER("lm_refine_tau", lm.refine_tau, "initial damping of coarse-to-fine's finer levels (0 = lm_tau)"),
      EMF_NUMBER("alpha", likelihood.alpha, "inlier weight of the likelihood mixture (eq. 7)"),
      EMF_NUMBER("sigma", likelihood.sigma, "Laplace scale of the likelihood (m)"),
      EMF_NUMBER("p_uniform", likelihood.p_uniform, "uniform outlier density"),
      EMF_NUMBER("background_max_weight", background_integration.max_weight, "W_max of the background"),
      EMF_NUMBER("object_max_weight", object_integration.max_weight, "W_max of objects"),
      EMF_NUMBER("background_silhouette_guard", background_integration.silhouette_guard,
                 "no free-space carving within this many voxels of a silhouette (0: off)"),
      EMF_NUMBER("object_silhouette_guard", object_integration.silhouette_guard, "the same for objects"),
      EMF_NUMBER("background_unowned_free_from", background_integration.unowned_free_from,
                 "free space for the background this many truncations in front of points an object drawn there "
                 "owns (0: off)"),
      EMF_NUMBER("match_iou", match_iou, "detection-to-object mask IoU threshold"),
      EMF_INTEGER("min_mask_pixels", min_mask_pixels, "smallest detection / visible mask (px)"),
      EMF_NUMBER("max_object_distance", max_object_distance, "farthest new object centre (m)"),
      EMF_NUMBER("max_volume_iou", max_volume_iou, "largest volumetric IoU of a new object with others"),
      EMF_NUMBER("max_covered_fraction", max_covered_fraction, "drop masks this much covered by objects"),
      EMF_NUMBER("min_existence", min_existence, "delete objects below this existence probability"),
      EMF_INTEGER("visibility_border", visibility_border, "image border ignored for visibility (px)"),
      EMF_NUMBER("keep_visible_fraction", keep_visible_fraction,
                 "objects in the map stay visible down to this fraction of min_mask_pixels"),
      EMF_NUMBER("min_association", min_association, "delete objects with a lower mean association"),
      EMF_BOOL("ignore_person", ignore_person, "person objects: association only"),
      EMF_INTEGER("lost_object_frames", lost_object_frames, "keep objects that left the view this long (0: delete)"),
      EMF_INTEGER("max_lost_objects", max_lost_objects, "most lost objects kept for re-identification"),
      EMF_NUMBER("reidentify_min_inliers", reidentify_min_inliers, "share of a detection on a lost object's surface"),
      EMF_NUMBER("reidentify_keep_margin", reidentify_keep_margin,
                 "share of a detection another fit must add to replace the fit from an object's last pose"),
      EMF_NUMBER("reidentify_pose_prior", reidentify_pose_prior,
                 "pull of each re-identification fit towards its start, in surface points per direction (0: off)"),
      EMF_NUMBER("reidentify_turn_below", reidentify_turn_below,
                 "a lost object's fit with a lower share of a detection on its surface, or not shown in view, is tried "
                 "turned too (0: off)"),
      EMF_NUMBER("reidentify_colour_agreement", reidentify_colour_agreement,
                 "least correlation of a re-identification fit's gray values with the model's colour on its "
                 "surface (0: off; objects then keep colour)"),
      EMF_INTEGER(
          "reidentify_turned_keep", reidentify_turned_keep,
          "turned starts solved to the end, those with the most points on the surface after a short solve (0: all)"),
      EMF_INTEGER("reidentify_turned_rank_iterations", reidentify_turned_rank_iterations,
                  "iterations of the short solves that rank the turned starts (reidentify_turned_keep)"),
      EMF_NUMBER("reidentify_mask_fraction", reidentify_mask_fraction,
                 "a detection re-identifies a lost object with this fraction of min_mask_pixels points of its own"),
      EMF_NUMBER(
          "relocalize_below", relocalize_below,
          "move unmatched objects detected twice or more with a lower mean association onto a detection (0: off)"),
      EMF_NUMBER("merge_min_inliers", merge_min_inliers,
                 "merge two models of one object when this share of a detection fits both (0: off)"),
      EMF_BOOL("young_object_grace", young_object_grace,
               "new objects survive invisibility until the next detection (not once nothing of them shows)"),
      EMF_BOOL("hold_unseen_objects", hold_unseen_objects,
               "objects in that grace keep their pose while cut by the image border"),
      EMF_BOOL("hold_occluded_objects", hold_occluded_objects,
               "objects hidden behind others move on at their velocity instead of being tracked"),
      EMF_NUMBER("hidden_moving_seconds", hidden_moving_seconds,
                 "an object hidden behind others moves on at its velocity this long after it was last tracked, then "
                 "stays (s)"),
      EMF_NUMBER("predict_hidden_share", predict_hidden_share,
                 "an object with this share of its drawn model behind nearer surfaces is associated and solved from "
                 "its constant-velocity prediction (0: off)"),
      EMF_NUMBER("slide_seen_through_share", slide_seen_through_share,
                 "a partly hidden object whose solve makes the frame see through this share more of its model, "
                 "agreeing on less than half as many more pixels, stays at the solve's start (0: off)"),
      EMF_NUMBER("leaving_share", leaving_share,
                 "an object standing still of whose extent less than this share lies inside the image keeps its pose "
                 "instead of being tracked (0: off)"),
      EMF_NUMBER("leaving_still_translation", leaving_still.translation,
                 "standing still, for leaving_share: moved at most this over the last 0.2 s (m)"),
      EMF_NUMBER("leaving_still_rotation_degrees", leaving_still.rotation_degrees,
                 "standing still, for leaving_share: turned at most this over the last 0.2 s (degrees)"),
      EMF_BOOL("refind_in_view", refind_in_view,
               "lost objects come back without a detection where the frame shows their model"),
      EMF_NUMBER("refind_moving_seconds", refind_moving_seconds,
                 "a lost object that was moving is looked for where its motion carried it, this long (s)"),
      EMF_INTEGER("refind_unexplained_every", refind_unexplained_every,
                  "look for lost objects in what no model explains on every this many frames (0: off)"),
      EMF_NUMBER("refind_unexplained_sigmas", refind_unexplained_sigmas,
                 "unexplained: off the background's surface by more than this many likelihood sigmas"),
      EMF_BOOL("refind_unexplained_across", refind_unexplained_across,
               "unexplained: the background's SDF divided by its gradient's length where above 1 (grazing surfaces)"),
      EMF_NUMBER("refind_unexplained_speed", refind_unexplained_speed,
                 "... only as far from where an object was last tracked as this speed takes it (m/s)"),
      EMF_BOOL("hold_unexplained", hold_unexplained,
               "while a lost object is looked for, the background does not fuse what no model explains (frames without "
               "detections)"),
      EMF_INTEGER("track_back_frames", track_back_frames,
                  "frames kept to track new and found objects back through (0: off)"),
      EMF_NUMBER("min_foreground", min_foreground, "render object voxels above this p_fg"),
      EMF_NUMBER("occlusion_margin", occlusion_margin, "object loses to background this far behind (m)"),
      EMF_BOOL("occlusion_seen_through", occlusion_seen_through,
               "... unless the frame's depth lies behind the background there and on the object"),
      EMF_BOOL("use_association", use_association, "ablation switch: association likelihoods"),
      EMF_BOOL("use_map_confidence", use_map_confidence, "ablation switch: map confidence weights"),
      ParameterEntry<S>{"static_classes", "classes never made objects (comma-separated, or 'none')",
                        // White space around a name is not part of it ("bed, oven" is bed
                        // and oven: class names hold none); empty names and "none" are skipped,
                        // so that what prints reads back as the same list.
                        [](P& p, const std::string& v) {
                          p.static_classes.clear();
                          std::size_t pos = 0;
                          while (pos <= v.size()) {
                            const std::size_t end = std::min(v.find(',', pos), v.size());
                            const auto blank = [&](std::size_t k) {
                              return v[k] == ' ' || v[k] == '\t' || v[k] == '\r' || v[k] == '\n' || v[k] == '\v' ||
                                     v[k] == '\f';
                            };
                            std::size_t first = pos, last = end;
                            while (first < last && blank(first)) ++first;
                            while (last > first && blank(last - 1)) --last;
                            const std::string name = v.substr(first, last - first);
                            if (!name.empty() && name != "none") p.static_classes.push_back(name);
                            pos = end + 1;
                          }
                        },
                        [](const P& p) {
                          std::string s;
                          for (const auto& c : p.static_classes) s += (s.empty() ? "" : ",") + c;
                          return s.empty() ? std::string("none") : s;
                        }},
  };
#undef EMF_NUMBER
#undef EMF_INTEGER
#undef EMF_BOOL
  return table;
}

/// Sets one parameter by name; unknown names and bad values throw
/// std::invalid_argument naming them.
template <class S>
void set_parameter(SystemParams<S>& params, const std::string& name, const std::string& value) {
  for (const auto& e : parameter_table<S>())
    if (name == e.name) return e.set(params, value);
  throw std::invalid_argument("unknown parameter '" + name + "' (docs/parameters.md lists them)");
}

/// Applies "key=value".
template <class S>
void apply_override(SystemParams<S>& params, const std::string& assignment) {
  const std::size_t eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw std::invalid_argument("override '" + assignment + "' is not of the form key=value");
  set_parameter(params, assignment.substr(0, eq), assignment.substr(eq + 1));
}

/// read_config (below) of a config file's text in memory; `name` stands for
/// the file in error messages ("read_config: '<name>' line 3: ...").
template <class S>
void parse_config(const std::string& text, const std::string& name, SystemParams<S>& params) {
  constexpr const char* where = "read_config";
  const std::string& path = name;
  std::size_t pos = 0;
  for (int number = 1; pos <= text.size(); ++number) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    if (const std::size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    const auto trim = [](std::string s) {
      const std::size_t a = s.find_first_not_of(" \t\r");
      if (a == std::string::npos) return std::string();
      return s.substr(a, s.find_last_not_of(" \t\r") - a + 1);
    };
    line = trim(line);
    if (line.empty()) continue;
    const std::size_t eq = line.find('=');
    const auto fail = [&](const std::string& problem) {
      throw std::runtime_error(std::string(where) + ": " + detail::io::quoted(path) + " line " +
                               std::to_string(number) + ": " + problem);
    };
    if (eq == std::string::npos) fail("expected 'key = value', got '" + line + "'");
    try {
      set_parameter(params, trim(line.substr(0, eq)), trim(line.substr(eq + 1)));
    } catch (const std::invalid_argument& e) {
      fail(e.what());
    }
    if (end == text.size()) break;
  }
  try {
    params.validate();
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(std::string(where) + ": " + detail::io::quoted(path) + ": " + e.what());
  }
}

/// Reads a config file: "key = value" per line, '#' comments, blank lines.
/// Errors name the file, the line and the problem; the result is validated.
template <class S>
void read_config(const std::string& path, SystemParams<S>& params) {
  parse_config(detail::io::read_file(path, "read_config"), path, params);
}

}  // namespace emfusion
