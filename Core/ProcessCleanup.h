#pragma once
// What a run must not leave behind when a signal ends it: its temporary files and folders and the
// process groups of its workers (mpiexec and its ranks). Writers and the worker launcher register
// what they create and withdraw it once committed or gone; the command line's signal handling
// calls terminateAndRemoveAll() before it exits with 128 + the signal.
#include <cstddef>
#include <filesystem>
#include <sys/types.h>

namespace brainshift::cleanup {

/// A temporary file or folder of this run (removed with everything under it).
void addTemporaryPath(const std::filesystem::path& path);
void withdrawTemporaryPath(const std::filesystem::path& path);

/// The process group of a worker this run started.
void addProcessGroup(pid_t group);
void withdrawProcessGroup(pid_t group);

/// Terminates every registered process group (SIGTERM; SIGKILL to what is left after
/// `graceSeconds`) and removes every registered path. From then on the add functions block the
/// thread that calls them: the process is ending, nothing new may be created.
void terminateAndRemoveAll(double graceSeconds);

/// Removes the temporary files (".tmp-<pid>-...") in `folder` whose process no longer runs: the
/// leftovers of a run killed outright (SIGKILL, a crash, a power cut). Returns how many.
std::size_t removeStaleTemporaries(const std::filesystem::path& folder);

} // namespace brainshift::cleanup
