#include "BrainShiftTestingSupport.h"

#include <csignal>
#include <execinfo.h>
#include <unistd.h>

#include <cstdlib>

namespace brainshift::testing {
namespace fs = std::filesystem;

void fail(const char* file, int line, const std::string& message)
{
  std::ostringstream where;
  where << file << ":" << line << ": " << message;
  throw CheckFailure(where.str());
}

namespace {
const char* currentTest = "a test";

/// A crash names the test and where it happened (the frames on stderr) before the process dies
/// of its signal as it would have: a crash on CI is diagnosed from its log.
void reportCrash(int signalNumber)
{
  const char* what = signalNumber == SIGSEGV ? "segmentation fault" : signalNumber == SIGBUS ? "bus error"
                   : signalNumber == SIGFPE ? "floating point exception" : "abort";
  const std::string line = std::string(currentTest) + " CRASHED (" + what + "); the stack:\n";
  [[maybe_unused]] const auto written = ::write(STDERR_FILENO, line.data(), line.size());
  void* frames[64];
  const int count = ::backtrace(frames, 64);
  ::backtrace_symbols_fd(frames, count, STDERR_FILENO);
  std::signal(signalNumber, SIG_DFL);
  std::raise(signalNumber);
}
} // namespace

int runTest(const char* name, const std::function<void()>& body)
{
  currentTest = name;
  for (int signalNumber : {SIGSEGV, SIGBUS, SIGFPE, SIGABRT}) std::signal(signalNumber, reportCrash);
  try {
    body();
  } catch (const CheckFailure& failure) {
    std::cerr << name << " FAILED\n  " << failure.what() << '\n';
    return EXIT_FAILURE;
  } catch (const std::exception& e) {
    std::cerr << name << " FAILED with an unexpected exception: " << e.what() << '\n';
    return EXIT_FAILURE;
  }
  std::cout << name << " passed\n";
  return EXIT_SUCCESS;
}

fs::path temporaryFolder(const std::string& testName)
{
  const char* root = std::getenv("BRAINSHIFT_TEST_TEMP");
  fs::path folder = fs::path(root ? root : fs::temp_directory_path().string()) / testName;
  fs::remove_all(folder);
  fs::create_directories(folder);
  return folder;
}

fs::path colin27Path(const std::string& fileName)
{
  const fs::path path = fs::path("/usr/share/mricron/templates") / fileName;
  return fs::exists(path) ? path : fs::path();
}

} // namespace brainshift::testing
