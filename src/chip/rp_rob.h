#pragma once
// RP-ROB, the ray-packet reordering buffer (paper Sections III-B, IV-D, Fig. 13).
//
// The RP-ROB holds placeholders for candidate RPs (CRPs) that the CTU found to
// be inside a non-empty coarse voxel (CV), and hands them to the FTU clustered
// by CV tag (CCRPs). It has `entries` entries of `entry_depth` placeholders.
// Entries are labelled dynamically: an empty entry takes the tag of the first
// CRP put in it, a CV with many CRPs may occupy several entries, and an entry
// whose last placeholder retires becomes empty and unlabelled again.
//
// A placeholder is either ready (waiting in its entry, first in first out) or
// in flight (scheduled to the FTU and not yet back). Operations:
//   insert(rp, tag)  a new CRP. Goes to an entry labelled `tag` that has room,
//                    the most occupied one first; else to an empty entry,
//                    which is labelled `tag`; else it is refused (the CTU
//                    stalls). The recent-tags recorder (LRU) notes `tag`.
//   schedule()       the next CCRP for the FTU. While the current tag has
//                    ready placeholders, the entry of that tag with the most
//                    free room is served. While the current tag still has
//                    placeholders in flight, nothing is scheduled. When all of
//                    the current tag's CCRPs have retired, the tag switches:
//                    among entries with ready CCRPs, those whose tag is in the
//                    recent-tags recorder are preferred and of them the one
//                    holding the fewest CCRPs is served; with no recorder hit,
//                    the entry holding the most CCRPs is served (an
//                    assumption: most reuse per MLP load). Ties go to the
//                    lowest entry index. This is the paper's rule
//                    (TagSwitchRule::Paper); TagSwitchRule::Fullest ignores
//                    the recorder and serves the entry holding the most ready
//                    CCRPs (the most batches per MLP load). With
//                    `switch_when_idle`, the tag also switches as soon as the
//                    current tag has no ready CCRP left (its CCRPs in flight
//                    come back to their entries and wait for the tag's next
//                    turn), instead of waiting until they have all retired.
//   reschedule(rp)   an in-flight CCRP goes back to its entry, ready (fine
//                    voxel transition: more samples in the same CV).
//   retire(rp)       an in-flight CCRP leaves (CV transition or termination);
//                    its placeholder is released.
// With reordering switched off, tags are ignored: a CRP goes to the first entry
// with room and schedule() serves the oldest ready placeholder of all entries
// (insertion and reschedule order), as a plain FIFO would.
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

namespace edrnr::chip {

// How schedule() picks the next CV tag when the current one is done.
enum class TagSwitchRule {
  Paper,    // recent-tags recorder hits first, the fewest CCRPs among them (Section IV-D)
  Fullest,  // the entry with the most ready CCRPs
};
// "paper", "fullest".
const char* tag_switch_rule_name(TagSwitchRule r);
// Parses a rule name; throws Error naming `field` and the accepted names.
TagSwitchRule parse_tag_switch_rule(const std::string& text, const std::string& field);

struct RpRobConfig {
  int entries = 16;
  int entry_depth = 4;
  int recent_tags = 4;  // size of the LRU recent-tags recorder
  bool reorder = true;
  TagSwitchRule tag_switch = TagSwitchRule::Paper;
  bool switch_when_idle = false;  // false: the paper's rule (switch once the tag's CCRPs have all retired)
  bool operator==(const RpRobConfig&) const = default;
};

struct RpRobCounters {
  uint64_t inserts = 0;
  uint64_t insert_refusals = 0;  // insert() calls that found no room
  uint64_t schedules = 0;
  uint64_t tag_runs = 0;  // maximal runs of consecutive schedules with one tag
  uint64_t reschedules = 0;
  uint64_t retires = 0;
  uint64_t recorder_hits = 0;  // tag switches decided by the recent-tags recorder
  uint64_t peak_entries_used = 0;
};

struct ScheduledRp {
  uint32_t rp = 0;   // RP pointer
  uint32_t tag = 0;  // CV tag
  int entry = 0;
};

class RpRob {
 public:
  // Throws Error if a size is not positive.
  explicit RpRob(const RpRobConfig& config);

  bool insert(uint32_t rp, uint32_t tag) {
    if (insert_known_refused(rp, tag)) {
      ++counters_.insert_refusals;  // no entry's count changed since the same insert was refused
      return false;
    }
    return insert_scan(rp, tag);
  }
  std::optional<ScheduledRp> schedule() {
    ScheduledRp s;
    if (!schedule(s)) return std::nullopt;
    return s;
  }
  // The same, into `out`: true when an RP was scheduled.
  bool schedule(ScheduledRp& out) {
    if (nothing_version_ == version_) return false;  // nothing changed since the last empty answer
    if (schedule_scan(out)) return true;
    nothing_version_ = version_;
    return false;
  }
  void reschedule(uint32_t rp);  // throws std::logic_error unless rp is in flight
  void retire(uint32_t rp);      // throws std::logic_error unless rp is in flight

  // Observers.
  int entries() const { return int(entries_.size()); }
  bool entry_labelled(int e) const { return entries_[size_t(e)].count > 0; }
  uint32_t entry_tag(int e) const { return entries_[size_t(e)].tag; }
  int entry_count(int e) const { return entries_[size_t(e)].count; }  // placeholders, ready + in flight
  int entry_ready(int e) const { return entries_[size_t(e)].ready; }
  size_t placeholders() const { return held_; }
  bool empty() const { return held_ == 0; }
  std::optional<uint32_t> current_tag() const {
    return has_current_ ? std::optional<uint32_t>(current_) : std::nullopt;
  }
  // Tags in the recent-tags recorder, most recent first.
  const std::deque<uint32_t>& recent_tags() const { return recent_; }
  const RpRobCounters& counters() const { return counters_; }

  // For a simulator that skips cycles in which nothing changes:
  // whether schedule() would return nothing without looking (it did so and
  // nothing that decides it changed since) ...
  bool schedule_known_empty() const { return nothing_version_ == version_; }
  // ... whether insert(rp, tag) would be refused without looking ...
  bool insert_known_refused(uint32_t rp, uint32_t tag) const {
    return refused_version_ == capacity_version_ && refused_rp_ == rp && refused_tag_ == tag;
  }
  // ... and the refused insert asked again `times` times in such cycles.
  void repeat_refused_insert(uint64_t times) { counters_.insert_refusals += times; }

 private:
  struct Ready {
    uint32_t rp;
    uint32_t tag;
    uint64_t stamp;  // insertion / reschedule order
  };
  struct Entry {
    uint32_t tag = 0;
    int count = 0;
    int ready = 0;  // placeholders ready (in the entry's queue)
  };
  struct Place {
    int entry = 0;
    uint32_t tag = 0;
    bool in_flight = false;
    bool held = false;  // the RP has a placeholder
  };

  void note_recent(uint32_t tag);
  bool in_recent(uint32_t tag) const;
  ScheduledRp pop(int e);
  bool schedule_scan(ScheduledRp& out);         // schedule() without the memo
  bool insert_scan(uint32_t rp, uint32_t tag);  // insert() without the memo
  Place& in_flight_place(uint32_t rp, const char* op);

  RpRobConfig config_;
  std::vector<Entry> entries_;             // compact, for the scans
  std::vector<std::deque<Ready>> queues_;  // each entry's ready placeholders, oldest first
  std::vector<Place> where_;               // by RP pointer
  size_t held_ = 0;                        // RPs with a placeholder
  uint64_t entries_used_ = 0;              // entries holding a placeholder (count > 0)
  std::deque<uint32_t> recent_;
  bool has_current_ = false;
  uint32_t current_ = 0;
  // Every change of the entries, the recorder or the current tag bumps
  // version_. A refused insert, or a schedule() with nothing to give, is
  // answered the same way while the version stays (the CTU and the FTU ask
  // again every cycle they wait), without scanning the entries again.
  uint64_t version_ = 0;
  // Whether an insert is refused depends on the entries' counts and tags
  // only, which change when an RP is inserted or retires: those bump
  // capacity_version_ (a schedule or a reschedule does not).
  uint64_t capacity_version_ = 0;
  uint64_t refused_version_ = ~uint64_t(0);  // insert(refused_rp_, refused_tag_) was refused at this capacity_version_
  uint32_t refused_rp_ = 0, refused_tag_ = 0;
  uint64_t nothing_version_ = ~uint64_t(0);  // schedule() had nothing to give then
  bool waiting_ = false;                     // the last scan gave nothing while the current tag's CCRPs were in flight
  bool has_last_scheduled_ = false;
  uint32_t last_scheduled_ = 0;
  uint64_t stamp_ = 0;
  RpRobCounters counters_;
};

}  // namespace edrnr::chip
