#pragma once
// What a run must not leave behind when a signal ends it: its temporary files and folders and the
// process groups of its workers (mpiexec and its ranks). Writers and the worker launcher register
// what they create and withdraw it once committed or gone; the command line's signal handling
// calls terminateAndRemoveAll() before it exits with 128 + the signal.
#include <cstddef>
#include <filesystem>
#include <functional>
#include <string>
#include <sys/types.h>

namespace brainshift::cleanup {

/// A temporary file or folder of this run (removed with everything under it).
void addTemporaryPath(const std::filesystem::path& path);
void withdrawTemporaryPath(const std::filesystem::path& path);

/// Registers `path` and runs `create` (which makes it, or the folder it will be written in) as one
/// step: once the process is ending the calling thread blocks before `create` runs. Registering
/// after creating would let a thread make a folder the cleanup has just removed (or is removing)
/// and leave it behind.
void createRegistered(const std::filesystem::path& path, const std::function<void()>& create);

/// A new folder from mkdtemp's `pattern` (ending in XXXXXX), registered as it is made (as
/// createRegistered). Throws std::system_error when mkdtemp fails.
std::filesystem::path makeTemporaryFolder(const std::string& pattern);

/// The process group of a worker this run started.
void addProcessGroup(pid_t group);
void withdrawProcessGroup(pid_t group);

/// Runs `start` (which forks a worker leading a process group of its own and returns its id, or a
/// negative number when it could not) and registers the group, as one step: once the process is
/// ending the calling thread blocks before `start` runs, so no worker outlives the cleanup.
pid_t startRegisteredGroup(const std::function<pid_t()>& start);

/// Terminates every registered process group (SIGTERM; SIGKILL to what is left after
/// `graceSeconds`) and removes every registered path, again while one is still there (for up to
/// half a second: a write in flight on another thread may put a file back into a folder being
/// removed). From then on the add and create functions block the thread that calls them: the
/// process is ending, nothing new may be created.
void terminateAndRemoveAll(double graceSeconds);

/// Removes the temporary files (".tmp-<pid>-...") in `folder` whose process no longer runs: the
/// leftovers of a run killed outright (SIGKILL, a crash, a power cut). Returns how many.
std::size_t removeStaleTemporaries(const std::filesystem::path& folder);

} // namespace brainshift::cleanup
