// run.json, eval.json and the benchmarks' JSON through nlohmann-json
// (io/run_outputs.hpp, io/run_json.hpp): what is written parses back with
// the keys in the order they were set, numbers that are not finite become
// null, and the layout is the one tests/app/stopped_run.sh reads line by line.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "emfusion/io/run_json.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::ScratchDir;

namespace {

/// The keys of a JSON object, in the order the text holds them.
std::vector<std::string> keys_of(const Json& object) {
  std::vector<std::string> keys;
  for (const auto& item : object.items()) keys.push_back(item.key());
  return keys;
}

}  // namespace

TEST_CASE("run.json written through nlohmann-json parses back with its keys in order and NaN as null", "[io]") {
  ScratchDir dir;
  // A run.json as the app writes it when a run was interrupted before its
  // first frame: no last timestamp (NaN), settings as strings.
  Json run;
  run["input"] = "synthetic:room-small";
  run["backend"] = "cpu";
  run["detector"] = "simulated";
  run["status"] = "interrupted";
  run["frames"] = std::size_t(0);
  run["frames_requested"] = std::size_t(3);
  run["signal"] = "SIGINT";
  run["last_frame"] = -1LL;
  run["last_timestamp"] = std::numeric_limits<double>::quiet_NaN();
  run["objects_created"] = std::size_t(0);
  Json& settings = run["settings"] = Json::object();
  settings["alpha"] = "0.5";
  settings["static_classes"] = "person,tv";
  Json& timings = run["timings_ms"] = Json::object();
  timings["total"]["median"] = 12.5;
  timings["total"]["p90"] = std::numeric_limits<double>::infinity();
  run["objects"] = Json::array();  // no object: an empty array, not null
  const std::string path = dir.file("run.json");
  write_json_file(path, run);

  const std::string text = emfusion::test::read_bytes(path);
  CHECK(text == json_text(run));
  CHECK(text.back() == '\n');
  // One member per line at two spaces: the layout the shell tests grep.
  CHECK(contains(text, "\n  \"status\": \"interrupted\",\n"));
  CHECK(contains(text, "\n  \"frames\": 0,\n"));
  CHECK(contains(text, "\n  \"last_frame\": -1,\n"));
  CHECK(contains(text, "\n  \"last_timestamp\": null,\n"));

  const nlohmann::json back = nlohmann::json::parse(text);  // throws on invalid JSON
  REQUIRE(back.is_object());
  CHECK(back.at("status").get<std::string>() == "interrupted");
  CHECK(back.at("frames").get<long long>() == 0);
  CHECK(back.at("frames_requested").get<long long>() == 3);
  CHECK(back.at("last_frame").get<long long>() == -1);
  CHECK(back.at("last_timestamp").is_null());
  CHECK(back.at("settings").at("alpha").get<std::string>() == "0.5");
  CHECK(back.at("timings_ms").at("total").at("median").get<double>() == 12.5);
  CHECK(back.at("timings_ms").at("total").at("p90").is_null());
  CHECK(back.at("objects").is_array());
  CHECK(back.at("objects").empty());
  // The order the program set the keys in, not sorted.
  const Json ordered = Json::parse(text);
  CHECK(keys_of(ordered) == std::vector<std::string>{"input", "backend", "detector", "status", "frames",
                                                     "frames_requested", "signal", "last_frame", "last_timestamp",
                                                     "objects_created", "settings", "timings_ms", "objects"});
}

TEST_CASE("eval.json: camera and per-object results, an object without a result as null", "[io]") {
  ScratchDir dir;
  Json eval;
  eval["sequence"] = "synthetic:room-small";
  eval["output"] = "out/room \"small\"\n";  // quotes and a newline are escaped
  Json& camera = eval["camera"] = Json::object();
  camera["ate_rmse_m"] = 0.0123;
  camera["poses"] = std::size_t(150);
  camera["rpe_rmse_m_per_s"] = std::nan("");  // a run shorter than 1 s
  Json& objects = eval["objects"] = Json::object();
  Json& cup = objects["cup"] = Json::object();
  cup["estimate"] = 3;
  cup["evaluated"] = true;
  cup["ate_rmse_m"] = 0.004;
  cup["coverage"] = 0.9;
  Json& chair = objects["chair"] = Json::object();
  chair["estimate"] = -1;
  chair["evaluated"] = false;
  chair["ate_rmse_m"] = std::nan("");
  chair["coverage"] = 0.0;
  const std::string path = dir.file("eval.json");
  write_json_file(path, eval);

  const nlohmann::json back = nlohmann::json::parse(emfusion::test::read_bytes(path));
  CHECK(back.at("output").get<std::string>() == "out/room \"small\"\n");
  CHECK(back.at("camera").at("ate_rmse_m").get<double>() == 0.0123);  // shortest round trip: exact
  CHECK(back.at("camera").at("poses").get<long long>() == 150);
  CHECK(back.at("camera").at("rpe_rmse_m_per_s").is_null());
  CHECK(back.at("objects").at("cup").at("evaluated").get<bool>());
  CHECK(back.at("objects").at("cup").at("coverage").get<double>() == 0.9);
  CHECK_FALSE(back.at("objects").at("chair").at("evaluated").get<bool>());
  CHECK(back.at("objects").at("chair").at("ate_rmse_m").is_null());
  // Objects in the order evaluated (cup first), not sorted by name.
  const Json ordered = Json::parse(emfusion::test::read_bytes(path));
  CHECK(keys_of(ordered.at("objects")) == std::vector<std::string>{"cup", "chair"});
}

TEST_CASE("run.json's object histories: counts, events and the deletion rule", "[io]") {
  ObjectHistory h;
  h.id = 7;
  h.tracked = 40, h.refused = 2, h.moved_on = 3, h.retried = 1, h.from_prediction = 5, h.confirmed = 4;
  h.tracked_back = 9, h.kept_start = 6;
  h.events = {{12, 0.4, ObjectEventKind::created, DeletionReason::none},
              {30, 1.0, ObjectEventKind::lost, DeletionReason::not_visible},
              {45, 1.5, ObjectEventKind::found_again, DeletionReason::none, 0, FoundBy::unexplained},
              {60, std::nan(""), ObjectEventKind::deleted, DeletionReason::not_visible}};
  const nlohmann::json back = nlohmann::json::parse(json_text(object_history_json(h, "cup")));
  CHECK(back.at("id").get<long long>() == 7);
  CHECK(back.at("class").get<std::string>() == "cup");
  CHECK(back.at("tracked_frames").get<long long>() == 40);
  CHECK(back.at("refused_frames").get<long long>() == 2);
  CHECK(back.at("moved_on_frames").get<long long>() == 3);
  CHECK(back.at("retried_frames").get<long long>() == 1);
  CHECK(back.at("from_prediction_frames").get<long long>() == 5);
  CHECK(back.at("confirmed_frames").get<long long>() == 4);
  CHECK(back.at("kept_start_frames").get<long long>() == 6);
  CHECK(back.at("tracked_back_frames").get<long long>() == 9);
  const nlohmann::json& events = back.at("events");
  REQUIRE(events.size() == 4);
  CHECK(events[0].at("event").get<std::string>() == "created");
  CHECK(events[0].at("frame").get<long long>() == 12);
  CHECK(events[0].at("timestamp").get<double>() == 0.4);
  CHECK_FALSE(events[0].contains("rule"));  // only lost and deleted say why
  CHECK(events[1].at("event").get<std::string>() == "lost");
  CHECK(events[1].at("rule").get<std::string>() == to_string(DeletionReason::not_visible));
  CHECK(events[2].at("event").get<std::string>() == "found_again");
  CHECK_FALSE(events[2].contains("rule"));
  CHECK(events[2].at("by").get<std::string>() == "unexplained");
  CHECK_FALSE(events[1].contains("by"));  // only found_again says how
  CHECK(events[3].at("event").get<std::string>() == "deleted");
  CHECK(events[3].at("timestamp").is_null());
  // An object with no events still has an (empty) array.
  const nlohmann::json empty = nlohmann::json::parse(json_text(object_history_json(ObjectHistory{}, "?")));
  CHECK(empty.at("events").is_array());
  CHECK(empty.at("events").empty());
}

TEST_CASE("run.json: a merge says into which object; the merged ids read back; bad files are named", "[io]") {
  ObjectHistory a, b;
  a.id = 1, b.id = 4;
  a.events = {{0, 0.0, ObjectEventKind::created, DeletionReason::none},
              {90, 3.0, ObjectEventKind::absorbed, DeletionReason::none, 4}};
  b.events = {{40, 1.3, ObjectEventKind::created, DeletionReason::none},
              {90, 3.0, ObjectEventKind::merged, DeletionReason::merged, 1}};
  const Json ja = object_history_json(a, "cup"), jb = object_history_json(b, "cup");
  const nlohmann::json back_a = nlohmann::json::parse(json_text(ja)), back_b = nlohmann::json::parse(json_text(jb));
  CHECK(back_a.at("events")[1].at("event").get<std::string>() == "absorbed");
  CHECK(back_a.at("events")[1].at("from").get<int>() == 4);
  CHECK(back_b.at("events")[1].at("event").get<std::string>() == "merged");
  CHECK(back_b.at("events")[1].at("into").get<int>() == 1);
  CHECK_FALSE(back_b.at("events")[1].contains("from"));

  ScratchDir dir;
  Json run;
  run["frames"] = 100;
  run["objects"] = Json::array({ja, jb});
  CHECK(read_merged_object_ids(dir.write("run.json", json_text(run))) == std::vector<int>{4});
  CHECK(read_merged_object_ids(dir.write("none.json", "{\"frames\": 3}")).empty());  // no objects: none merged
  const auto error = [&](const std::string& name, const std::string& text) {
    return error_of([&] { read_merged_object_ids(dir.write(name, text)); });
  };
  CHECK(contains(error("cut.json", "{\"objects\": [{\"id\": 1, "), "cut.json"));
  CHECK(contains(error("cut.json", "{\"objects\": [{\"id\": 1, "), "not valid JSON"));
  CHECK(contains(error("array.json", "[1, 2]"), "not a JSON object"));
  CHECK(contains(error("objects.json", "{\"objects\": 3}"), "\"objects\" is not an array"));
  CHECK(contains(error("id.json", "{\"objects\": [{\"id\": \"x\"}]}"), "integer \"id\""));
  CHECK(contains(error("events.json", "{\"objects\": [{\"id\": 2, \"events\": {}}]}"), "object 2"));
  CHECK(contains(error_of([&] { read_merged_object_ids(dir.file("missing.json")); }), "missing.json"));
}

TEST_CASE("JSON text: bytes that are not UTF-8 are replaced, not fatal; a bad path names itself", "[io]") {
  Json j;
  j["input"] = std::string("seq-\xff\xfe");  // a path from a filesystem of another encoding
  const nlohmann::json back = nlohmann::json::parse(json_text(j));
  CHECK(back.at("input").get<std::string>() == "seq-\xEF\xBF\xBD\xEF\xBF\xBD");  // two U+FFFD
  CHECK(contains(error_of([] { write_json_file("/nonexistent-emfusion-dir/run.json", Json::object()); }),
                 "/nonexistent-emfusion-dir/run.json"));
}
