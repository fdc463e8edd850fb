// report.html of a run (`emfusion eval`, docs/evaluation.md "The run
// report"): gathers what the report shows from the run's output directory
// (frames.csv, objects.txt, pictures/) and from the trajectories against
// their ground truth, and writes the page (eval/report_html.hpp).
//
// What cannot be read does not stop the report: a missing or malformed
// frames.csv, a picture that cannot be read, an evaluation that fails
// (e.g. timestamps that match no ground truth) leave their section saying
// why, and the message is also returned in `warnings` for the caller to
// print. Only a report that cannot be written is an error.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <system_error>
#include <vector>

#include "emfusion/core/timed_pose.hpp"
#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/object_matching.hpp"
#include "emfusion/eval/report_html.hpp"
#include "emfusion/eval/rpe.hpp"
#include "emfusion/eval/trajectory.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/frame_log.hpp"
#include "emfusion/io/run_outputs.hpp"

namespace emfusion {

/// At most this many frames' pictures go into a report, evenly spread
/// over the run, and at most this many pictures per frame (segmentation,
/// then the background's and the objects' associations).
inline constexpr std::size_t report_picture_frames = 4;
inline constexpr std::size_t report_pictures_per_frame = 5;

namespace detail::run_report {

inline std::string fixed(double v, int decimals, const char* unit) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f%s", decimals, v, unit);
  return buffer;
}

/// The frames of <output>/pictures (segmentation_<frame>.png), and for each
/// the association pictures' model names.
inline std::map<std::size_t, std::vector<std::string>> picture_frames(const std::filesystem::path& dir) {
  std::map<std::size_t, std::vector<std::string>> frames;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return frames;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    const auto digits = [](const std::string& s) {
      return !s.empty() && s.find_first_not_of("0123456789") == std::string::npos;
    };
    // segmentation_<frame>.png
    if (name.size() > 13 + 4 && name.rfind("segmentation_", 0) == 0 && name.substr(name.size() - 4) == ".png" &&
        digits(name.substr(13, name.size() - 17)) && name.size() - 17 <= 9)
      frames[std::stoul(name.substr(13, name.size() - 17))];
  }
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    // association_<frame>_<model>.png
    if (name.rfind("association_", 0) != 0 || name.size() < 12 + 6 + 1 + 4 || name.substr(name.size() - 4) != ".png")
      continue;
    const std::string number = name.substr(12, 6);
    if (number.find_first_not_of("0123456789") != std::string::npos || name[18] != '_') continue;
    const auto it = frames.find(std::stoul(number));
    if (it != frames.end()) it->second.push_back(name.substr(19, name.size() - 19 - 4));
  }
  // background first, then the objects by id.
  for (auto& [frame, models] : frames)
    std::sort(models.begin(), models.end(), [](const std::string& a, const std::string& b) {
      const auto key = [](const std::string& m) {
        if (m == "background") return -1L;
        if (m.rfind("object_", 0) == 0) {
          try {
            return std::stol(m.substr(7));
          } catch (const std::exception&) {
          }
        }
        return 1L << 40;
      };
      return key(a) != key(b) ? key(a) < key(b) : a < b;
    });
  return frames;
}

}  // namespace detail::run_report

/// The report's data for the run in `output` of `sequence`.
inline eval::ReportData run_report_data(const std::string& sequence, const std::string& output,
                                        const Trajectory& gt_camera,
                                        const std::map<std::string, Trajectory>& gt_objects,
                                        const Trajectory& est_camera, const std::map<int, Trajectory>& est_objects,
                                        std::vector<std::string>& warnings) {
  namespace fs = std::filesystem;
  using detail::run_report::fixed;
  eval::ReportData d;
  d.sequence = sequence, d.output = output;
  d.title = "EM-Fusion run report: " + fs::path(sequence).filename().string();
  if (fs::path(sequence).filename().empty()) d.title = "EM-Fusion run report: " + sequence;
  const fs::path out(output);

  // frames.csv
  std::vector<FrameLogRow> rows;
  const std::string frames_path = (out / "frames.csv").string();
  std::error_code ec;
  if (!fs::exists(frames_path, ec)) {
    d.timings_problem =
        "'" + frames_path + "' is missing: the run was made by an emfusion that did not write it, or it was removed";
  } else {
    try {
      rows = read_frame_log(frames_path);
      if (rows.empty()) d.timings_problem = "'" + frames_path + "' has no frames";
    } catch (const std::exception& e) {
      d.timings_problem = std::string("could not read the per-frame figures: ") + e.what();
      warnings.push_back(d.timings_problem);
    }
  }
  // Time 0: the first frame of the run.
  double t0 = 0;
  if (!est_camera.empty())
    t0 = est_camera.front().timestamp;
  else if (!rows.empty())
    t0 = rows.front().timestamp;
  else if (!gt_camera.empty())
    t0 = gt_camera.front().timestamp;

  // Camera: ATE alignment, per-pose errors, RPE windows.
  if (est_camera.size() < 3) {
    d.camera_problem = "camera.txt has " + std::to_string(est_camera.size()) + " poses: at least 3 are needed";
  } else {
    try {
      const std::vector<eval::Match> matches = eval::associate(est_camera, gt_camera);
      std::vector<Vec3d> est, gt;
      for (const eval::Match& m : matches) {
        est.push_back(est_camera[m.est].pose.translation());
        gt.push_back(gt_camera[m.gt].pose.translation());
      }
      const eval::AteResult ate = eval::ate_of_positions(est, gt);
      for (std::size_t k = 0; k < matches.size(); ++k) {
        const Vec3d p = ate.T_gt_est * (est[k] * ate.scale);
        d.estimate.push_back({p[0], p[1], p[2]});
        d.ground_truth.push_back({gt[k][0], gt[k][1], gt[k][2]});
        d.error_time.push_back(est_camera[matches[k].est].timestamp - t0);
        d.error_m.push_back(norm(p - gt[k]));
      }
      d.summary.push_back({"camera ATE RMSE", fixed(100 * ate.rmse, 2, " cm") + " over " + std::to_string(ate.matched) +
                                                  " poses (max " + fixed(100 * ate.max, 2, " cm") + ")"});
    } catch (const std::exception& e) {
      d.camera_problem = std::string("no camera evaluation: ") + e.what();
      warnings.push_back(d.camera_problem);
    }
    if (d.camera_problem.empty()) {
      if (est_camera.back().timestamp - est_camera.front().timestamp < 1.0) {
        d.rpe_problem = "the run is shorter than 1 s: no RPE window";
      } else {
        try {
          const std::vector<eval::RpePair> pairs = eval::relative_pose_errors(est_camera, gt_camera);
          double sum = 0;
          for (const eval::RpePair& p : pairs) {
            d.rpe_time.push_back(p.start - t0);
            d.rpe_m.push_back(p.translation);
            sum += p.translation * p.translation;
          }
          d.summary.push_back({"camera RPE RMSE (1 s)", fixed(100 * std::sqrt(sum / double(pairs.size())), 2, " cm/s") +
                                                            " over " + std::to_string(pairs.size()) + " windows"});
        } catch (const std::exception& e) {
          d.rpe_problem = std::string("no RPE: ") + e.what();
        }
      }
    }
  }

  // Objects: ground-truth objects with their matched estimates, then the
  // estimates that match none.
  std::map<int, ObjectListEntry> listed;
  const std::string list_path = (out / "objects.txt").string();
  if (fs::exists(list_path, ec)) {
    try {
      for (const ObjectListEntry& e : read_object_list(list_path)) listed[e.id] = e;
    } catch (const std::exception& e) {
      d.objects_problem = e.what();
      warnings.push_back(d.objects_problem);
    }
  }
  const auto fill = [&](eval::ReportObject& r, int id) {
    const auto it = listed.find(id);
    if (it != listed.end()) {
      r.class_name = it->second.class_name;
      r.first_time = it->second.first_timestamp - t0, r.last_time = it->second.last_timestamp - t0;
    } else if (const auto t = est_objects.find(id); t != est_objects.end() && !t->second.empty()) {
      r.first_time = t->second.front().timestamp - t0, r.last_time = t->second.back().timestamp - t0;
    }
  };
  std::set<int> matched;
  if (!gt_objects.empty() && est_camera.size() >= 3 && d.camera_problem.empty()) {
    try {
      for (const eval::ObjectEvaluation& o : eval::evaluate_objects(est_camera, gt_camera, est_objects, gt_objects)) {
        eval::ReportObject r;
        r.name = o.name;
        for (const int id : o.estimates) {
          r.estimate += (r.estimate.empty() ? "" : ", ") + std::to_string(id);
          matched.insert(id);
        }
        r.evaluated = o.evaluated;
        if (o.primary >= 0) fill(r, o.primary);
        if (o.evaluated)
          r.ate_m = o.result.ate.rmse, r.coverage = o.result.coverage;
        else
          r.coverage = 0, r.problem = o.problem;
        if (o.estimates.size() > 1)
          r.problem += (r.problem.empty() ? "" : "; ") + std::string("evaluated: ") + std::to_string(o.primary) +
                       " (the most frames)";
        d.objects.push_back(r);
      }
    } catch (const std::exception& e) {
      d.objects_problem = std::string("no object evaluation: ") + e.what();
      warnings.push_back(d.objects_problem);
    }
  } else if (gt_objects.empty()) {
    d.objects_problem = "the sequence has no object ground truth: the run's objects are listed, not evaluated";
  }
  std::set<int> ids;
  for (const auto& [id, traj] : est_objects) ids.insert(id);
  for (const auto& [id, entry] : listed) ids.insert(id);
  for (const int id : ids) {
    if (matched.count(id)) continue;
    eval::ReportObject r;
    r.estimate = std::to_string(id);
    fill(r, id);
    r.problem = gt_objects.empty() ? "" : "matches no ground-truth object";
    d.objects.push_back(r);
  }
  std::size_t evaluated = 0;
  for (const eval::ReportObject& r : d.objects) evaluated += r.evaluated;
  d.summary.push_back({"objects", std::to_string(ids.size()) + " estimated, " + std::to_string(gt_objects.size()) +
                                      " in the ground truth, " + std::to_string(evaluated) + " evaluated"});

  // Timings and memory.
  if (!rows.empty()) {
    eval::ReportTimings& t = d.timings;
    t.stages.push_back({"total", {}});
    for (const FrameLogStage& s : frame_log_stages) t.stages.push_back({s.name, {}});
    double peak = 0, device_peak = NAN;
    for (const FrameLogRow& r : rows) {
      t.time.push_back(r.timestamp - t0);
      t.stages[0].second.push_back(r.times.total);
      for (std::size_t k = 0; k < std::size(frame_log_stages); ++k)
        t.stages[k + 1].second.push_back(r.times.*frame_log_stages[k].field);
      t.objects.push_back(r.objects);
      t.rss_mib.push_back(r.rss_mib);
      t.device_mib.push_back(r.device_mib ? *r.device_mib : NAN);
      if (std::isfinite(r.rss_mib)) peak = std::max(peak, r.rss_mib);
      if (r.device_mib) device_peak = std::isfinite(device_peak) ? std::max(device_peak, *r.device_mib) : *r.device_mib;
    }
    const auto [median, p90] = eval::detail::report::median_p90(t.stages[0].second);
    d.summary.insert(d.summary.begin(),
                     {"frames", std::to_string(rows.size()) + " (frames.csv), " + fixed(median, 1, " ms") +
                                    " per frame median, " + fixed(p90, 1, " ms") + " 90th percentile"});
    d.summary.push_back(
        {"memory",
         "resident " + fixed(peak, 0, " MiB") + " at most" +
             (std::isfinite(device_peak) ? ", device " + fixed(device_peak, 0, " MiB") + " at most" : std::string())});
  }

  // Pictures of up to report_picture_frames frames, evenly spread.
  const fs::path pictures = out / "pictures";
  const std::map<std::size_t, std::vector<std::string>> frames = detail::run_report::picture_frames(pictures);
  if (frames.empty()) {
    d.pictures_problem = "the run has no pictures ('" + pictures.string() + "' has no segmentation_<frame>.png)";
  } else {
    std::vector<std::size_t> all;
    for (const auto& entry : frames) all.push_back(entry.first);
    std::vector<std::size_t> chosen;
    const std::size_t n = std::min(report_picture_frames, all.size());
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t i = n == 1 ? 0 : std::size_t(std::lround(double(k) * double(all.size() - 1) / double(n - 1)));
      if (chosen.empty() || chosen.back() != all[i]) chosen.push_back(all[i]);
    }
    for (const std::size_t frame : chosen) {
      char number[24];
      std::snprintf(number, sizeof(number), "%06zu", frame);
      eval::ReportFrame f;
      f.title = "frame " + std::to_string(frame);
      std::vector<std::pair<std::string, std::string>> files{
          {"segmentation", "segmentation_" + std::string(number) + ".png"}};
      for (const std::string& model : frames.at(frame))
        files.push_back({"association: " + model, "association_" + std::string(number) + "_" + model + ".png"});
      if (files.size() > report_pictures_per_frame) files.resize(report_pictures_per_frame);
      for (const auto& [caption, file] : files) {
        try {
          f.pictures.push_back({caption, emfusion::detail::io::read_file((pictures / file).string(), "run report")});
        } catch (const std::exception& e) {
          warnings.push_back(e.what());
        }
      }
      if (!f.pictures.empty()) d.frames.push_back(std::move(f));
    }
  }
  return d;
}

/// Writes <output>/report.html (atomically: a temporary file renamed into
/// place) and returns its path.
inline std::string write_run_report(const std::string& sequence, const std::string& output, const Trajectory& gt_camera,
                                    const std::map<std::string, Trajectory>& gt_objects, const Trajectory& est_camera,
                                    const std::map<int, Trajectory>& est_objects, std::vector<std::string>& warnings) {
  const std::string path = (std::filesystem::path(output) / "report.html").string();
  write_text_file(path, eval::report_html(run_report_data(sequence, output, gt_camera, gt_objects, est_camera,
                                                          est_objects, warnings)));
  return path;
}

}  // namespace emfusion
