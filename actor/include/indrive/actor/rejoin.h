// When a waiting actor or evaluator replaces its DDS participant (training_actor.cc and
// evaluator.cc say why it does): after actor.rejoin_after_s without word of the learner, then
// after twice as long for each replacement that heard nothing either, up to actor.rejoin_max_s.
// A process started long before its learner (an evaluator left waiting on another host) so
// replaces its participant a few times an hour instead of every 20 s, each time discovered
// afresh by every participant of the domain; once the learner is heard the wait is the short
// one again, so a stalled handshake with a learner that is there is still retried soon.
#pragma once

namespace indrive::actor {

class RejoinSchedule {
 public:
  // after_s <= 0: never replace. max_s below after_s is taken as after_s (no growth).
  RejoinSchedule(double after_s, double max_s);

  bool enabled() const { return after_s_ > 0.0; }
  // Seconds of silence (and of the current participant's life) before the next replacement.
  double wait_s() const;
  // A participant was replaced without the learner having been heard since the last one.
  void replaced() { ++unanswered_; }
  // The learner was heard: the next wait is after_s again.
  void heard() { unanswered_ = 0; }
  // Replacements in a row that heard nothing.
  int unanswered() const { return unanswered_; }

 private:
  double after_s_;
  double max_s_;
  int unanswered_ = 0;
};

}  // namespace indrive::actor
