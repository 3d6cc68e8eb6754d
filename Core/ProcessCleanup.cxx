#include "ProcessCleanup.h"

#include <cctype>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <mutex>
#include <set>
#include <string>
#include <system_error>
#include <thread>
#include <vector>
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

void createRegistered(const fs::path& path, const std::function<void()>& create)
{
  auto lock = lockUnlessEnding();
  registry().paths.insert(path);
  create();
}

fs::path makeTemporaryFolder(const std::string& pattern)
{
  std::vector<char> name(pattern.begin(), pattern.end());
  name.push_back('\0');
  auto lock = lockUnlessEnding();
  if (!::mkdtemp(name.data())) throw std::system_error(errno, std::generic_category(), "mkdtemp " + pattern);
  const fs::path made(name.data());
  registry().paths.insert(made);
  return made;
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

pid_t startRegisteredGroup(const std::function<pid_t()>& start)
{
  auto lock = lockUnlessEnding();
  const pid_t group = start();
  if (group > 0) registry().groups.insert(group);
  return group;
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
  // Another thread may be writing into a registered folder right now (a file it opened before the
  // process began ending): a removal that found the folder not empty is tried again.
  const auto removalDeadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(500);
  for (;;) {
    bool anyLeft = false;
    for (const fs::path& path : paths) {
      std::error_code ignored;
      fs::remove_all(path, ignored);
      anyLeft = anyLeft || fs::symlink_status(path, ignored).type() != fs::file_type::not_found;
    }
    if (!anyLeft || std::chrono::steady_clock::now() >= removalDeadline) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
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
