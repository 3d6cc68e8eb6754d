#include "FiniteElementSolver.h"

#include "BrainShiftErrors.h"

#include <chrono>
#include <csignal>
#include <cstring>
#include <fcntl.h>
#include <poll.h>
#include <sstream>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace brainshift {
namespace fs = std::filesystem;

fs::path workerBesideExecutable()
{
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return (ec ? fs::current_path() : self.parent_path()) / "brainshift-fe-worker";
}

namespace {
using Clock = std::chrono::steady_clock;

struct TemporaryFolder {
  fs::path path;
  bool owned = false;
  ~TemporaryFolder()
  {
    std::error_code ignored;
    if (owned) fs::remove_all(path, ignored);
  }
};

/// The worker's own message when it gave one (mpiexec adds its banner after it), else the last lines.
std::string lastLines(const std::string& text, std::size_t count)
{
  {
    std::istringstream in(text);
    std::string own, petsc;
    for (std::string line; std::getline(in, line);) {
      if (line.rfind("brainshift-fe-worker: ", 0) == 0) own = line.substr(22);
      // PETSc's own explanation: the first error line after its banner.
      const auto at = line.find("PETSC ERROR: ");
      if (petsc.empty() && at != std::string::npos && line.find("----") == std::string::npos) petsc = line.substr(at + 13);
    }
    if (!own.empty()) return petsc.empty() ? own : own + " (PETSc: " + petsc + ")";
  }
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) lines.push_back(line);
  }
  std::string out;
  for (std::size_t i = lines.size() > count ? lines.size() - count : 0; i < lines.size(); ++i) out += (out.empty() ? "" : " | ") + lines[i];
  return out;
}
} // namespace

FiniteElementResult solveWithWorker(const FiniteElementJob& job, const FiniteElementRunOptions& options)
{
  job.validate();
  if (options.ranks < 1) throw std::invalid_argument("the worker needs at least one rank");
  std::error_code ec;
  if (!fs::is_regular_file(options.worker, ec) || ::access(options.worker.c_str(), X_OK) != 0) {
    throw MethodError("the finite element worker " + options.worker.string() + " is missing or not executable");
  }
  TemporaryFolder folder;
  if (options.workFolder.empty()) {
    char pattern[] = "/tmp/brainshift-fe-XXXXXX";
    if (!::mkdtemp(pattern)) throw MethodError(std::string("cannot create a work folder: ") + std::strerror(errno));
    folder.path = pattern;
    folder.owned = true;
  } else {
    folder.path = options.workFolder;
    fs::create_directories(folder.path);
  }
  const fs::path jobFile = folder.path / "job.bsfe", resultFile = folder.path / "result.bsfe";
  fs::remove(resultFile, ec);
  writeFiniteElementJob(job, jobFile);

  std::vector<std::string> arguments = {options.mpiexec, "-n", std::to_string(options.ranks)};
  if (options.allowOversubscription) arguments.push_back("--oversubscribe");
  if (::geteuid() == 0) arguments.push_back("--allow-run-as-root");
  if (!options.hostfile.empty()) {
    arguments.push_back("--hostfile");
    arguments.push_back(options.hostfile.string());
  }
  arguments.push_back(options.worker.string());
  arguments.push_back(jobFile.string());
  arguments.push_back(resultFile.string());

  int out[2], err[2];
  if (::pipe(out) != 0 || ::pipe(err) != 0) throw MethodError(std::string("cannot start the worker: ") + std::strerror(errno));
  const pid_t child = ::fork();
  if (child < 0) throw MethodError(std::string("cannot start the worker: ") + std::strerror(errno));
  if (child == 0) {
    ::setpgid(0, 0); // its own process group: every rank can be stopped together
    ::dup2(out[1], STDOUT_FILENO);
    ::dup2(err[1], STDERR_FILENO);
    ::close(out[0]);
    ::close(err[0]);
    std::vector<char*> argv;
    for (auto& a : arguments) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execvp(argv[0], argv.data());
    std::fprintf(stderr, "cannot run %s: %s\n", argv[0], std::strerror(errno));
    ::_exit(127);
  }
  ::setpgid(child, child);
  ::close(out[1]);
  ::close(err[1]);
  ::fcntl(out[0], F_SETFL, O_NONBLOCK);
  ::fcntl(err[0], F_SETFL, O_NONBLOCK);

  std::string stdoutBuffer, stderrText;
  const auto start = Clock::now();
  std::string stopReason;
  int status = 0;
  bool exited = false;
  auto drain = [&](int fd, std::string& into) {
    char buffer[4096];
    for (ssize_t got; (got = ::read(fd, buffer, sizeof(buffer))) > 0;) into.append(buffer, std::size_t(got));
  };
  auto stopGroup = [&](const std::string& why) {
    stopReason = why;
    ::kill(-child, SIGTERM);
    const auto deadline = Clock::now() + std::chrono::duration<double>(options.cancelGraceSeconds);
    while (Clock::now() < deadline) {
      if (::waitpid(child, &status, WNOHANG) == child) {
        exited = true;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ::kill(-child, SIGKILL); // whatever is left of the group, ranks included
    if (!exited) {
      ::waitpid(child, &status, 0);
      exited = true;
    }
  };
  while (!exited) {
    pollfd fds[2] = {{out[0], POLLIN, 0}, {err[0], POLLIN, 0}};
    ::poll(fds, 2, 50);
    drain(out[0], stdoutBuffer);
    drain(err[0], stderrText);
    for (std::size_t newline; (newline = stdoutBuffer.find('\n')) != std::string::npos;) {
      const std::string line = stdoutBuffer.substr(0, newline);
      stdoutBuffer.erase(0, newline + 1);
      std::istringstream fields(line);
      std::string word, stage;
      double fraction = 0;
      if (fields >> word >> stage >> fraction && word == "progress" && options.progress) options.progress(stage, fraction);
    }
    if (::waitpid(child, &status, WNOHANG) == child) {
      exited = true;
      break;
    }
    if (options.cancel && options.cancel->load()) stopGroup("cancelled");
    else if (std::chrono::duration<double>(Clock::now() - start).count() > options.timeoutSeconds) {
      std::ostringstream why;
      why << "timed out after " << options.timeoutSeconds << " s";
      stopGroup(why.str());
    }
  }
  drain(err[0], stderrText);
  ::close(out[0]);
  ::close(err[0]);
  ::kill(-child, SIGKILL); // no orphaned ranks, even after a normal exit
  if (!stopReason.empty()) throw MethodError("the finite element worker was stopped: " + stopReason);
  if (WIFSIGNALED(status)) {
    throw MethodError("the finite element worker died (signal " + std::to_string(WTERMSIG(status)) + ")" +
                      (stderrText.empty() ? "" : ": " + lastLines(stderrText, 3)));
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    const std::string message = lastLines(stderrText, 3);
    throw MethodError("the finite element worker failed (exit " + std::to_string(WEXITSTATUS(status)) + ")" +
                      (message.empty() ? "" : ": " + message));
  }
  try {
    return readFiniteElementResult(resultFile);
  } catch (const std::exception& e) {
    throw MethodError(std::string("the finite element worker wrote no usable result: ") + e.what());
  }
}

} // namespace brainshift
