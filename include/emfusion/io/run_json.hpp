// The parts of run.json (docs/io.md, "run.json") that come from library
// types: an object's history (slam/object_history.hpp) as one entry of
// run.json's "objects" array. JSON lives in io/ only: slam/ gathers the
// histories and never sees nlohmann-json.
#pragma once

#include <string>
#include <utility>

#include "emfusion/io/run_outputs.hpp"
#include "emfusion/slam/object_history.hpp"

namespace emfusion {

/// One entry of run.json's "objects": {"id", "class", "tracked_frames",
/// "refused_frames", "retried_frames", "from_prediction_frames", "events"},
/// each event {"event", "frame", "timestamp"} plus "rule" (the deletion
/// rule) for `lost` and `deleted`. A timestamp that is not finite is
/// written as null (json_text).
inline Json object_history_json(const ObjectHistory& history, const std::string& class_name) {
  Json object;
  object["id"] = history.id;
  object["class"] = class_name;
  object["tracked_frames"] = history.tracked;
  object["refused_frames"] = history.refused;
  object["retried_frames"] = history.retried;
  object["from_prediction_frames"] = history.from_prediction;
  Json& events = object["events"] = Json::array();
  for (const ObjectEvent& e : history.events) {
    Json event;
    event["event"] = to_string(e.kind);
    event["frame"] = e.frame;
    event["timestamp"] = e.timestamp;
    if (e.kind == ObjectEventKind::deleted || e.kind == ObjectEventKind::lost) event["rule"] = to_string(e.reason);
    events.push_back(std::move(event));
  }
  return object;
}

}  // namespace emfusion
