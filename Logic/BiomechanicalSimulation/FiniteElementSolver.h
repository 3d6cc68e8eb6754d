#pragma once
// Runs a finite element job in the MPI/PETSc worker (Worker/), as a separate process group
// started with mpiexec: progress streamed to the caller, a timeout, cancellation (terminate, then
// kill after a grace period, no orphaned ranks), and a worker that dies or fails turned into a
// clear error. The caller survives whatever the worker does.
#include "FiniteElementJob.h"

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
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

/// A worker that stays up between scans: the mesh and the boundary nodes are known before surgery,
/// only the imposed values arrive during it. The constructor prepares (partition, assembly,
/// elimination, preconditioner setup: the worker's `--serve` mode); each solve() answers a new set
/// of values for the same fixed nodes, reusing all of it. The worker is stopped on destruction.
class FiniteElementSession {
public:
  FiniteElementSession(const FiniteElementJob& job, FiniteElementRunOptions options);
  ~FiniteElementSession();
  FiniteElementSession(const FiniteElementSession&) = delete;
  FiniteElementSession& operator=(const FiniteElementSession&) = delete;

  /// Wall seconds of the preparation as the caller saw it (process start included).
  double prepareSeconds() const { return prepareSeconds_; }
  /// One solve; `fixedDisplacements` has 3 values per fixed node of the job, in its order.
  /// MethodError when the solve fails (the session stays usable) or the worker has died.
  FiniteElementResult solve(const std::vector<double>& fixedDisplacements);
  /// One solve with other fixed nodes of the same mesh (a later scan frees or imposes other
  /// surface nodes): the worker eliminates them anew and sets its preconditioner up again, keeping
  /// the partition and the assembled matrix. Later solves are for these nodes.
  FiniteElementResult solve(const std::vector<std::int32_t>& fixedNodes, const std::vector<double>& fixedDisplacements);
  /// One solve with soft constraints (matches of the image inside the brain) beside the fixed
  /// nodes, their worst rejected in rounds as `rejection` says; the operator changes with them, so
  /// the worker sets its preconditioner (or factorisation) up again for each round. Later solves
  /// without constraints go back to the prepared operator.
  FiniteElementResult solve(const std::vector<std::int32_t>& fixedNodes, const std::vector<double>& fixedDisplacements,
                            const std::vector<SoftConstraint>& softConstraints, const SoftConstraintRejection& rejection);
  /// The job the worker was prepared with (mesh, materials, options), to check a later job against.
  const FiniteElementJob& preparedJob() const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  double prepareSeconds_ = 0;
};

/// The worker beside the running executable (for the command line and the host).
std::filesystem::path workerBesideExecutable();

/// The PETSc options of a worker that solves more than once (a watch session's, a solve followed by
/// one with block matches): `given`, after conjugate gradients with incomplete Cholesky in the
/// blocks unless `given` chooses the method or the preconditioner. Each solve imposes other nodes
/// or constraints, and an incomplete Cholesky is set up again in a fraction of the time a Cholesky
/// factorisation is; PETSc's ILU(0) in the blocks is not always positive, and CG broke down on it
/// (KSP reason -8) on the small case meshed with grading 1.
std::string solverOptionsForRepeatedSolves(const std::string& given);

} // namespace brainshift
