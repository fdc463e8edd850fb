// The parts of run.json (docs/io.md, "run.json") that come from library
// types: an object's history (slam/object_history.hpp) as one entry of
// run.json's "objects" array, and the merged ids read back from one. JSON lives in io/ only: slam/ gathers the
// histories and never sees nlohmann-json.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "emfusion/slam/object_history.hpp"

namespace emfusion {

/// One entry of run.json's "objects": {"id", "class", "tracked_frames",
/// "refused_frames", "moved_on_frames", "retried_frames", "from_prediction_frames",
/// "confirmed_frames", "tracked_back_frames", "events"},
/// each event {"event", "frame", "timestamp"} plus "rule" (the deletion
/// rule) for `lost` and `deleted`, "by" ("detection", "in_view" or
/// "unexplained": how it was found) for `found_again`, "into" (the id it goes on as) for
/// `merged` and "from" (the id it took over) for `absorbed`. A timestamp that is not finite is
/// written as null (json_text).
inline Json object_history_json(const ObjectHistory& history, const std::string& class_name) {
  Json object;
  object["id"] = history.id;
  object["class"] = class_name;
  object["tracked_frames"] = history.tracked;
  object["refused_frames"] = history.refused;
  object["moved_on_frames"] = history.moved_on;
  object["retried_frames"] = history.retried;
  object["from_prediction_frames"] = history.from_prediction;
  object["confirmed_frames"] = history.confirmed;
  object["kept_start_frames"] = history.kept_start;
  object["tracked_back_frames"] = history.tracked_back;
  Json& events = object["events"] = Json::array();
  for (const ObjectEvent& e : history.events) {
    Json event;
    event["event"] = to_string(e.kind);
    event["frame"] = e.frame;
    event["timestamp"] = e.timestamp;
    if (e.kind == ObjectEventKind::deleted || e.kind == ObjectEventKind::lost) event["rule"] = to_string(e.reason);
    if (e.kind == ObjectEventKind::found_again) event["by"] = to_string(e.by);
    if (e.kind == ObjectEventKind::merged) event["into"] = e.other;
    if (e.kind == ObjectEventKind::absorbed) event["from"] = e.other;
    events.push_back(std::move(event));
  }
  return object;
}

/// The ids that a run.json (`path`) says were merged into another object
/// (an event "merged"): their poses are in that object's trajectory too, so
/// an evaluation counts each object once. Throws std::runtime_error naming
/// the file when it cannot be read, is not JSON, or its "objects" entries
/// are not as object_history_json writes them.
inline std::vector<int> read_merged_object_ids(const std::string& path) {
  const std::string text = detail::io::read_file(path, "read_merged_object_ids");
  const auto bad = [&](const std::string& what) {
    detail::io::fail("read_merged_object_ids", path, what);
  };
  const Json json = Json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded()) bad("not valid JSON");
  if (!json.is_object()) bad("not a JSON object");
  std::vector<int> ids;
  if (!json.contains("objects")) return ids;
  const Json& objects = json["objects"];
  if (!objects.is_array()) bad("\"objects\" is not an array");
  for (const Json& o : objects) {
    if (!o.is_object() || !o.contains("id") || !o["id"].is_number_integer()) bad("an object without an integer \"id\"");
    if (!o.contains("events")) continue;
    if (!o["events"].is_array()) bad("object " + o["id"].dump() + ": \"events\" is not an array");
    for (const Json& e : o["events"])
      if (e.is_object() && e.contains("event") && e["event"] == "merged") ids.push_back(o["id"].get<int>());
  }
  return ids;
}

}  // namespace emfusion
