#pragma once
// A library's error text in one line: ITK's exception descriptions run over several lines
// ("ITK ERROR: Reader(0x...): Could not create IO object ...\n  Tried to create one of ...").
#include <fcntl.h>
#include <mutex>
#include <string>
#include <unistd.h>

namespace brainshift {

/// The first non-empty line of `description`, without ITK's "ITK ERROR: Class(0x...): " prefix.
inline std::string oneLine(const std::string& description)
{
  std::string line;
  for (std::size_t start = 0; start < description.size() && line.empty();) {
    const std::size_t end = std::min(description.find('\n', start), description.size());
    line = description.substr(start, end - start);
    while (!line.empty() && (line.back() == ' ' || line.back() == '\r')) line.pop_back();
    start = end + 1;
  }
  if (line.rfind("ITK ERROR: ", 0) == 0) {
    const std::size_t object = line.find("): ");
    line = object == std::string::npos ? line.substr(11) : line.substr(object + 3);
  }
  while (!line.empty() && (line.back() == ':' || line.back() == ' ')) line.pop_back();
  return line;
}

/// Mutes the process's standard error while alive, for a library that prints its own error and
/// carries on (the caller checks the result and reports once). Writers run in parallel threads:
/// the first to mute saves the real stderr, the last to finish restores it.
class MutedStderr {
public:
  MutedStderr()
  {
    std::lock_guard<std::mutex> lock(state().mutex);
    if (state().count++ > 0) return;
    state().saved = ::fcntl(STDERR_FILENO, F_DUPFD_CLOEXEC, 3);
    const int quiet = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
    if (quiet >= 0 && state().saved >= 0) ::dup2(quiet, STDERR_FILENO);
    if (quiet >= 0) ::close(quiet);
  }
  ~MutedStderr()
  {
    std::lock_guard<std::mutex> lock(state().mutex);
    if (--state().count > 0 || state().saved < 0) return;
    ::dup2(state().saved, STDERR_FILENO);
    ::close(state().saved);
    state().saved = -1;
  }
  MutedStderr(const MutedStderr&) = delete;
  MutedStderr& operator=(const MutedStderr&) = delete;

private:
  struct State {
    std::mutex mutex;
    int count = 0;
    int saved = -1;
  };
  static State& state()
  {
    static State* instance = new State; // shared by every translation unit (inline function)
    return *instance;
  }
};

} // namespace brainshift
