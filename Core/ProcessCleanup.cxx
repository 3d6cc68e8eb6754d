#include "ProcessCleanup.h"

#include <cctype>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <unistd.h>

namespace brainshift::cleanup {
namespace fs = std::filesystem;

namespace {
struct Registry {
  std::mutex mutex;
  std::set<fs::path> paths;
  std::set<pid_t> groups;
  bool ending = false;
};

/// Never destroyed: a signal may arrive while static objects are being torn down.
Registry& registry()
{
  static Registry* instance = new Registry;
  return *instance;
}

/// The lock, or never returns when the process is ending.
std::unique_lock<std::mutex> lockUnlessEnding()
{
  std::unique_lock<std::mutex> lock(registry().mutex);
  while (registry().ending) {
    lock.unlock();
    std::this_thread::sleep_for(std::chrono::hours(1));
    lock.lock();
  }
  return lock;
}

bool anyGroupAlive(const std::set<pid_t>& groups)
{
  for (pid_t group : groups) {
    if (::kill(-group, 0) == 0 || errno == EPERM) return true;
  }
  return false;
}
} // namespace

void addTemporaryPath(const fs::path& path)
{
  auto lock = lockUnlessEnding();
  registry().paths.insert(path);
}

void withdrawTemporaryPath(const fs::path& path)
{
  std::lock_guard<std::mutex> lock(registry().mutex);
  registry().paths.erase(path);
}

void addProcessGroup(pid_t group)
{
  auto lock = lockUnlessEnding();
  registry().groups.insert(group);
}

void withdrawProcessGroup(pid_t group)
{
  std::lock_guard<std::mutex> lock(registry().mutex);
  registry().groups.erase(group);
}

void terminateAndRemoveAll(double graceSeconds)
{
  std::set<pid_t> groups;
  std::set<fs::path> paths;
  {
    std::lock_guard<std::mutex> lock(registry().mutex);
    registry().ending = true;
    groups = registry().groups;
    paths = registry().paths;
  }
  for (pid_t group : groups) ::kill(-group, SIGTERM);
  // A group whose leader is an unreaped zombie still answers kill(0): the wait is bounded.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(graceSeconds);
  while (anyGroupAlive(groups) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  for (pid_t group : groups) ::kill(-group, SIGKILL);
  for (const fs::path& path : paths) {
    std::error_code ignored;
    fs::remove_all(path, ignored);
  }
}

std::size_t removeStaleTemporaries(const fs::path& folder)
{
  std::size_t removed = 0;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(".tmp-", 0) != 0) continue;
    std::size_t end = 5;
    while (end < name.size() && std::isdigit(static_cast<unsigned char>(name[end]))) ++end;
    // A process id has at most 9 digits here (pid_max <= 4,194,304); longer digits are not ours.
    if (end == 5 || end > 5 + 9 || end >= name.size() || name[end] != '-') continue;
    const pid_t owner = pid_t(std::stol(name.substr(5, end - 5)));
    if (owner == ::getpid() || ::kill(owner, 0) == 0 || errno == EPERM) continue;
    std::error_code ignored;
    if (fs::remove_all(entry.path(), ignored) > 0) ++removed;
  }
  return removed;
}

} // namespace brainshift::cleanup
