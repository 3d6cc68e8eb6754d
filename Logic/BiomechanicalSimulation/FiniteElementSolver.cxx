#include "FiniteElementSolver.h"

#include "BrainShiftErrors.h"
#include "ProcessCleanup.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <csignal>
#include <cstring>
#include <system_error>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <sstream>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace brainshift {
namespace fs = std::filesystem;

std::string solverOptionsForRepeatedSolves(const std::string& given)
{
  if (given.find("-ksp_type") != std::string::npos || given.find("-pc_type") != std::string::npos) return given;
  const bool subGiven = given.find("-sub_pc_type") != std::string::npos;
  return std::string("-ksp_type cg -pc_type bjacobi ") + (subGiven ? "" : "-sub_pc_type icc ") + given;
}

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
  TemporaryFolder() = default;
  TemporaryFolder(TemporaryFolder&& other) noexcept : path(std::move(other.path)), owned(other.owned) { other.owned = false; }
  TemporaryFolder& operator=(TemporaryFolder&& other) noexcept
  {
    std::swap(path, other.path);
    std::swap(owned, other.owned);
    return *this;
  }
  ~TemporaryFolder()
  {
    std::error_code ignored;
    if (owned) {
      fs::remove_all(path, ignored);
      cleanup::withdrawTemporaryPath(path);
    }
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

namespace {

/// One run of the worker under mpiexec, in its own process group, with pipes to its standard
/// input, output and error.
class WorkerProcess {
public:
  WorkerProcess(const FiniteElementRunOptions& options, const std::vector<std::string>& workerArguments)
    : options_(options)
  {
    std::vector<std::string> arguments = {options.mpiexec, "-n", std::to_string(options.ranks)};
    if (options.allowOversubscription) arguments.push_back("--oversubscribe");
    if (::geteuid() == 0) arguments.push_back("--allow-run-as-root");
    if (!options.hostfile.empty()) {
      arguments.push_back("--hostfile");
      arguments.push_back(options.hostfile.string());
    }
    arguments.push_back(options.worker.string());
    arguments.insert(arguments.end(), workerArguments.begin(), workerArguments.end());
    int in[2], out[2], err[2];
    if (::pipe(in) != 0 || ::pipe(out) != 0 || ::pipe(err) != 0) {
      throw MethodError(std::string("cannot start the worker: ") + std::strerror(errno));
    }
    std::vector<char*> argv; // made before the fork: the child of a threaded process must not allocate
    for (auto& a : arguments) argv.push_back(a.data());
    argv.push_back(nullptr);
    // Started and registered as one step: a signal's cleanup either ends this worker or comes
    // before it is started (this thread then blocks here until the process exits).
    child_ = cleanup::startRegisteredGroup([&] {
      const pid_t child = ::fork();
      if (child == 0) {
        ::setpgid(0, 0); // its own process group: every rank can be stopped together
        ::dup2(in[0], STDIN_FILENO);
        ::dup2(out[1], STDOUT_FILENO);
        ::dup2(err[1], STDERR_FILENO);
        ::close(in[1]);
        ::close(out[0]);
        ::close(err[0]);
        ::execvp(argv[0], argv.data());
        std::fprintf(stderr, "cannot run %s: %s\n", argv[0], std::strerror(errno));
        ::_exit(127);
      }
      if (child > 0) ::setpgid(child, child);
      return child;
    });
    if (child_ < 0) throw MethodError(std::string("cannot start the worker: ") + std::strerror(errno));
    ::close(in[0]);
    ::close(out[1]);
    ::close(err[1]);
    input_ = in[1];
    output_ = out[0];
    error_ = err[0];
    ::fcntl(output_, F_SETFL, O_NONBLOCK);
    ::fcntl(error_, F_SETFL, O_NONBLOCK);
  }

  ~WorkerProcess()
  {
    if (!exited_) stop("");
    ::kill(-child_, SIGKILL); // no orphaned ranks, even after a normal exit
    cleanup::withdrawProcessGroup(child_);
    ::close(input_);
    ::close(output_);
    ::close(error_);
  }

  /// A dead worker shows as a failed write, not as a SIGPIPE that kills the caller: the signal is
  /// blocked in this thread for the write and a pending one consumed, leaving the process's
  /// signal handling (the host's) as it was.
  void writeLine(const std::string& line)
  {
    const std::string text = line + "\n";
    sigset_t pipe, previous;
    sigemptyset(&pipe);
    sigaddset(&pipe, SIGPIPE);
    ::pthread_sigmask(SIG_BLOCK, &pipe, &previous);
    const ssize_t written = ::write(input_, text.data(), text.size());
    const int error = errno;
    if (written < 0 && error == EPIPE) {
      const timespec immediately{0, 0};
      while (::sigtimedwait(&pipe, nullptr, &immediately) == SIGPIPE) {
      }
    }
    ::pthread_sigmask(SIG_SETMASK, &previous, nullptr);
    if (written != ssize_t(text.size())) {
      throw MethodError("the finite element worker is gone" + stderrSummary());
    }
  }

  /// The next line of output that is not progress; empty when the worker exited. Progress lines
  /// go to the callback. Timeout and cancellation stop the worker with a MethodError.
  std::optional<std::string> readLine(double timeoutSeconds)
  {
    const auto start = Clock::now();
    for (;;) {
      for (std::size_t newline; (newline = stdout_.find('\n')) != std::string::npos;) {
        const std::string line = stdout_.substr(0, newline);
        stdout_.erase(0, newline + 1);
        std::istringstream fields(line);
        std::string word, stage;
        double fraction = 0;
        if (fields >> word >> stage >> fraction && word == "progress") {
          if (options_.progress) options_.progress(stage, fraction);
          continue;
        }
        return line;
      }
      if (exited_) return std::nullopt;
      pollfd fds[2] = {{output_, POLLIN, 0}, {error_, POLLIN, 0}};
      ::poll(fds, 2, 50);
      drain();
      if (stdout_.find('\n') != std::string::npos) continue;
      if (::waitpid(child_, &status_, WNOHANG) == child_) {
        exited_ = true;
        drain();
        continue;
      }
      if (options_.cancel && options_.cancel->load()) stop("cancelled");
      if (std::chrono::duration<double>(Clock::now() - start).count() > timeoutSeconds) {
        std::ostringstream why;
        why << "timed out after " << timeoutSeconds << " s";
        stop(why.str());
      }
    }
  }

  /// MethodError unless the worker exited normally.
  void requireCleanExit()
  {
    if (!exited_) return;
    if (WIFSIGNALED(status_)) {
      throw MethodError("the finite element worker died (signal " + std::to_string(WTERMSIG(status_)) + ")" + stderrSummary());
    }
    if (WIFEXITED(status_) && WEXITSTATUS(status_) == 2) { // the worker refused its job: the options
      throw InputError("the finite element worker refused the job" + stderrSummary());
    }
    if (!WIFEXITED(status_) || WEXITSTATUS(status_) != 0) {
      throw MethodError("the finite element worker failed (exit " + std::to_string(WEXITSTATUS(status_)) + ")" + stderrSummary());
    }
  }

  bool exited() const { return exited_; }

private:
  void drain()
  {
    char buffer[4096];
    for (ssize_t got; (got = ::read(output_, buffer, sizeof(buffer))) > 0;) stdout_.append(buffer, std::size_t(got));
    for (ssize_t got; (got = ::read(error_, buffer, sizeof(buffer))) > 0;) stderr_.append(buffer, std::size_t(got));
  }

  std::string stderrSummary() const
  {
    const std::string message = lastLines(stderr_, 3);
    return message.empty() ? "" : ": " + message;
  }

  /// Terminates the group, waits the grace period, kills what is left; MethodError with `why`.
  void stop(const std::string& why)
  {
    ::kill(-child_, SIGTERM);
    const auto deadline = Clock::now() + std::chrono::duration<double>(options_.cancelGraceSeconds);
    while (!exited_ && Clock::now() < deadline) {
      if (::waitpid(child_, &status_, WNOHANG) == child_) exited_ = true;
      else std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ::kill(-child_, SIGKILL);
    if (!exited_) {
      ::waitpid(child_, &status_, 0);
      exited_ = true;
    }
    if (!why.empty()) throw MethodError("the finite element worker was stopped: " + why);
  }

  const FiniteElementRunOptions& options_;
  pid_t child_ = -1;
  int input_ = -1, output_ = -1, error_ = -1;
  int status_ = 0;
  bool exited_ = false;
  std::string stdout_, stderr_;
};

void requireWorker(const FiniteElementRunOptions& options)
{
  if (options.ranks < 1) throw std::invalid_argument("the worker needs at least one rank");
  std::error_code ec;
  if (!fs::is_regular_file(options.worker, ec) || ::access(options.worker.c_str(), X_OK) != 0) {
    throw MethodError("the finite element worker " + options.worker.string() + " is missing or not executable");
  }
}

/// The job file for the worker; a failed write (a full disk) is the run's failure, named.
void writeJobFor(const FiniteElementJob& job, const fs::path& file)
{
  try {
    writeFiniteElementJob(job, file);
  } catch (const std::runtime_error& e) {
    throw MethodError(std::string("the finite element job: ") + e.what() + " (disk full or not writable?)");
  }
}

TemporaryFolder workFolderFor(const FiniteElementRunOptions& options)
{
  TemporaryFolder folder;
  if (options.workFolder.empty()) {
    try {
      folder.path = cleanup::makeTemporaryFolder("/tmp/brainshift-fe-XXXXXX"); // registered as it is made
    } catch (const std::system_error& e) {
      throw MethodError(std::string("cannot create the finite element worker's folder in /tmp: ") + e.code().message() +
                        " (disk full or /tmp not writable?)");
    }
    folder.owned = true;
  } else {
    folder.path = options.workFolder;
    fs::create_directories(folder.path);
  }
  return folder;
}

} // namespace

FiniteElementResult solveWithWorker(const FiniteElementJob& job, const FiniteElementRunOptions& options)
{
  job.validate();
  requireWorker(options);
  TemporaryFolder folder = workFolderFor(options);
  const fs::path jobFile = folder.path / "job.bsfe", resultFile = folder.path / "result.bsfe";
  std::error_code ec;
  fs::remove(resultFile, ec);
  writeJobFor(job, jobFile);
  WorkerProcess worker(options, {jobFile.string(), resultFile.string()});
  const auto start = Clock::now();
  while (worker.readLine(options.timeoutSeconds - std::chrono::duration<double>(Clock::now() - start).count())) {
  }
  worker.requireCleanExit();
  try {
    return readFiniteElementResult(resultFile);
  } catch (const std::exception& e) {
    throw MethodError(std::string("the finite element worker wrote no usable result: ") + e.what());
  }
}

struct FiniteElementSession::Impl {
  FiniteElementRunOptions options;
  FiniteElementJob prepared;  ///< the job the worker was prepared with
  FiniteElementJob fixedPart; ///< the fixed nodes (values replaced per solve)
  TemporaryFolder folder;
  std::unique_ptr<WorkerProcess> worker;
  int solves = 0;
};

FiniteElementSession::FiniteElementSession(const FiniteElementJob& job, FiniteElementRunOptions options)
  : impl_(std::make_unique<Impl>())
{
  job.validate();
  requireWorker(options);
  const auto start = Clock::now();
  impl_->options = std::move(options);
  impl_->folder = workFolderFor(impl_->options);
  const fs::path jobFile = impl_->folder.path / "job.bsfe";
  writeJobFor(job, jobFile);
  impl_->fixedPart.fixedNodes = job.fixedNodes;
  impl_->prepared = job;
  impl_->worker = std::make_unique<WorkerProcess>(impl_->options, std::vector<std::string>{"--serve", jobFile.string()});
  const auto answer = impl_->worker->readLine(impl_->options.timeoutSeconds);
  if (!answer || *answer != "ready") {
    impl_->worker->requireCleanExit();
    throw MethodError("the finite element worker did not get ready" + (answer ? ": " + *answer : std::string()));
  }
  prepareSeconds_ = std::chrono::duration<double>(Clock::now() - start).count();
}

FiniteElementSession::~FiniteElementSession()
{
  if (impl_ && impl_->worker && !impl_->worker->exited()) {
    try {
      impl_->worker->writeLine("quit");
      impl_->worker->readLine(impl_->options.cancelGraceSeconds);
    } catch (const std::exception&) {
    }
  }
}

const FiniteElementJob& FiniteElementSession::preparedJob() const { return impl_->prepared; }

FiniteElementResult FiniteElementSession::solve(const std::vector<std::int32_t>& fixedNodes,
                                                const std::vector<double>& fixedDisplacements)
{
  if (fixedNodes.empty()) throw std::invalid_argument("a solve needs at least one fixed node");
  const std::size_t nodes = impl_->prepared.nodeCount();
  std::vector<char> seen(nodes, 0);
  for (std::int32_t node : fixedNodes) {
    if (node < 0 || std::size_t(node) >= nodes) {
      throw std::invalid_argument("fixed node " + std::to_string(node) + " is not a node of the prepared mesh");
    }
    if (seen[std::size_t(node)]++) throw std::invalid_argument("fixed node " + std::to_string(node) + " is given twice");
  }
  const std::vector<std::int32_t> before = impl_->fixedPart.fixedNodes;
  impl_->fixedPart.fixedNodes = fixedNodes;
  try {
    return solve(fixedDisplacements);
  } catch (const std::invalid_argument&) {
    impl_->fixedPart.fixedNodes = before; // nothing reached the worker
    throw;
  }
}

FiniteElementResult FiniteElementSession::solve(const std::vector<std::int32_t>& fixedNodes,
                                                const std::vector<double>& fixedDisplacements,
                                                const std::vector<SoftConstraint>& softConstraints,
                                                const SoftConstraintRejection& rejection)
{
  FiniteElementJob check;
  check.softConstraints = softConstraints;
  check.rejection = rejection;
  check.validateSoftConstraints(impl_->prepared.tetrahedronCount());
  impl_->fixedPart.softConstraints = softConstraints;
  impl_->fixedPart.rejection = rejection;
  struct Forget { // the constraints belong to this solve only
    FiniteElementJob& part;
    ~Forget() { part.softConstraints.clear(); part.rejection = {}; }
  } forget{impl_->fixedPart};
  return solve(fixedNodes, fixedDisplacements);
}

FiniteElementResult FiniteElementSession::solve(const std::vector<double>& fixedDisplacements)
{
  if (fixedDisplacements.size() != 3 * impl_->fixedPart.fixedNodes.size()) {
    throw std::invalid_argument("a solve needs 3 values per fixed node (" + std::to_string(3 * impl_->fixedPart.fixedNodes.size()) +
                                "), not " + std::to_string(fixedDisplacements.size()));
  }
  for (double d : fixedDisplacements) {
    if (!std::isfinite(d)) throw std::invalid_argument("a boundary displacement is not finite");
  }
  if (impl_->worker->exited()) throw MethodError("the finite element worker has stopped; prepare a new session");
  const int n = ++impl_->solves;
  const fs::path valuesFile = impl_->folder.path / ("values-" + std::to_string(n) + ".bsfe");
  const fs::path resultFile = impl_->folder.path / ("result-" + std::to_string(n) + ".bsfe");
  FiniteElementJob values = impl_->fixedPart;
  values.fixedDisplacements = fixedDisplacements;
  writeJobFor(values, valuesFile);
  impl_->worker->writeLine("solve " + valuesFile.string() + " " + resultFile.string());
  const auto answer = impl_->worker->readLine(impl_->options.timeoutSeconds);
  if (!answer) {
    impl_->worker->requireCleanExit();
    throw MethodError("the finite element worker stopped during a solve");
  }
  if (answer->rfind("failed", 0) == 0) throw MethodError("the finite element solve failed: " + answer->substr(std::min<std::size_t>(7, answer->size())));
  if (*answer != "solved") throw MethodError("the finite element worker answered '" + *answer + "'");
  FiniteElementResult result = readFiniteElementResult(resultFile);
  std::error_code ec;
  fs::remove(valuesFile, ec);
  fs::remove(resultFile, ec);
  return result;
}

} // namespace brainshift
