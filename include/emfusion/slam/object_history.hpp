// What became of every object over a run, gathered from the FrameResults
// the system returns: when it was created, lost (deleted as not visible and
// kept for re-identification), found again (and how), given up (a lost object kept
// longer than lost_object_frames), relocalized (moved onto a detection after
// its tracking left it behind), merged into another model of the same
// object or absorbing one (merging.hpp) or deleted, with the rule that deleted it,
// and how its tracking went (frames tracked, refused, retried, started at
// the motion prediction). The app writes it to run.json and prints it.
#pragma once

#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"

namespace emfusion {

enum class ObjectEventKind { created, lost, found_again, given_up, deleted, relocalized, merged, absorbed };

inline const char* to_string(ObjectEventKind k) {
  switch (k) {
    case ObjectEventKind::created: return "created";
    case ObjectEventKind::lost: return "lost";
    case ObjectEventKind::found_again: return "found_again";
    case ObjectEventKind::given_up: return "given_up";
    case ObjectEventKind::deleted: return "deleted";
    case ObjectEventKind::relocalized: return "relocalized";
    case ObjectEventKind::merged: return "merged";
    case ObjectEventKind::absorbed: return "absorbed";
  }
  return "unknown";
}

struct ObjectEvent {
  int frame = 0;
  double timestamp = 0;
  ObjectEventKind kind = ObjectEventKind::created;
  DeletionReason reason = DeletionReason::none;  ///< for `deleted`: the rule
  /// For `merged`: the object it went on as; for `absorbed`: the object it took over.
  int other = 0;
  FoundBy by = FoundBy::detection;  ///< for `found_again`: how
};

/// One object's life.
struct ObjectHistory {
  int id = 0;
  std::vector<ObjectEvent> events;  ///< in frame order
  int tracked = 0;                  ///< frames its solve was accepted
  int refused = 0;                  ///< frames its solve ran and was refused (the pose stayed)
  int moved_on = 0;                 ///< frames it was hidden behind a nearer surface and moved on, not solved
  int retried = 0;                  ///< frames a first solve was refused and run again from the other start
  int from_prediction = 0;          ///< frames the solve taken started at the motion prediction
  /// Frames its solve, refused by the motion bound, was taken as the last
  /// of refused solves that agree (SystemParams::confirm_jump_frames).
  int confirmed = 0;
  /// Frames it was left at its solve's start because the frame saw through
  /// it at the solved pose (SystemParams::slide_seen_through_share).
  int kept_start = 0;
  /// Frames before its creation or return it was tracked back through
  /// (track_back_frames), all told.
  int tracked_back = 0;
};

/// Collects ObjectHistory from each frame: call add() after every
/// System::process (or after the stages of a frame of one's own loop).
class ObjectHistories {
 public:
  template <class S, Backend B>
  void add(const FrameResult& r, const Map<S, B>& map) {
    const auto event = [&](int id, ObjectEventKind kind, DeletionReason reason = DeletionReason::none,
                           int other = 0) {
      history(id).events.push_back({r.frame, r.timestamp, kind, reason, other});
    };
    for (const ObjectStatus& s : r.object_status) {
      ObjectHistory& h = history(s.id);
      if (s.tracking == TrackingOutcome::tracked) ++h.tracked;
      else if (s.tracking == TrackingOutcome::moved_on) ++h.moved_on;
      else if (s.tracking != TrackingOutcome::not_tracked) ++h.refused;
      h.retried += s.attempts > 1;
      h.from_prediction += s.tracking == TrackingOutcome::tracked && s.from_prediction;
      h.confirmed += s.tracking == TrackingOutcome::tracked && s.confirmed;
      h.kept_start += s.tracking == TrackingOutcome::tracked && s.kept_start;
    }
    for (int id : r.created) event(id, ObjectEventKind::created);
    for (std::size_t k = 0; k < r.reidentified.size(); ++k) {
      event(r.reidentified[k], ObjectEventKind::found_again);
      if (k < r.found_by.size()) history(r.reidentified[k]).events.back().by = r.found_by[k];
    }
    for (int id : r.relocalized) event(id, ObjectEventKind::relocalized);
    for (const TrackedBack& t : r.tracked_back) history(t.id).tracked_back += t.frames;
    std::vector<int> lost_now;
    for (const auto& l : map.lost) lost_now.push_back(l.object->id());
    for (int id : r.deleted) {
      const bool kept = std::find(lost_now.begin(), lost_now.end(), id) != lost_now.end();
      DeletionReason reason = DeletionReason::none;
      for (const ObjectRecord& rec : map.records)
        if (rec.id == id) reason = rec.reason;
      event(id, kept ? ObjectEventKind::lost : ObjectEventKind::deleted, reason);
    }
    for (const ObjectMerge& m : r.merged) {
      event(m.from, ObjectEventKind::merged, DeletionReason::merged, m.into);
      event(m.into, ObjectEventKind::absorbed, DeletionReason::none, m.from);
    }
    // Lost objects that left the lost list without being found again or merged.
    const auto merged = [&](int id) {
      return std::any_of(r.merged.begin(), r.merged.end(), [&](const ObjectMerge& m) { return m.from == id || m.into == id; });
    };
    for (int id : lost_) {
      const bool still = std::find(lost_now.begin(), lost_now.end(), id) != lost_now.end();
      const bool found = std::find(r.reidentified.begin(), r.reidentified.end(), id) != r.reidentified.end();
      if (!still && !found && !merged(id)) event(id, ObjectEventKind::given_up);
    }
    lost_ = std::move(lost_now);
  }

  /// Every object seen so far, by id.
  const std::map<int, ObjectHistory>& objects() const { return objects_; }

 private:
  ObjectHistory& history(int id) {
    ObjectHistory& h = objects_[id];
    h.id = id;
    return h;
  }
  std::map<int, ObjectHistory> objects_;
  std::vector<int> lost_;
};

}  // namespace emfusion
