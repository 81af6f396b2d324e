#include "indrive/actor/rejoin.h"

#include <algorithm>
#include <cmath>

namespace indrive::actor {

RejoinSchedule::RejoinSchedule(double after_s, double max_s)
    : after_s_(after_s), max_s_(std::max(after_s, max_s)) {}

double RejoinSchedule::wait_s() const {
  // 2^unanswered overflows nothing: the exponent is capped well before a double's range ends.
  const double grown = after_s_ * std::exp2(std::min(unanswered_, 60));
  return std::min(grown, max_s_);
}

}  // namespace indrive::actor
