// ObjectHistories (slam/object_history.hpp): the events and tracking counts
// of each object, gathered from hand-made FrameResults and a map's lost
// list and records.
#include <memory>
#include <string>

#include "emfusion/slam/object_history.hpp"
#include "support/catch.hpp"

using namespace emfusion;

namespace {
using S = float;
std::unique_ptr<ObjectModel<S, Host>> object(int id) {
  return std::make_unique<ObjectModel<S, Host>>(id, "cup", SE3<S>::identity(), 8, S(0.01), S(10));
}
FrameResult frame(int f) {
  FrameResult r;
  r.frame = f;
  r.timestamp = f / 30.0;
  return r;
}
ObjectStatus status(int id, TrackingOutcome outcome, int attempts, bool from_prediction) {
  ObjectStatus s;
  s.id = id;
  s.tracking = outcome;
  s.attempts = attempts;
  s.from_prediction = from_prediction;
  return s;
}
}  // namespace

TEST_CASE("Object histories: created, tracked, retried, lost, found again, given up, deleted", "[slam]") {
  SystemParams<S> params;
  params.background_voxels = 8;
  Map<S, Host> map(params);
  map.records = {ObjectRecord{}, ObjectRecord{}};
  map.records[0].id = 1, map.records[1].id = 2;
  ObjectHistories h;

  FrameResult r = frame(0);
  r.created = {1, 2};
  r.tracked_back = {{1, 4}};  // its trajectory holds 4 frames before this one
  h.add(r, map);
  r = frame(1);
  r.object_status = {status(1, TrackingOutcome::tracked, 2, true), status(2, TrackingOutcome::jump_rejected, 2, false)};
  h.add(r, map);
  r = frame(1);  // object 2 hidden: moved on, neither tracked nor refused
  r.object_status = {status(2, TrackingOutcome::moved_on, 1, false)};
  h.add(r, map);
  r = frame(1);  // object 2's refused solve taken as confirmed (confirm_jump_frames): tracked
  r.object_status = {status(2, TrackingOutcome::tracked, 1, false)};
  r.object_status[0].confirmed = true;
  h.add(r, map);
  // Object 1 is deleted as not visible and kept as lost; 2 by the existence rule.
  r = frame(2);
  r.deleted = {1, 2};
  map.records[0].reason = DeletionReason::not_visible, map.records[1].reason = DeletionReason::existence;
  map.lost.push_back(LostObject<S, Host>{object(1), 2});
  h.add(r, map);
  r = frame(3);
  r.found_again(1, FoundBy::in_view);
  r.tracked_back = {{1, 6}};  // ... and tracked back 6 frames (4 when it was created: 10 in all)
  CHECK(r.reidentified == std::vector<int>{1});
  CHECK(r.found_by == std::vector<FoundBy>{FoundBy::in_view});
  map.lost.clear();
  h.add(r, map);
  r = frame(4);
  r.deleted = {1};
  map.lost.push_back(LostObject<S, Host>{object(1), 4});
  h.add(r, map);
  r = frame(5);  // kept longer than lost_object_frames: gone without a report of its own
  map.lost.clear();
  h.add(r, map);

  REQUIRE(h.objects().size() == 2);
  const ObjectHistory& a = h.objects().at(1);
  const ObjectHistory& b = h.objects().at(2);
  CHECK(a.tracked == 1);
  CHECK(a.retried == 1);
  CHECK(a.from_prediction == 1);
  CHECK(a.confirmed == 0);
  CHECK(a.tracked_back == 10);
  CHECK(b.tracked_back == 0);
  CHECK(b.refused == 1);
  CHECK(b.moved_on == 1);
  CHECK(b.tracked == 1);
  CHECK(b.confirmed == 1);
  CHECK(b.retried == 1);
  REQUIRE(a.events.size() == 5);
  CHECK(a.events[0].kind == ObjectEventKind::created);
  CHECK(a.events[1].kind == ObjectEventKind::lost);
  CHECK(a.events[1].reason == DeletionReason::not_visible);
  CHECK(a.events[2].kind == ObjectEventKind::found_again);
  CHECK(a.events[2].frame == 3);
  CHECK(a.events[2].by == FoundBy::in_view);
  CHECK(a.events[3].kind == ObjectEventKind::lost);
  CHECK(a.events[4].kind == ObjectEventKind::given_up);
  CHECK(a.events[4].frame == 5);
  REQUIRE(b.events.size() == 2);
  CHECK(b.events[1].kind == ObjectEventKind::deleted);
  CHECK(b.events[1].reason == DeletionReason::existence);
  CHECK(std::string(to_string(ObjectEventKind::found_again)) == "found_again");
}

TEST_CASE("Object histories: a merge ends one id and the other goes on; a lost one merged is not given up",
          "[slam]") {
  SystemParams<S> params;
  params.background_voxels = 8;
  Map<S, Host> map(params);
  map.records = {ObjectRecord{}, ObjectRecord{}};
  map.records[0].id = 1, map.records[1].id = 2;
  ObjectHistories h;
  FrameResult r = frame(0);
  r.created = {1};
  h.add(r, map);
  r = frame(1);  // 1 lost, then 2 made from the same object
  r.deleted = {1};
  map.records[0].reason = DeletionReason::not_visible;
  map.lost.push_back(LostObject<S, Host>{object(1), 1});
  h.add(r, map);
  r = frame(2);
  r.created = {2};
  h.add(r, map);
  r = frame(6);  // found to be one: 1 takes 2 over and leaves the lost list
  r.merged = {ObjectMerge{2, 1}};
  map.lost.clear();
  h.add(r, map);

  const ObjectHistory& a = h.objects().at(1);
  const ObjectHistory& b = h.objects().at(2);
  REQUIRE(a.events.size() == 3);
  CHECK(a.events[2].kind == ObjectEventKind::absorbed);
  CHECK(a.events[2].other == 2);
  CHECK(a.events[2].frame == 6);
  REQUIRE(b.events.size() == 2);
  CHECK(b.events[1].kind == ObjectEventKind::merged);
  CHECK(b.events[1].other == 1);
  CHECK(b.events[1].reason == DeletionReason::merged);
  CHECK(std::string(to_string(ObjectEventKind::merged)) == "merged");
  CHECK(std::string(to_string(DeletionReason::merged)) == "merged");
}
