#pragma once
// Assertions for test functions `int NameTest(int, char*[])`: a failed check throws, the
// driver wrapper prints where and why, and the test returns EXIT_FAILURE.
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace brainshift::testing {

struct CheckFailure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

[[noreturn]] void fail(const char* file, int line, const std::string& message);

/// Runs `body`; prints a failed check or an unexpected exception and returns EXIT_FAILURE.
int runTest(const char* name, const std::function<void()>& body);

/// A fresh, empty folder for one test under the build tree's Testing/Temporary.
std::filesystem::path temporaryFolder(const std::string& testName);

/// The Colin27 template of Debian's mricron-data, or an empty path if it is not installed.
std::filesystem::path colin27Path(const std::string& fileName = "ch2.nii.gz");

} // namespace brainshift::testing

#define BS_CHECK(condition)                                                                              \
  do {                                                                                                   \
    if (!(condition)) ::brainshift::testing::fail(__FILE__, __LINE__, "check failed: " #condition);     \
  } while (0)

#define BS_CHECK_MSG(condition, message)                                                                 \
  do {                                                                                                   \
    if (!(condition)) {                                                                                  \
      std::ostringstream bs_message_;                                                                    \
      bs_message_ << "check failed: " #condition ": " << message;                                        \
      ::brainshift::testing::fail(__FILE__, __LINE__, bs_message_.str());                                \
    }                                                                                                    \
  } while (0)

#define BS_CHECK_NEAR(actual, expected, tolerance)                                                       \
  do {                                                                                                   \
    const double bs_a_ = (actual), bs_e_ = (expected), bs_t_ = (tolerance);                              \
    if (!(std::abs(bs_a_ - bs_e_) <= bs_t_)) {                                                           \
      std::ostringstream bs_message_;                                                                    \
      bs_message_ << #actual " = " << bs_a_ << ", expected " << bs_e_ << " +- " << bs_t_;                \
      ::brainshift::testing::fail(__FILE__, __LINE__, bs_message_.str());                                \
    }                                                                                                    \
  } while (0)

/// Checks that `statement` throws `ExceptionType` whose message contains `fragment`.
#define BS_CHECK_THROWS(statement, ExceptionType, fragment)                                              \
  do {                                                                                                   \
    bool bs_thrown_ = false;                                                                             \
    try {                                                                                                \
      statement;                                                                                         \
    } catch (const ExceptionType& bs_e_) {                                                               \
      bs_thrown_ = true;                                                                                 \
      const std::string bs_what_ = bs_e_.what();                                                         \
      if (bs_what_.find(fragment) == std::string::npos) {                                                \
        ::brainshift::testing::fail(__FILE__, __LINE__,                                                  \
                                    std::string("message '") + bs_what_ + "' lacks '" + (fragment) + "'"); \
      }                                                                                                  \
    }                                                                                                    \
    if (!bs_thrown_) ::brainshift::testing::fail(__FILE__, __LINE__, #statement " did not throw " #ExceptionType); \
  } while (0)
