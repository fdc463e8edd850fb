// emfusion: the full EM-Fusion system on a recording or a built-in synthetic
// scene, and the evaluation of its outputs (docs/user-guide.md).
//
//   emfusion run <input> --output <dir> [--masks <dir>] [--calibration <file>]
//                [--intrinsics fr1|fr2|fr3|default|fx,fy,cx,cy[,width,height]]
//                [--depth-scale S] [--backend cpu|cuda] [--config <file>]
//                [--set key=value ...] [--max-frames N]
//                [--checkpoint-every N] [--resume <dir>]
//   emfusion eval <sequence> <output-dir>
//   emfusion mesh <checkpoint> --output <dir>
//
// <input> is, by what is on disk (docs/io.md, "Inputs of the emfusion app"):
//   synthetic:<scene>   a built-in scene (room, room-small, room1, room8,
//                       room16, corridor, corridor-small; no data needed), with
//                       ground truth and a simulated detector;
//   <file>.klg          an ElasticFusion/Co-Fusion log; camera from
//                       --calibration, --intrinsics or the "default" preset,
//                       depth value per metre from --depth-scale (default 1000);
//   <dir>               a TUM-layout sequence when it has associations.txt or
//                       depth.txt (depth scale default 5000, camera from
//                       calibration.txt unless given; ground truth from
//                       groundtruth.txt), else a Co-Fusion folder when it has
//                       colour/ and depth/ folders (EXR depth in metres, so no
//                       --depth-scale; camera from calibration.txt unless given).
// --calibration and --intrinsics (only one of them) replace the camera of
// every recorded input. Masks come from --masks, else <dir>/masks when it has
// a masks.txt. With ground truth, `run` ends by printing the camera and
// object errors. The trajectories are written as the frames go; SIGINT or
// SIGTERM stops a run after the frame in progress with every output written
// for the frames processed, and exit status 130 / 143 (docs/user-guide.md,
// "Stopping a run"). --checkpoint-every N saves the whole state to
// <output>/checkpoint.emfckpt every N frames and when the run ends; --resume
// <dir> goes on from <dir>/checkpoint.emfckpt with the same input and
// parameters ("Resuming a run"); `mesh` writes the meshes of a checkpoint.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/core.h>

#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/object_matching.hpp"
#include "emfusion/eval/rpe.hpp"
#include "emfusion/io/checkpoint.hpp"
#include "emfusion/io/cofusion.hpp"
#include "emfusion/io/config.hpp"
#include "emfusion/io/frame_log.hpp"
#include "emfusion/io/intrinsics.hpp"
#include "emfusion/io/klg.hpp"
#include "emfusion/io/masks.hpp"
#include "emfusion/io/pictures.hpp"
#include "emfusion/io/ply.hpp"
#include "emfusion/io/run_json.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "emfusion/io/run_report.hpp"
#include "emfusion/io/trajectory_stream.hpp"
#include "emfusion/io/tum.hpp"
#include "emfusion/preprocess/intensity.hpp"
#include "emfusion/sim/detector.hpp"
#include "emfusion/sim/dynamic_scene.hpp"
#include "emfusion/slam/object_history.hpp"
#include "support/camera_input.hpp"
#include "support/system_host.hpp"  // emfusion/slam/system.hpp, System<float, Host> compiled once
#include "emfusion/volume/marching_cubes.hpp"
#include "support/backend.hpp"
#include "support/interrupt.hpp"

using namespace emfusion;
using S = float;
namespace fs = std::filesystem;

namespace {

struct RunOptions {
  std::string input, output, masks, calibration, intrinsics, backend = "cpu", config;
  double depth_scale = 0;
  std::vector<std::string> overrides;
  int max_frames = 0;
  int checkpoint_every = 0;
  std::string resume;
  bool verbose = false;
  bool pictures = false;
};

/// Ground truth of an input, when it has any.
struct GroundTruth {
  Trajectory camera;
  std::map<std::string, Trajectory> objects;
};

/// What the loop needs from any input: frames, a camera, detections.
struct Input {
  std::size_t frames = 0;
  PinholeCamera<double> camera;
  std::function<double(std::size_t)> timestamp;
  std::function<Image<float, Host>(std::size_t)> depth;
  /// Frame i's colour image, when the input has one (pictures only).
  std::function<std::optional<ColourImage>(std::size_t)> colour = [](std::size_t) { return std::nullopt; };
  std::function<std::optional<Detections>(int, double)> detect = [](int, double) { return std::nullopt; };
  std::string detector = "none";
  std::optional<GroundTruth> truth;
};

/// synthetic:<scene> names.
std::optional<sim::DynamicSceneParams> synthetic_params(const std::string& input) {
  const std::string prefix = "synthetic:";
  if (input.rfind(prefix, 0) != 0) return std::nullopt;
  const std::string name = input.substr(prefix.size());
  sim::DynamicSceneParams p;
  if (name == "room") return p;
  if (name == "room-small") {
    p.width = 320, p.height = 240, p.frames = 150;
    return p;
  }
  if (name == "room1" || name == "room8" || name == "room16") {
    p.moving_objects = name == "room1" ? 1 : name == "room8" ? 8 : 16;
    return p;
  }
  if (name == "corridor" || name == "corridor-small") {  // an 11 m walk with four moving objects
    p.layout = sim::SceneLayout::corridor;
    p.frames = 600;
    p.moving_objects = 4;
    if (name == "corridor-small") p.width = 320, p.height = 240;
    return p;
  }
  throw std::invalid_argument("unknown synthetic scene '" + name +
                              "' (room, room-small, room1, room8, room16, corridor, corridor-small)");
}

/// The simulated detector of a built-in scene (`run` and `export`): its
/// 40x40 px minimum is for 640x480 images, as the system's.
sim::SimulatedDetectorParams detector_params(const sim::DynamicSceneParams& scene) {
  sim::SimulatedDetectorParams dp;
  dp.min_area = std::max(1, int(dp.min_area * double(scene.width) * scene.height / (640.0 * 480.0)));
  return dp;
}

/// The kinds of input `run` reads.
enum class InputKind { Synthetic, Klg, CoFusion, Tum };

constexpr const char* expected_inputs =
    "expected synthetic:<scene>, a .klg file, a Co-Fusion folder (colour/ and depth/ folders) or a TUM-layout "
    "sequence directory (associations.txt or depth.txt)";

[[noreturn]] void bad_input(const std::string& input, const std::string& problem) {
  throw std::runtime_error("'" + input + "': " + problem + " (" + expected_inputs + ")");
}

/// The kind of `input`, by what is on disk: a .klg file; a directory with
/// associations.txt or depth.txt (TUM layout); a directory with colour/ and
/// depth/ folders (Co-Fusion). Anything else is an error naming the path.
InputKind input_kind(const std::string& input) {
  if (input.rfind("synthetic:", 0) == 0) return InputKind::Synthetic;
  const fs::path path(input);
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status))
    bad_input(input, ec && ec != std::errc::no_such_file_or_directory ? ec.message() : "not found");
  if (fs::is_regular_file(status)) {
    std::string extension = path.extension().string();
    for (char& c : extension) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (extension == ".klg") return InputKind::Klg;
    bad_input(input, "a file, but its name does not end in .klg");
  }
  if (!fs::is_directory(status)) bad_input(input, "neither a file nor a directory");
  const auto is_file = [&](const char* name) { return fs::is_regular_file(path / name, ec); };
  const auto is_dir = [&](const char* name) { return fs::is_directory(path / name, ec); };
  if (is_file("associations.txt") || is_file("depth.txt")) return InputKind::Tum;
  if (is_dir("colour") && is_dir("depth")) return InputKind::CoFusion;
  std::string problem =
      "neither a TUM-layout sequence (no associations.txt or depth.txt) nor a Co-Fusion folder (no colour/ and depth/ "
      "folders)";
  if (is_dir("colour")) problem += ": it has a colour/ folder but no depth/ folder";
  if (is_dir("depth")) problem += ": it has a depth/ folder but no colour/ folder and no depth.txt";
  throw std::runtime_error("'" + input + "': " + problem);
}

/// Checks --calibration and --intrinsics (at most one of them) and parses
/// --intrinsics; the calibration file is read later, for recorded inputs.
std::optional<PinholeCamera<double>> intrinsics_option(const RunOptions& o) {
  if (!o.calibration.empty() && !o.intrinsics.empty())
    throw std::invalid_argument("--calibration '" + o.calibration + "' and --intrinsics '" + o.intrinsics +
                                "' both given: give only one of them");
  if (o.intrinsics.empty()) return std::nullopt;
  try {
    return intrinsics_from_argument(o.intrinsics);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("--intrinsics: ") + e.what());
  }
}

/// Where the camera came from, for messages.
std::string camera_option_text(const RunOptions& o) {
  if (!o.calibration.empty()) return "--calibration '" + o.calibration + "'";
  if (!o.intrinsics.empty()) return "--intrinsics '" + o.intrinsics + "'";
  return "";
}

Input open_input(const RunOptions& o) {
  Input in;
  // Bad options first, then what is on disk.
  const std::optional<PinholeCamera<double>> intrinsics = intrinsics_option(o);
  const InputKind kind = input_kind(o.input);
  if (kind == InputKind::Synthetic) {
    const auto params = synthetic_params(o.input);
    const std::pair<bool, const char*> recording_options[] = {{!o.calibration.empty(), "--calibration"},
                                                              {!o.intrinsics.empty(), "--intrinsics"},
                                                              {o.depth_scale > 0, "--depth-scale"}};
    for (const auto& [given, name] : recording_options)
      if (given)
        throw std::invalid_argument(std::string(name) + " does not apply to '" + o.input +
                                    "': a synthetic scene has its own camera and depth in metres");
    auto seq = std::make_shared<sim::SyntheticSequence>(*params);
    auto detector = std::make_shared<sim::SimulatedDetector<float>>(seq->scene(), detector_params(*params));
    in.frames = seq->size();
    in.camera = seq->camera();
    in.timestamp = [seq](std::size_t i) { return seq->timestamp(i); };
    in.depth = [seq](std::size_t i) { return seq->depth(i); };
    in.detect = [detector](int i, double t) { return detector->detect(i, t); };
    in.detector = "simulated";
    GroundTruth gt;
    gt.camera = seq->scene().camera_trajectory();
    for (int k = 0; k < seq->scene().object_count(); ++k)
      gt.objects[seq->scene().object_name(k)] = seq->scene().object_trajectory(k);
    in.truth = gt;
  } else {
    const std::optional<PinholeCamera<double>> camera =
        o.calibration.empty() ? intrinsics : std::optional(read_calibration(o.calibration));
    std::string camera_source = camera_option_text(o);
    if (kind == InputKind::Klg) {
      // A log has no intrinsics and no ground truth.
      if (!camera) camera_source = "the default preset: give the camera with --calibration or --intrinsics";
      auto seq = std::make_shared<KlgSequence>(KlgSequence::open(
          o.input, camera ? *camera : intrinsics_preset("default"), o.depth_scale > 0 ? o.depth_scale : 1000.0));
      in.frames = seq->size();
      in.camera = seq->camera();
      in.timestamp = [seq](std::size_t i) { return seq->timestamp(i); };
      in.depth = [seq](std::size_t i) { return seq->depth(i); };
      in.colour = [seq, path = o.input](std::size_t i) -> std::optional<ColourImage> {
        const std::vector<std::uint8_t> bytes = seq->colour_bytes(i);
        if (bytes.empty()) return std::nullopt;
        if (seq->colour_is_jpeg(i)) return decode_jpeg(bytes, path + " frame " + std::to_string(i));
        return colour_from_rgb_bytes(bytes, seq->camera().width, seq->camera().height);
      };
    } else if (kind == InputKind::CoFusion) {
      // The format has no ground truth that the reader offers.
      if (o.depth_scale > 0)
        throw std::invalid_argument("--depth-scale does not apply to '" + o.input +
                                    "': a Co-Fusion folder's EXR depth is in metres");
      CoFusionOptions copt;
      copt.camera = camera;
      auto seq = std::make_shared<CoFusionSequence>(CoFusionSequence::open(o.input, copt));
      if (!camera) camera_source = "'" + seq->camera_source() + "'";  // a calibration.txt
      in.frames = seq->size();
      in.camera = seq->camera();
      in.timestamp = [seq](std::size_t i) { return seq->timestamp(i); };
      in.depth = [seq](std::size_t i) { return seq->depth(i); };
      in.colour = [seq](std::size_t i) { return std::optional(read_colour(seq->colour_path(i))); };
    } else {
      TumOptions topt;
      if (o.depth_scale > 0) topt.depth_scale = o.depth_scale;
      topt.camera = camera;
      auto seq = std::make_shared<TumSequence>(TumSequence::open(o.input, topt));
      if (!camera) {  // calibration.txt, or a text starting with "default"
        const std::string& source = seq->camera_source();
        camera_source = source.rfind("default", 0) == 0 ? source : "'" + source + "'";
      }
      in.frames = seq->size();
      in.camera = seq->camera();
      in.timestamp = [seq](std::size_t i) { return seq->timestamp(i); };
      in.depth = [seq](std::size_t i) { return seq->depth(i); };
      if (seq->has_colour())
        in.colour = [seq](std::size_t i) { return std::optional(read_colour(seq->colour_path(i))); };
      if (auto gt = seq->ground_truth()) in.truth = GroundTruth{*gt, {}};
      if (in.truth)
        for (auto& [name, traj] : seq->ground_truth_objects()) in.truth->objects[name] = traj;
    }
    // A camera of the wrong size shows on the first frame: fail before the
    // run starts, saying where the camera came from.
    if (in.frames > 0) {
      try {
        in.depth(0);
      } catch (const std::runtime_error& e) {
        throw std::runtime_error(std::string(e.what()) + " (camera " + std::to_string(in.camera.width) + "x" +
                                 std::to_string(in.camera.height) + " from " + camera_source + ")");
      }
    }
    if (kind == InputKind::Klg && !camera) {
      const PinholeCamera<double>& c = in.camera;
      fmt::print(stderr,
                 "emfusion: '{}' holds no intrinsics and neither --calibration nor --intrinsics is given: using the "
                 "default preset (fx {:g}, fy {:g}, cx {:g}, cy {:g}, {}x{})\n",
                 o.input, c.fx, c.fy, c.cx, c.cy, c.width, c.height);
    }
  }
  // Masks: --masks, else <input>/masks of a directory input when it has a masks.txt.
  std::string masks = o.masks;
  if (masks.empty() && (kind == InputKind::Tum || kind == InputKind::CoFusion)) {
    std::error_code ec;
    const fs::path folder = fs::path(o.input) / "masks";
    if (fs::is_regular_file(folder / "masks.txt", ec)) masks = folder.string();
  }
  if (!masks.empty()) {
    auto dir = std::make_shared<MaskDirectory>(MaskDirectory::open(masks, in.camera.width, in.camera.height));
    in.detect = [dir](int i, double t) { return dir->detect(i, t); };
    in.detector = masks;
  }
  return in;
}

/// Median and 90th percentile of a list of times.
std::pair<double, double> median_p90(std::vector<double> v) {
  if (v.empty()) return {0, 0};
  std::sort(v.begin(), v.end());
  const auto at = [&](double q) { return v[std::min(v.size() - 1, std::size_t(q * double(v.size() - 1) + 0.5))]; };
  return {at(0.5), at(0.9)};
}

/// run.json's "objects": per object its class, tracking counts and events
/// (docs/io.md, "run.json"); and one line per object on stdout, e.g.
/// "object 3 (cup): created 12, lost 150, found_again 171 (in_view); tracked 270, refused 2, retried 1"
/// (and ", moved on hidden 9" for an object that was hidden behind others,
/// ", confirmed jumps 1" for one whose refused solves agreed: confirm_jump_frames,
/// ", kept at start 2" for one whose solves slid where the frame saw through it:
/// slide_seen_through_share,
/// ", tracked back 29" for one whose trajectory holds poses of frames before
/// it was created or found again: track_back_frames).
void write_object_histories(Json& json, const ObjectHistories& histories, const std::vector<ObjectRecord>& records) {
  Json& objects = json["objects"] = Json::array();
  for (const auto& [id, h] : histories.objects()) {
    std::string class_name = "?";
    for (const ObjectRecord& r : records)
      if (r.id == id) class_name = r.class_name;
    objects.push_back(object_history_json(h, class_name));
    std::string line;
    for (const ObjectEvent& e : h.events) {
      line += fmt::format("{}{} {}", line.empty() ? "" : ", ", to_string(e.kind), e.frame);
      if (e.kind == ObjectEventKind::deleted) line += fmt::format(" ({})", to_string(e.reason));
      if (e.kind == ObjectEventKind::found_again) line += fmt::format(" ({})", to_string(e.by));
      if (e.kind == ObjectEventKind::merged) line += fmt::format(" (into {})", e.other);
      if (e.kind == ObjectEventKind::absorbed) line += fmt::format(" (object {})", e.other);
    }
    fmt::print("object {} ({}): {}; tracked {}, refused {}, retried {}{}{}{}{}\n", id, class_name,
               line.empty() ? "no events" : line, h.tracked, h.refused, h.retried,
               h.moved_on > 0 ? fmt::format(", moved on hidden {}", h.moved_on) : std::string(),
               h.confirmed > 0 ? fmt::format(", confirmed jumps {}", h.confirmed) : std::string(),
               h.kept_start > 0 ? fmt::format(", kept at start {}", h.kept_start) : std::string(),
               h.tracked_back > 0 ? fmt::format(", tracked back {}", h.tracked_back) : std::string());
  }
}

void print_evaluation(const Trajectory& est_cam, const std::map<int, Trajectory>& est_objects, const GroundTruth& gt,
                      Json* json) {
  if (est_cam.size() < 3) {
    fmt::print("camera: fewer than 3 poses, no evaluation\n");
    return;
  }
  const auto ate = eval::absolute_trajectory_error(est_cam, gt.camera);
  // RPE needs pose pairs 1 s apart: short runs have none.
  const bool has_rpe = est_cam.back().timestamp - est_cam.front().timestamp >= 1.0;
  const double rpe = has_rpe ? eval::relative_pose_error(est_cam, gt.camera).translation_rmse : NAN;
  const std::string rpe_text = has_rpe ? fmt::format("{:.2f} cm/s", 100 * rpe) : "- (run shorter than 1 s)";
  fmt::print("camera: ATE RMSE {:.2f} cm over {} poses, RPE RMSE {}\n", 100 * ate.rmse, ate.matched, rpe_text);
  if (json) {
    Json& camera = (*json)["camera"] = Json::object();
    camera["ate_rmse_m"] = ate.rmse;
    camera["poses"] = ate.matched;
    camera["rpe_rmse_m_per_s"] = rpe;  // NaN (no RPE) is written as null
  }
  if (gt.objects.empty()) return;
  const auto objects = eval::evaluate_objects(est_cam, gt.camera, est_objects, gt.objects);
  fmt::print("{:<16} {:<10} {:>12} {:>10}\n", "object", "estimate", "ATE RMSE", "coverage");
  Json* evaluated = json ? &((*json)["objects"] = Json::object()) : nullptr;
  for (const auto& o : objects) {
    if (o.evaluated)
      fmt::print("{:<16} {:<10} {:9.2f} cm {:9.0f} %\n", o.name, o.primary, 100 * o.result.ate.rmse,
                 100 * o.result.coverage);
    else
      fmt::print("{:<16} {:<10} {:>12} {:>10}  ({})\n", o.name, "-", "-", "0 %", o.problem);
    if (evaluated) {
      Json& object = (*evaluated)[o.name] = Json::object();
      object["estimate"] = o.primary;
      object["evaluated"] = o.evaluated;
      object["ate_rmse_m"] = o.evaluated ? o.result.ate.rmse : NAN;
      object["coverage"] = o.evaluated ? o.result.coverage : 0.0;
    }
  }
}

/// The pictures of one frame (docs/user-guide.md section 4): the rendered
/// segmentation over the colour image, and each model's association.
template <class B>
void write_pictures(const std::string& dir, std::size_t frame, const std::optional<ColourImage>& colour,
                    const System<S, B>& system, const FrameResult& result) {
  const std::string number = fmt::format("{:06}", frame);
  const ColourImage* c = colour ? &*colour : nullptr;
  // The segmentation and the association images of this frame were made
  // before its deletions and creations: label (model) k + 1 is the k-th
  // object of object_status.
  std::vector<int> ids;
  for (const ObjectStatus& st : result.object_status) ids.push_back(st.id);
  const Image<int, Host> seg = system.segmentation().template to<Host>();
  write_png((fs::path(dir) / ("segmentation_" + number + ".png")).string(),
            segmentation_overlay(c, seg, 0.5f, &ids));
  const auto& q = system.associations();
  for (int m = 0; m < q.model_count() && m <= int(ids.size()); ++m) {
    const std::string model = m == 0 ? "background" : "object_" + std::to_string(ids[std::size_t(m - 1)]);
    write_png((fs::path(dir) / ("association_" + number + "_" + model + ".png")).string(),
              association_heatmap(q.image(m).template to<Host>(), c));
  }
}

/// objects.txt's lines for the system's records (persons are not exported).
std::vector<ObjectListEntry> object_list(const std::vector<ObjectRecord>& records) {
  std::vector<ObjectListEntry> list;
  for (const ObjectRecord& r : records)
    if (!r.person) list.push_back({r.id, r.class_name, r.first_timestamp, r.last_timestamp, r.deleted});
  return list;
}

/// The outputs that grow with every frame, written as they grow, so that a
/// run stopped at any moment keeps them (docs/user-guide.md, "Stopping a
/// run"): camera.txt and objects/<id>.txt appended and flushed after each
/// frame, synced to the disk about once a second; objects.txt replaced whole
/// (temporary file and rename) when an object comes or goes, and once a
/// second for the last timestamps.
class StreamedOutputs {
 public:
  explicit StreamedOutputs(const std::string& dir)
      : dir_(dir), camera_((fs::path(dir) / "camera.txt").string()), last_sync_(std::chrono::steady_clock::now()) {
    // Replaces a previous run's list at once: it would name objects of that run.
    write_object_list(list_path(), list_);
  }

  /// Writes what the last process() added to the camera trajectory and the
  /// object records.
  void update(const Trajectory& camera, const std::vector<ObjectRecord>& records) {
    for (std::size_t k = camera_.size(); k < camera.size(); ++k) camera_.append(camera[k]);
    camera_.flush();
    for (const ObjectRecord& r : records) {
      if (r.person) continue;
      auto it = objects_.find(r.id);
      if (it == objects_.end()) {
        const fs::path path = fs::path(dir_) / "objects" / (std::to_string(r.id) + ".txt");
        it = objects_.emplace(r.id, TumTrajectoryStream(path.string())).first;
      }
      TumTrajectoryStream& stream = it->second;
      for (std::size_t k = stream.size(); k < r.trajectory.size(); ++k) stream.append(r.trajectory[k]);
      // A deleted object holds no descriptor (a long run creates many); if
      // it is re-identified, its file is reopened and continued.
      if (r.deleted && stream.is_open()) {
        stream.sync();
        stream.close();
      } else {
        stream.flush();
      }
    }
    // fdatasync costs about a millisecond per file here, and so does a
    // rename over objects.txt (ext4 writes the new data first): a new,
    // deleted or re-identified object is written at once, the last
    // timestamps of live objects once a second, as the syncs.
    const auto now = std::chrono::steady_clock::now();
    const bool due = now - last_sync_ >= std::chrono::seconds(1);
    std::vector<ObjectListEntry> list = object_list(records);
    if (list != list_ && (due || !same_objects(list, list_))) {
      write_object_list(list_path(), list);
      list_ = std::move(list);
    }
    if (due) {
      sync();
      last_sync_ = now;
    }
  }

  /// Syncs and closes every trajectory file, reporting any write error.
  void close() {
    sync();
    camera_.close();
    for (auto& entry : objects_) entry.second.close();
  }

 private:
  void sync() {
    camera_.sync();
    for (auto& entry : objects_)
      if (entry.second.is_open()) entry.second.sync();
  }
  std::string list_path() const { return (fs::path(dir_) / "objects.txt").string(); }
  /// The same objects in the same state, whatever their last timestamps.
  static bool same_objects(const std::vector<ObjectListEntry>& a, const std::vector<ObjectListEntry>& b) {
    return std::equal(a.begin(), a.end(), b.begin(), b.end(), [](const ObjectListEntry& x, const ObjectListEntry& y) {
      return x.id == y.id && x.class_name == y.class_name && x.first_timestamp == y.first_timestamp &&
             x.deleted == y.deleted;
    });
  }

  std::string dir_;
  TumTrajectoryStream camera_;
  std::map<int, TumTrajectoryStream> objects_;
  std::vector<ObjectListEntry> list_;
  std::chrono::steady_clock::time_point last_sync_;
};

/// frames.csv's lines of the frames before `first` from the run resumed
/// (<resume>/frames.csv), so that a resumed run's file covers every frame;
/// none when not resuming or when that file is missing or unreadable.
std::vector<FrameLogRow> resumed_frame_log(const std::string& resume, std::size_t first) {
  std::vector<FrameLogRow> kept;
  const fs::path path = fs::path(resume) / "frames.csv";
  if (resume.empty() || first == 0 || !fs::exists(path)) return kept;
  try {
    for (const FrameLogRow& row : read_frame_log(path.string()))
      if (row.frame < first) kept.push_back(row);
  } catch (const std::runtime_error& e) {
    fmt::print(stderr, "emfusion: warning: {}: frames.csv starts at the checkpoint\n", e.what());
  }
  return kept;
}

/// meshes/background.ply and meshes/object_<id>.ply of every live object.
template <class B>
void write_meshes(const fs::path& dir, const Map<S, B>& map) {
  map.background.visit([&](const auto& bg) {
    write_ply((dir / "background.ply").string(), transformed(marching_cubes(bg, S(0), S(1)), bg.pose()));
  });
  for (const auto& obj : map.objects)
    write_ply((dir / ("object_" + std::to_string(obj->id()) + ".ply")).string(),
              transformed(marching_cubes(obj->volume(), S(0), S(1)), obj->T_object_volume()));
}

template <class B>
void run(const RunOptions& o) {
  SystemParams<S> params;
  // room-small is the quick scene: a 256^3 background of 2 cm voxels.
  if (o.input == "synthetic:room-small") params.background_voxels = 256, params.background_voxel_size = S(0.02);
  if (!o.config.empty()) read_config(o.config, params);
  for (const auto& a : o.overrides) apply_override(params, a);
  params.validate();
  Input in = open_input(o);
  const std::size_t frames = o.max_frames > 0 ? std::min<std::size_t>(in.frames, std::size_t(o.max_frames)) : in.frames;
  if (frames == 0) throw std::runtime_error("'" + o.input + "' has no frames");
  // Fail on an unwritable output before spending time on the frames.
  const fs::path out(o.output);
  const std::string pictures = (out / "pictures").string();
  std::vector<std::string> dirs{o.output, (out / "objects").string(), (out / "meshes").string()};
  if (o.pictures) dirs.push_back(pictures);
  for (const std::string& dir : dirs) {
    create_output_directory(dir);
    check_writable_directory(dir);
  }

  const B backend{};
  System<S, B> system(in.camera.cast<S>(), params, backend);
  // A resumed run goes on at the frame after the checkpoint's last one: the
  // frame count is the index of the next input frame.
  std::size_t first = 0;
  if (!o.resume.empty()) {
    const std::string from = (fs::path(o.resume) / "checkpoint.emfckpt").string();
    restore_checkpoint(system, from);
    first = std::size_t(system.frame_count());
    if (first > frames)
      throw std::runtime_error("'" + from + "' has " + std::to_string(first) + " frames processed, but '" + o.input +
                               "' gives only " + std::to_string(frames));
    fmt::print(stderr, "emfusion: resuming from '{}' at frame {}\n", from, first);
  }
  const std::string checkpoint = (out / "checkpoint.emfckpt").string();
  // run.json is written before the first frame, saying "running", and
  // replaced at the end: one that still says so is a run killed on the way.
  const auto run_summary = [&](const char* status, std::size_t processed) {
    Json json;
    json["input"] = o.input;
    json["backend"] = B::name;
    json["detector"] = in.detector;
    json["status"] = status;
    json["frames"] = processed;
    json["frames_requested"] = frames;
    return json;
  };
  const auto settings = [&](Json& json) {
    Json& values = json["settings"] = Json::object();
    for (const auto& e : parameter_table<S>()) values[e.name] = e.get(system.params());
  };
  {
    Json json = run_summary("running", 0);
    settings(json);
    write_json_file((out / "run.json").string(), json);
  }
  // Colour asked for where there is none: say so once, and go on with depth.
  if (system.params().uses_colour() && first < frames && !in.colour(first))
    fmt::print(stderr,
               "note: '{}' has no colour images: object_colour_weight or reidentify_colour_agreement is set, objects "
               "are tracked and found again on depth alone\n",
               o.input);
  StreamedOutputs streams(o.output);
  FrameLog frame_log((out / "frames.csv").string(), resumed_frame_log(o.resume, first));
  // The trajectories so far, from the checkpoint: the files come out as
  // those of a run that never stopped.
  if (first > 0) streams.update(system.camera_trajectory(), system.object_records());

  std::vector<StageTimes> times;
  ObjectHistories histories;  // of the frames this process ran (a resumed run: since the checkpoint)
  // One updating progress line on a terminal; plain lines on a pipe and in
  // CI (which may run the app on a pseudo-terminal).
  const bool tty = isatty(fileno(stderr)) && std::getenv("CI") == nullptr;
  const auto start = std::chrono::steady_clock::now();
  std::size_t processed = first;
  // A signal stops the loop between frames; the outputs below are then
  // those of the frames processed.
  for (std::size_t i = first; i < frames && examples::interrupt_signal() == 0; ++i) {
    const double t = in.timestamp(i);
    const Image<S, B> depth = in.depth(i).template to<B>(backend);
    const std::optional<Detections> det = in.detect(int(i), t);
    // The objects' colour (object_colour_weight, reidentify_colour_agreement)
    // takes the frame's gray values.
    const std::optional<ColourImage> colour =
        system.params().uses_colour() ? in.colour(i) : std::optional<ColourImage>{};
    Image<S, B> intensity;
    if (colour && (colour->width() != in.camera.width || colour->height() != in.camera.height))
      throw std::runtime_error("'" + o.input + "' frame " + std::to_string(i) + ": its colour image is " +
                               std::to_string(colour->width()) + "x" + std::to_string(colour->height()) +
                               ", the camera's " + std::to_string(in.camera.width) + "x" +
                               std::to_string(in.camera.height));
    if (colour) intensity_image(*colour, intensity, backend);
    const FrameResult r = system.process(depth, t, det ? &*det : nullptr, colour ? &intensity : nullptr);
    histories.add(r, system.map());
    processed = i + 1;
    streams.update(system.camera_trajectory(), system.object_records());
    frame_log.append({i, t, r.times, r.live_objects, resident_memory_mib(), device_memory_mib<B>()});
    if (o.checkpoint_every > 0 && processed % std::size_t(o.checkpoint_every) == 0 && processed < frames)
      save_checkpoint(checkpoint, system);
    times.push_back(r.times);
    if (o.pictures) write_pictures(pictures, i, colour ? colour : in.colour(i), system, r);
    if (o.verbose) {
      // On a terminal, each message starts a line of its own after the progress line.
      const char* const nl = tty ? "\n" : "";
      for (const int id : r.created) fmt::print(stderr, "{}frame {}: created object {}\n", nl, i, id);
      for (std::size_t k = 0; k < r.reidentified.size(); ++k)
        fmt::print(stderr, "{}frame {}: re-identified lost object {} ({})\n", nl, i, r.reidentified[k],
                   k < r.found_by.size() ? to_string(r.found_by[k]) : "?");
      for (const int id : r.relocalized)
        fmt::print(stderr, "{}frame {}: moved object {} onto its detection (relocalized)\n", nl, i, id);
      for (const int id : r.deleted)
        for (const ObjectRecord& rec : system.object_records())
          if (rec.id == id)
            fmt::print(stderr, "{}frame {}: deleted object {} ({}): {}\n", nl, i, id, rec.class_name,
                       to_string(rec.reason));
      // Frames the system refused to map, and detections it ignored (docs/system.md, "Hostile input").
      if (r.camera_tracking != TrackingOutcome::tracked && r.camera_tracking != TrackingOutcome::not_tracked)
        fmt::print(stderr, "{}frame {}: camera {} (step {:.3f} m, {:.1f} deg, {} valid depth pixels), frame not mapped\n",
                   nl, i, to_string(r.camera_tracking), r.camera_step.translation,
                   r.camera_step.rotation * 180.0 / 3.14159265358979323846, r.depth.valid);
      if (r.invalid_detections > 0 || r.detections_over_cap > 0)
        fmt::print(stderr, "{}frame {}: {} detections ignored (unusable label or score), {} over the object cap\n", nl,
                   i, r.invalid_detections, r.detections_over_cap);
      if (r.held_for_colour > 0)
        fmt::print(stderr, "{}frame {}: {} detections made no object (a lost object fits them in depth, not colour)\n",
                   nl, i, r.held_for_colour);
    }
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double fps = double(i + 1 - first) / elapsed;
    if (tty) {
      const int width = 30, done = int(width * double(i + 1) / double(frames));
      const long left = std::lround(double(frames - i - 1) / fps);
      fmt::print(stderr, "\r[{}{}] {}/{}  {:.1f} fps  {}:{:02} left  {} objects ", std::string(std::size_t(done), '#'),
                 std::string(std::size_t(width - done), '.'), i + 1, frames, fps, left / 60, left % 60, r.live_objects);
      if (i + 1 == frames) fmt::print(stderr, "\n");
    } else if ((i + 1) % 30 == 0 || i + 1 == frames) {
      fmt::print(stderr, "frame {}/{}: {:.1f} fps, {} objects\n", i + 1, frames, fps, r.live_objects);
    }
  }
  const int sig = examples::interrupt_signal();
  const bool interrupted = processed < frames;
  if (interrupted)
    fmt::print(stderr,
               "{}emfusion: {}: stopped after {} of {} frames; writing the outputs (a second signal stops at once)\n",
               tty ? "\n" : "", examples::signal_name(sig), processed, frames);

  // Outputs (FORMATS.md section 5): the trajectories are complete already.
  streams.close();
  frame_log.close();
  if (o.checkpoint_every > 0) save_checkpoint(checkpoint, system);
  const std::vector<ObjectListEntry> list = object_list(system.object_records());
  write_object_list((out / "objects.txt").string(), list);
  std::map<int, Trajectory> est_objects;
  // A model merged into another has its poses in the other's trajectory too.
  for (const ObjectRecord& r : system.object_records())
    if (!r.person && r.reason != DeletionReason::merged) est_objects[r.id] = r.trajectory;
  write_meshes(out / "meshes", system.map());

  Json json = run_summary(interrupted ? "interrupted" : "finished", processed);
  if (interrupted) {
    json["signal"] = examples::signal_name(sig);
    // The last frame processed: its index in the input and its timestamp.
    json["last_frame"] = (long long)processed - 1;
    json["last_timestamp"] = processed > 0 ? in.timestamp(processed - 1) : NAN;
  }
  json["objects_created"] = list.size();
  // The models' memory as the run ended (the background's: what it holds,
  // not its bound; docs/user-guide.md, "Outputs").
  Json& memory = json["memory"] = Json::object();
  memory["background"] = system.background().describe();
  memory["background_bytes"] = system.background().memory_bytes();
  memory["models_bytes"] = system.memory_bytes();
  settings(json);
  Json& timings = json["timings_ms"] = Json::object();
  const auto stage = [&](const char* name, double StageTimes::*field) {
    std::vector<double> v;
    for (const auto& t : times) v.push_back(t.*field);
    const auto [med, p90] = median_p90(v);
    Json& entry = timings[name] = Json::object();
    entry["median"] = med;
    entry["p90"] = p90;
  };
  stage("preprocess", &StageTimes::preprocess);
  stage("e_step", &StageTimes::e_step);
  stage("track_background", &StageTimes::track_background);
  stage("track_objects", &StageTimes::track_objects);
  stage("raycast", &StageTimes::raycast);
  stage("detections", &StageTimes::detections);
  stage("integrate", &StageTimes::integrate);
  stage("foreground", &StageTimes::foreground);
  stage("total", &StageTimes::total);
  write_object_histories(json, histories, system.object_records());
  std::vector<double> totals;
  for (const auto& t : times) totals.push_back(t.total);
  const auto [med, p90] = median_p90(totals);
  fmt::print("{} frames on {}: {:.1f} ms per frame (median), {:.1f} ms (90th percentile); {} objects created\n",
             processed, B::name, med, p90, list.size());
  if (in.truth) {
    Json& evaluation = json["evaluation"] = Json::object();
    print_evaluation(system.camera_trajectory(), est_objects, *in.truth, &evaluation);
  }
  write_json_file((out / "run.json").string(), json);
  if (interrupted)
    fmt::print("wrote {} (interrupted by {} after {} of {} frames)\n", o.output, examples::signal_name(sig), processed,
               frames);
  else
    fmt::print("wrote {}\n", o.output);
}

/// `emfusion mesh`: the meshes of a checkpoint's map, without its sequence.
void mesh(const std::string& checkpoint, const std::string& output) {
  const Checkpoint<S, Host> ck = load_checkpoint<S, Host>(checkpoint);
  const fs::path dir = fs::path(output) / "meshes";
  create_output_directory(dir.string());
  write_meshes(dir, ck.map);
  fmt::print("wrote {} ({} objects, {} frames)\n", dir.string(), ck.map.objects.size(), ck.map.frames);
}

/// `emfusion export`: a built-in scene as a sequence folder holding what a
/// recording of it with a detector would (FORMATS.md): noisy depth
/// (examples::export_tum_sequence: depth/, depth.txt, calibration.txt,
/// groundtruth.txt), groundtruth_objects/<name>.txt, masks/ (the detections
/// `run` sees on the scene: the same simulated detector), masks_gt/ (the
/// scene's own labels, object k as k + 1, every frame) and scene.json (the
/// objects in label order and the detector's period). `run` and `eval`
/// read it as any sequence; bench/generalisation.py scores runs on it as on
/// its generated sequences.
void export_scene(const std::string& input, const std::string& dir, int max_frames) {
  const auto params = synthetic_params(input);
  if (!params)
    throw std::invalid_argument("'" + input + "' is not a built-in scene: expected synthetic:<scene>");
  const sim::DynamicScene<float> scene = sim::make_dynamic_scene<float>(*params);
  const int frames = max_frames > 0 ? std::min(max_frames, scene.frame_count()) : scene.frame_count();
  const fs::path out(dir);
  const sim::SimulatedDetectorParams dp = detector_params(*params);
  sim::SimulatedDetector<float> detector(scene, dp);
  std::vector<Detections> detected, truth;
  // The scene's labels come with each frame's depth (one render a frame).
  examples::export_tum_sequence(scene, input, frames, dir, [&](int f, const Image<int, Host>& labels) {
    if (auto d = detector.detect(f, scene.timestamp(f))) detected.push_back(std::move(*d));
    Detections g;
    g.timestamp = scene.timestamp(f);
    const std::vector<int> l = labels.to_host();
    g.labels = Image<std::uint16_t, Host>::from_host(labels.width(), labels.height(),
                                                     std::vector<std::uint16_t>(l.begin(), l.end()));
    for (int k = 0; k < scene.object_count(); ++k) g.instances.push_back({k + 1, scene.object_class(k), 1.0});
    truth.push_back(std::move(g));
  });
  write_mask_directory((out / "masks").string(), detected);
  write_mask_directory((out / "masks_gt").string(), truth);
  create_output_directory((out / "groundtruth_objects").string());
  Json info;
  info["scene"] = input;
  info["frames"] = frames;
  info["det_every"] = dp.period;
  info["objects"] = Json::array();
  for (int k = 0; k < scene.object_count(); ++k) {
    Trajectory poses = scene.object_trajectory(k);
    poses.resize(std::size_t(frames));
    write_tum_trajectory((out / "groundtruth_objects" / (scene.object_name(k) + ".txt")).string(), poses);
    info["objects"].push_back(Json{{"name", scene.object_name(k)}, {"class", scene.object_class(k)}});
  }
  write_json_file((out / "scene.json").string(), info);
  write_text_file((out / "README.txt").string(),
                  "Made by `emfusion export` from the built-in scene " + input + " (" + std::to_string(frames) +
                      " frames): rendered noisy depth (no colour), the scene's exact camera and object "
                      "trajectories, the simulated detector's masks (masks/) and the scene's labels "
                      "(masks_gt/). Generated, not data: delete freely.\n");
  fmt::print("wrote {} frames of {} to {} ({} objects, {} detector frames)\n", frames, input, dir,
             scene.object_count(), detected.size());
}

void evaluate(const std::string& sequence, const std::string& output) {
  GroundTruth gt;
  if (const auto params = synthetic_params(sequence)) {
    const auto scene = sim::make_dynamic_scene<float>(*params);
    gt.camera = scene.camera_trajectory();
    for (int k = 0; k < scene.object_count(); ++k) gt.objects[scene.object_name(k)] = scene.object_trajectory(k);
  } else {
    const TumSequence seq = TumSequence::open(sequence);
    const auto camera = seq.ground_truth();
    if (!camera) throw std::runtime_error("'" + sequence + "' has no groundtruth.txt");
    gt.camera = *camera;
    for (auto& [name, traj] : seq.ground_truth_objects()) gt.objects[name] = traj;
  }
  const Trajectory est_cam = read_tum_trajectory((fs::path(output) / "camera.txt").string());
  std::map<int, Trajectory> est_objects;
  const std::string list = (fs::path(output) / "objects.txt").string();
  // Objects run.json says were merged into another are counted as that one.
  const std::string run_json = (fs::path(output) / "run.json").string();
  const std::vector<int> merged = fs::exists(run_json) ? read_merged_object_ids(run_json) : std::vector<int>{};
  if (fs::exists(list))
    for (const auto& e : read_object_list(list))
      if (std::find(merged.begin(), merged.end(), e.id) == merged.end())
        est_objects[e.id] = read_tum_trajectory((fs::path(output) / "objects" / (std::to_string(e.id) + ".txt")).string());
  Json json;
  json["sequence"] = sequence;
  json["output"] = output;
  print_evaluation(est_cam, est_objects, gt, &json);
  write_json_file((fs::path(output) / "eval.json").string(), json);
  // report.html: what cannot be read is said in the page and here, and the rest is written.
  std::vector<std::string> warnings;
  const std::string report = write_run_report(sequence, output, gt.camera, gt.objects, est_cam, est_objects, warnings);
  for (const std::string& w : warnings) fmt::print(stderr, "emfusion: warning: {}\n", w);
  fmt::print("wrote {}\n", report);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"emfusion: EM-Fusion dynamic object-level RGB-D SLAM"};
  app.require_subcommand(1);
  RunOptions o;
  auto* run_cmd = app.add_subcommand("run", "run the system on a sequence and write trajectories, objects and meshes");
  run_cmd
      ->add_option("input", o.input,
                   "synthetic:<scene>, a .klg log, a Co-Fusion folder (colour/, depth/) or a TUM-layout sequence "
                   "directory")
      ->required();
  run_cmd->add_option("--output,-o", o.output, "output directory")->required();
  run_cmd->add_option("--masks", o.masks, "mask directory (default: <input>/masks when present)");
  run_cmd->add_option("--calibration", o.calibration, "calibration file: fx fy cx cy width height");
  run_cmd->add_option("--intrinsics", o.intrinsics,
                      "camera: fr1, fr2, fr3, default (640x480) or fx,fy,cx,cy[,width,height] (not with "
                      "--calibration)");
  run_cmd
      ->add_option("--depth-scale", o.depth_scale, "depth value per metre (default 5000 for PNG depth, 1000 for .klg)")
      ->check(CLI::PositiveNumber);
  run_cmd->add_option("--backend", o.backend, "cpu or cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  run_cmd->add_option("--config", o.config, "parameter file: key = value per line")->check(CLI::ExistingFile);
  run_cmd->add_option("--set", o.overrides, "override a parameter: key=value (repeatable)");
  run_cmd->add_option("--max-frames", o.max_frames, "process at most N frames")->check(CLI::PositiveNumber);
  run_cmd->add_flag("--verbose,-v", o.verbose, "log object creation and deletion, refused frames and ignored detections");
  run_cmd
      ->add_option("--checkpoint-every", o.checkpoint_every,
                   "save the whole state to <output>/checkpoint.emfckpt every N frames and at the end")
      ->check(CLI::PositiveNumber);
  run_cmd->add_option("--resume", o.resume,
                      "go on from <dir>/checkpoint.emfckpt (same input and parameters as the run that saved it)");
  run_cmd->add_flag("--pictures", o.pictures,
                    "write per-frame segmentation and association pictures to <output>/pictures/");
  std::string eval_sequence, eval_output;
  auto* eval_cmd = app.add_subcommand("eval", "evaluate a run's outputs against a sequence's ground truth");
  eval_cmd->add_option("sequence", eval_sequence, "sequence directory or synthetic:<scene>")->required();
  eval_cmd->add_option("output", eval_output, "output directory of `emfusion run`")->required();
  std::string export_input, export_dir;
  int export_frames = 0;
  auto* export_cmd =
      app.add_subcommand("export", "write a built-in scene as a sequence folder: depth, ground truth, detector masks");
  export_cmd->add_option("scene", export_input, "synthetic:<scene>")->required();
  export_cmd->add_option("output", export_dir, "the folder to write")->required();
  export_cmd->add_option("--max-frames", export_frames, "at most N frames")->check(CLI::PositiveNumber);
  std::string mesh_checkpoint, mesh_output;
  auto* mesh_cmd = app.add_subcommand("mesh", "write the meshes of a checkpoint (no sequence needed)");
  mesh_cmd->add_option("checkpoint", mesh_checkpoint, "a checkpoint.emfckpt of `emfusion run --checkpoint-every`")
      ->required();
  mesh_cmd->add_option("--output,-o", mesh_output, "output directory (meshes go to <dir>/meshes/)")->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    if (*run_cmd) {
      examples::catch_interrupts();
      examples::with_backend(o.backend, [&](auto backend) { run<decltype(backend)>(o); });
      // Stopped by a signal (even one that came after the last frame): the
      // shell's convention, 128 + the signal's number.
      if (const int sig = examples::interrupt_signal()) return 128 + sig;
    } else if (*mesh_cmd) {
      mesh(mesh_checkpoint, mesh_output);
    } else if (*export_cmd) {
      export_scene(export_input, export_dir, export_frames);
    } else {
      evaluate(eval_sequence, eval_output);
    }
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "emfusion: error: {}\n", e.what());
    return 1;
  }
}
