// What a run leaves behind when it is ended: the temporaries of runs that were killed outright are
// found by their process id and removed (and only theirs); a signal's cleanup terminates the
// workers' process groups (SIGKILL for one that ignores SIGTERM) and removes the registered paths;
// a thread that keeps making work folders and files in them while the cleanup runs leaves nothing
// behind (it is stopped before it makes the next one, and what it was writing is removed after
// it), and a worker started as the cleanup begins is either ended by it or never started.
#include "BrainShiftTestingSupport.h"
#include "ProcessCleanup.h"

#include <chrono>
#include <csignal>
#include <fstream>
#include <mutex>
#include <thread>
#include <vector>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

namespace {
namespace fs = std::filesystem;

/// The id of a process that has run and been reaped: no process has it (until the ids wrap).
pid_t endedProcessId()
{
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  int status = 0;
  ::waitpid(child, &status, 0);
  return child;
}

/// A worker in a process group of its own (as the launcher starts mpiexec), sleeping; with
/// `ignoreTerm` it ignores SIGTERM, as a hung worker may, else SIGTERM ends it whatever the test's
/// parent set. Returns once the worker is set up (it says so through a pipe), so no signal can
/// reach it before; -1 when it could not be started.
pid_t startWorkerGroup(bool ignoreTerm)
{
  int ready[2];
  if (::pipe(ready) != 0) return -1;
  const pid_t child = ::fork();
  if (child == 0) {
    ::close(ready[0]);
    ::setpgid(0, 0);
    std::signal(SIGTERM, ignoreTerm ? SIG_IGN : SIG_DFL);
    sigset_t term;
    sigemptyset(&term);
    sigaddset(&term, SIGTERM);
    sigprocmask(SIG_UNBLOCK, &term, nullptr);
    const char byte = 1;
    if (::write(ready[1], &byte, 1) != 1) ::_exit(1);
    for (;;) ::pause();
  }
  ::close(ready[1]); // a worker that dies before it writes ends the read
  char byte = 0;
  const bool told = child > 0 && ::read(ready[0], &byte, 1) == 1;
  ::close(ready[0]);
  if (child > 0) ::setpgid(child, child); // either side may win the race; both set the same group
  if (!told && child > 0) ::kill(-child, SIGKILL);
  return told ? child : -1;
}

/// Runs the signal-time cleanup in a child process (it ends the registry for good) and returns
/// its exit code: 0 when both workers ended by the expected signal and the paths are gone.
int cleanupInChild(const fs::path& temporaryFile, const fs::path& temporaryFolder)
{
  const pid_t child = ::fork();
  BS_CHECK(child >= 0);
  if (child == 0) {
    using namespace brainshift;
    const pid_t polite = startWorkerGroup(false);
    const pid_t stubborn = startWorkerGroup(true);
    if (polite < 0 || stubborn < 0) {
      if (polite > 0) ::kill(-polite, SIGKILL);
      if (stubborn > 0) ::kill(-stubborn, SIGKILL);
      ::_exit(8);
    }
    cleanup::addProcessGroup(polite);
    cleanup::addProcessGroup(stubborn);
    cleanup::addTemporaryPath(temporaryFile);
    cleanup::addTemporaryPath(temporaryFolder);
    cleanup::terminateAndRemoveAll(0.3);
    int politeStatus = 0, stubbornStatus = 0;
    ::waitpid(polite, &politeStatus, 0);
    ::waitpid(stubborn, &stubbornStatus, 0);
    const bool politeByTerm = WIFSIGNALED(politeStatus) && WTERMSIG(politeStatus) == SIGTERM;
    const bool stubbornByKill = WIFSIGNALED(stubbornStatus) && WTERMSIG(stubbornStatus) == SIGKILL;
    const bool pathsGone = !fs::exists(temporaryFile) && !fs::exists(temporaryFolder);
    ::_exit((politeByTerm ? 0 : 1) | (stubbornByKill ? 0 : 2) | (pathsGone ? 0 : 4));
  }
  int status = 0;
  BS_CHECK(::waitpid(child, &status, 0) == child);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 100;
}

/// In a child process: a thread makes work folders under `base` and files in them (as a worker's
/// job folder and the atomic writer's temporaries are made) as fast as it can, and another starts
/// worker groups, while this thread ends the process's registry after `delayMs`. Exit 0 when
/// nothing is left under `base` and every worker started is gone, 4 when a folder or a file is
/// left, 1 when a worker outlived the cleanup.
int racingCleanupInChild(const fs::path& base, int delayMs)
{
  const pid_t child = ::fork();
  BS_CHECK(child >= 0);
  if (child == 0) {
    using namespace brainshift;
    std::thread writer([&base] {
      for (int n = 0;; ++n) {
        const fs::path folder = cleanup::makeTemporaryFolder((base / "work-XXXXXX").string());
        const fs::path file = folder / ".tmp-job";
        cleanup::createRegistered(file, [&] { fs::create_directories(folder); });
        std::ofstream(file) << "job " << n;
        cleanup::withdrawTemporaryPath(file);
        std::error_code ignored;
        fs::remove_all(folder, ignored);
        cleanup::withdrawTemporaryPath(folder);
      }
    });
    std::vector<pid_t> started; // read after the cleanup only
    std::mutex startedMutex;
    std::thread launcher([&] {
      for (;;) {
        const pid_t worker = cleanup::startRegisteredGroup([] {
          const pid_t pid = ::fork();
          if (pid == 0) {
            ::setpgid(0, 0);
            for (;;) ::pause();
          }
          if (pid > 0) ::setpgid(pid, pid);
          return pid;
        });
        {
          std::lock_guard<std::mutex> lock(startedMutex);
          started.push_back(worker);
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(delayMs));
    cleanup::terminateAndRemoveAll(0.02); // the workers are this process's unreaped children: no grace to wait out
    bool workerLeft = false;
    {
      std::lock_guard<std::mutex> lock(startedMutex);
      // A worker the cleanup killed is gone within moments (however loaded the machine, a second
      // is plenty); one it never knew of pauses for ever.
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(1);
      for (pid_t worker : started) {
        int status = 0;
        pid_t reaped = 0;
        while ((reaped = ::waitpid(worker, &status, WNOHANG)) == 0 && std::chrono::steady_clock::now() < deadline) {
          std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        if (reaped == 0) {
          workerLeft = true;
          ::kill(-worker, SIGKILL); // not left to hold the test's output open
        }
      }
    }
    std::error_code ec;
    const bool anythingLeft = fs::directory_iterator(base, ec) != fs::directory_iterator();
    ::_exit((anythingLeft ? 4 : 0) | (workerLeft ? 1 : 0)); // the blocked threads end with the process
  }
  int status = 0;
  BS_CHECK(::waitpid(child, &status, 0) == child);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 100;
}
} // namespace

int ProcessCleanupTest(int, char*[])
{
  return brainshift::testing::runTest("ProcessCleanupTest", [] {
    using namespace brainshift;
    const fs::path folder = testing::temporaryFolder("ProcessCleanupTest");
    const std::string dead = std::to_string(endedProcessId());
    const std::string self = std::to_string(::getpid());

    // A killed run's leftovers: a file and a folder (a worker's job folder) under its process id.
    std::ofstream(folder / (".tmp-" + dead + "-0-warped.nii.gz")) << "half a volume";
    fs::create_directories(folder / (".tmp-" + dead + "-1-job") / "inside");
    std::ofstream(folder / (".tmp-" + dead + "-1-job") / "inside" / "nodes.bin") << "x";
    // Kept: this run's own, a live process's (pid 1), names that only look alike, real outputs.
    std::ofstream(folder / (".tmp-" + self + "-0-report.json")) << "{}";
    std::ofstream(folder / ".tmp-1-0-scene.mrml") << "<MRML/>";
    std::ofstream(folder / ".tmp-abc-0-labels.nii.gz") << "x";
    std::ofstream(folder / ".tmp--0-x") << "x";
    std::ofstream(folder / ".tmp-99999999999999999999-0-x") << "x"; // digits no process id has
    std::ofstream(folder / ("tmp-" + dead + "-0-output.nii.gz")) << "x";
    std::ofstream(folder / "report.json") << "{}";

    BS_CHECK(cleanup::removeStaleTemporaries(folder) == 2);
    BS_CHECK(!fs::exists(folder / (".tmp-" + dead + "-0-warped.nii.gz")));
    BS_CHECK(!fs::exists(folder / (".tmp-" + dead + "-1-job")));
    for (const std::string& kept : {".tmp-" + self + "-0-report.json", std::string(".tmp-1-0-scene.mrml"),
                                   std::string(".tmp-abc-0-labels.nii.gz"), std::string(".tmp--0-x"), std::string(".tmp-99999999999999999999-0-x"),
                                   "tmp-" + dead + "-0-output.nii.gz", std::string("report.json")}) {
      BS_CHECK_MSG(fs::exists(folder / kept), kept);
    }
    BS_CHECK(cleanup::removeStaleTemporaries(folder) == 0);
    BS_CHECK(cleanup::removeStaleTemporaries(folder / "no-such-folder") == 0);

    // The signal-time cleanup: workers ended (the stubborn one by SIGKILL after the grace), paths
    // registered and still present removed, a path withdrawn (committed) left alone.
    const fs::path pending = folder / ".tmp-pending-mesh.vtu";
    const fs::path jobFolder = folder / "job";
    std::ofstream(pending) << "partial";
    fs::create_directories(jobFolder / "sub");
    const int outcome = cleanupInChild(pending, jobFolder);
    BS_CHECK_MSG(outcome == 0, "exit " << outcome << " (1: a worker outlived SIGTERM, 2: the one ignoring it was "
                                          "not killed, 4: a registered path is still there, 8: a worker could not be started)");
    BS_CHECK(!fs::exists(pending) && !fs::exists(jobFolder));
    BS_CHECK(fs::exists(folder / "report.json"));

    // Racing the cleanup: 20 runs, the cleanup 1 to 20 ms into the threads' work.
    const fs::path racing = folder / "racing";
    for (int run = 0; run < 20; ++run) {
      fs::create_directories(racing);
      const int raced = racingCleanupInChild(racing, 1 + run);
      BS_CHECK_MSG(raced == 0, "run " << run << ": exit " << raced << " (4: a work folder or file was left, 1: a worker outlived the cleanup)");
      std::error_code ignored;
      fs::remove_all(racing, ignored);
    }

    const fs::path committed = folder / "committed.json";
    std::ofstream(committed) << "{}";
    cleanup::addTemporaryPath(committed);
    cleanup::withdrawTemporaryPath(committed);
    const pid_t child = ::fork();
    BS_CHECK(child >= 0);
    if (child == 0) {
      cleanup::terminateAndRemoveAll(0.0);
      ::_exit(0);
    }
    int status = 0;
    BS_CHECK(::waitpid(child, &status, 0) == child);
    BS_CHECK(WIFEXITED(status) && WEXITSTATUS(status) == 0);
    BS_CHECK(fs::exists(committed));
  });
}
