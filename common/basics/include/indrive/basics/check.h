// Invariant checks: a broken invariant is a bug, so it aborts with file, line and a message.
//
//   INDRIVE_CHECK(a.size() == b.size()) << "shapes " << a.size() << " vs " << b.size();
//   INDRIVE_CHECK_EQ(rows, cols) << "matrix must be square";
//
// Failures at a boundary (files, SUMO, DDS, user input) are not invariants: throw a typed
// exception with a message that says what to do instead.
#pragma once

#include <sstream>

namespace indrive::detail {

// Streams a message, then prints it and aborts in its destructor.
class CheckFailure {
 public:
  CheckFailure(const char* file, int line, const char* condition);
  [[noreturn]] ~CheckFailure();
  template <typename T>
  CheckFailure& operator<<(const T& value) {
    stream_ << value;
    return *this;
  }

 private:
  std::ostringstream stream_;
};

}  // namespace indrive::detail

#define INDRIVE_CHECK(condition) \
  if (condition) {               \
  } else                         \
    ::indrive::detail::CheckFailure(__FILE__, __LINE__, #condition)

#define INDRIVE_CHECK_EQ(a, b) \
  INDRIVE_CHECK((a) == (b)) << #a " = " << (a) << ", " #b " = " << (b) << ": "
#define INDRIVE_CHECK_LT(a, b) \
  INDRIVE_CHECK((a) < (b)) << #a " = " << (a) << ", " #b " = " << (b) << ": "
#define INDRIVE_CHECK_LE(a, b) \
  INDRIVE_CHECK((a) <= (b)) << #a " = " << (a) << ", " #b " = " << (b) << ": "
