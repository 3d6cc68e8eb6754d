#pragma once
// Runs a finite element job in the MPI/PETSc worker (Worker/), as a separate process group
// started with mpiexec: progress streamed to the caller, a timeout, cancellation (terminate, then
// kill after a grace period, no orphaned ranks), and a worker that dies or fails turned into a
// clear error. The caller survives whatever the worker does.
#include "FiniteElementJob.h"

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>

namespace brainshift {

struct FiniteElementRunOptions {
  int ranks = 1;
  std::filesystem::path worker;          ///< the brainshift-fe-worker executable
  std::string mpiexec = "mpiexec";
  std::filesystem::path hostfile;        ///< for a cluster; empty: this machine
  /// More ranks than cores is allowed (Open MPI's --oversubscribe); as root, Open MPI needs
  /// --allow-run-as-root: both are given when they apply, not left to surprise.
  bool allowOversubscription = true;
  double timeoutSeconds = 600;
  double cancelGraceSeconds = 3;
  std::filesystem::path workFolder;      ///< where the job and result files go (a temporary folder if empty)
  /// Called with the stage ("partition", "assembly", "setup", "solve", "done") and its fraction.
  std::function<void(const std::string&, double)> progress;
  const std::atomic<bool>* cancel = nullptr;
};

/// Solves. std::invalid_argument for a job that fails validate(); MethodError when the worker is
/// missing, dies, times out, is cancelled, or its solver does not converge (with its message).
FiniteElementResult solveWithWorker(const FiniteElementJob& job, const FiniteElementRunOptions& options);

/// The worker beside the running executable (for the command line and the host).
std::filesystem::path workerBesideExecutable();

} // namespace brainshift
