// brainshift-fe-worker JOB RESULT: solves a linear elastic problem on linear tetrahedra with
// imposed displacements (FiniteElementJob.h) in parallel with PETSc, as an MPI program.
// brainshift-fe-worker --serve JOB: prepares the same problem (before surgery) and then answers
// new imposed values for the same boundary nodes from standard input (during surgery).
//
// Every rank reads the job. The nodes are partitioned by recursive coordinate bisection, the same
// on every rank and every run (nodes weighted by the tetrahedra around them, which is the assembly
// work), nodes are renumbered so that each rank owns a contiguous block, each tetrahedron is
// assembled by the owner of its first node, the fixed dofs are eliminated keeping the matrix
// symmetric (MatZeroRowsColumns), and the system is solved by the tuned default (setTunedDefault:
// chosen by measurement, by size and by whether the problem is served) unless the job's options
// say otherwise. The
// convergence reason is checked. Progress goes to stdout as "progress <stage> <fraction>" lines.
// Exit status: 0 solved, 2 bad job (options PETSc refuses or never reads included), 3 the solver
// did not converge or its solution does not satisfy the equations (true residual), 1 anything else.
#include "FiniteElementJob.h"
#include "NumberText.h"

#include <petscksp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <numeric>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {
using namespace brainshift;

struct WorkerFailure : std::runtime_error {
  WorkerFailure(int status, const std::string& message) : std::runtime_error(message), status(status) {}
  int status;
};

void check(PetscErrorCode code, const char* what)
{
  if (code) throw WorkerFailure(1, std::string("PETSc failed in ") + what + " (error " + std::to_string(code) + ")");
}

void progress(int rank, const char* stage, double fraction)
{
  if (rank == 0) {
    std::printf("progress %s %.3f\n", stage, fraction);
    std::fflush(stdout);
  }
}

double maxOverRanks(double value)
{
  double result = value;
  MPI_Allreduce(&value, &result, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  return result;
}

/// New global number of every node (all ranks hold the whole map) and this rank's range.
struct Numbering {
  std::vector<PetscInt> newOfOld;
  PetscInt firstOwned = 0, ownedCount = 0;
  std::vector<PetscInt> rangeStarts; // per rank, size ranks + 1
  std::string partitioner;
  int ownerOf(PetscInt newNode) const
  {
    return int(std::upper_bound(rangeStarts.begin(), rangeStarts.end(), newNode) - rangeStarts.begin()) - 1;
  }
};

/// The ranks' parts of the nodes by recursive coordinate bisection, the same on every rank (each
/// holds the whole job): the nodes split across the longest side of their bounding box where the
/// work (the tetrahedra around each node, which is the assembly) divides in proportion to the
/// ranks on either side, then each side again. Deterministic: the same job on the same ranks, the
/// same parts, iterates and displacements to the last bit. (PT-Scotch, used before, breaks ties
/// with a generator seeded anew each run and runs non-deterministic parallel coarsening: the same
/// job got another partition each run, and a displacement a few 1e-5 mm off; Debian's build offers
/// no deterministic mode.)
std::vector<int> bisectedOwners(const FiniteElementJob& job, int size)
{
  const std::size_t n = job.nodeCount();
  std::vector<double> work(n, 0.0);
  for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
    for (int a = 0; a < 4; ++a) work[std::size_t(job.tetrahedra[4 * t + std::size_t(a)])] += 1;
  }
  for (double& w : work) w = std::max(w, 1.0);
  std::vector<int> owner(n, 0);
  std::vector<std::size_t> nodes(n);
  std::iota(nodes.begin(), nodes.end(), std::size_t(0));
  // Splits nodes[begin, end) among ranks [firstRank, firstRank + ranks).
  std::function<void(std::size_t, std::size_t, int, int)> split = [&](std::size_t begin, std::size_t end, int firstRank, int ranks) {
    if (ranks == 1 || end - begin <= 1) {
      for (std::size_t i = begin; i < end; ++i) owner[nodes[i]] = firstRank;
      return;
    }
    std::array<double, 3> low{1e300, 1e300, 1e300}, high{-1e300, -1e300, -1e300};
    for (std::size_t i = begin; i < end; ++i) {
      for (int d = 0; d < 3; ++d) {
        const double x = job.nodes[3 * nodes[i] + std::size_t(d)];
        low[std::size_t(d)] = std::min(low[std::size_t(d)], x);
        high[std::size_t(d)] = std::max(high[std::size_t(d)], x);
      }
    }
    int axis = 0;
    for (int d = 1; d < 3; ++d) {
      if (high[std::size_t(d)] - low[std::size_t(d)] > high[std::size_t(axis)] - low[std::size_t(axis)]) axis = d;
    }
    std::sort(nodes.begin() + std::ptrdiff_t(begin), nodes.begin() + std::ptrdiff_t(end), [&](std::size_t a, std::size_t b) {
      const double xa = job.nodes[3 * a + std::size_t(axis)], xb = job.nodes[3 * b + std::size_t(axis)];
      return xa < xb || (xa == xb && a < b); // ties by node number: one order on every rank
    });
    const int lowRanks = ranks / 2;
    double total = 0;
    for (std::size_t i = begin; i < end; ++i) total += work[nodes[i]];
    const double target = total * double(lowRanks) / double(ranks);
    double sum = 0;
    std::size_t middle = begin;
    while (middle < end - 1 && sum + work[nodes[middle]] <= target) sum += work[nodes[middle++]];
    middle = std::max(middle, begin + 1);
    split(begin, middle, firstRank, lowRanks);
    split(middle, end, firstRank + lowRanks, ranks - lowRanks);
  };
  split(0, n, 0, size);
  return owner;
}

Numbering partitionNodes(const FiniteElementJob& job, int rank, int size)
{
  const PetscInt n = PetscInt(job.nodeCount());
  Numbering numbering;
  numbering.newOfOld.resize(std::size_t(n));
  numbering.rangeStarts.assign(std::size_t(size) + 1, 0);
  if (size == 1) {
    std::iota(numbering.newOfOld.begin(), numbering.newOfOld.end(), 0);
    numbering.ownedCount = n;
    numbering.rangeStarts = {0, n};
    numbering.partitioner = "none (one rank)";
    return numbering;
  }
  // Each rank's nodes numbered in a block, in their old order (as PETSc's ISPartitioningToNumbering).
  const std::vector<int> owner = bisectedOwners(job, size);
  for (int o : owner) numbering.rangeStarts[std::size_t(o) + 1] += 1;
  for (int r = 0; r < size; ++r) numbering.rangeStarts[std::size_t(r) + 1] += numbering.rangeStarts[std::size_t(r)];
  std::vector<PetscInt> next(numbering.rangeStarts.begin(), numbering.rangeStarts.end() - 1);
  for (PetscInt old = 0; old < n; ++old) numbering.newOfOld[std::size_t(old)] = next[std::size_t(owner[std::size_t(old)])]++;
  numbering.firstOwned = numbering.rangeStarts[std::size_t(rank)];
  numbering.ownedCount = numbering.rangeStarts[std::size_t(rank) + 1] - numbering.firstOwned;
  numbering.partitioner = "recursive coordinate bisection";
  return numbering;
}

/// The tuned default solver, chosen by measurement on brain meshes of the built-in case
/// (`brainshift bench simulate`, Testing/Benchmarks/results/simulate: 20,037 to 933,141 equations,
/// 1 and 2 ranks, each solution compared with the exact one). It applies unless the job's options
/// choose the Krylov method or the preconditioner themselves (-ksp_type, -pc_type); any other
/// option (-ksp_rtol, ...) goes over it.
/// - Solved once (the command line's simulate stage): up to kSmallProblemLimit equations, CG with
///   block Jacobi and incomplete Cholesky in each rank's block: no setup to speak of, the fastest
///   whole stage at 78,480 and 245,502 equations (0.8 s and 4.1 s on one rank, against 3.1 s and
///   12 s for CG + GAMG). PETSc's default ILU(0) in the blocks is not always positive: CG broke
///   down on it (KSP reason -8) at 933,141 equations, and there incomplete Cholesky, shifted to
///   stay positive, took 303 iterations to stop 0.25 mm from the solution. Above the limit, GMRES
///   with block Jacobi/ILU(0), the seed paper's solver: the fastest whole stage at 933,141
///   equations (30 s on one rank, 19 s on two, against 43 s and 26 s for CG + GAMG, whose setup
///   is the cost), within 0.01 mm.
/// - Served (prepared before surgery, solved for each scan): up to kSmallProblemLimit equations,
///   a sparse Cholesky factorisation kept between scans, CHOLMOD on one rank and MUMPS on several;
///   the during-surgery solve is then two triangular solves (0.07-0.1 s at 78,480 equations,
///   0.45-0.6 s at 245,502, against 0.26 s and 1.8 s for the fastest iterative solver). Above it
///   the factorisation's time and memory grow too fast (28 s to factor 245,502 equations): CG with
///   GAMG (rigid body modes as near-nullspace), the fastest during-surgery solve at 933,141
///   equations (12 s on two ranks), its iterations flat under refinement (19 to 25).
/// - Iterative solvers stop at a relative (preconditioned) residual of kRelativeTolerance: in the
///   tolerance sweep (78,480 equations) the displacement then lies within 4e-4 mm of the exact
///   solution with CG + block Jacobi and 6e-4 mm with CG + GAMG, far below the model's own error,
///   for a third less time than at 1e-6.
constexpr std::int64_t kSmallProblemLimit = 300000;
constexpr double kRelativeTolerance = 1e-5;
/// The true relative residual may exceed the solver's tolerance by this factor (the solver
/// watches the preconditioned residual).
constexpr double kResidualSlack = 10;

void setTunedDefault(KSP ksp, PC pc, std::int64_t equations, int ranks, bool served)
{
  PetscBool kspTypeGiven = PETSC_FALSE, pcTypeGiven = PETSC_FALSE;
  check(PetscOptionsHasName(nullptr, nullptr, "-ksp_type", &kspTypeGiven), "PetscOptionsHasName");
  check(PetscOptionsHasName(nullptr, nullptr, "-pc_type", &pcTypeGiven), "PetscOptionsHasName");
  check(KSPSetTolerances(ksp, kRelativeTolerance, PETSC_DEFAULT, PETSC_DEFAULT, 20000), "KSPSetTolerances");
  check(KSPSetType(ksp, KSPCG), "KSPSetType");
  if (kspTypeGiven || pcTypeGiven) { // the job chooses: CG + GAMG beneath its options
    check(PCSetType(pc, PCGAMG), "PCSetType");
    return;
  }
  const bool small = equations <= kSmallProblemLimit;
  if (served && small) {
    check(KSPSetType(ksp, KSPPREONLY), "KSPSetType");
    check(PCSetType(pc, PCCHOLESKY), "PCSetType");
    check(PCFactorSetMatSolverType(pc, ranks == 1 ? MATSOLVERCHOLMOD : MATSOLVERMUMPS), "PCFactorSetMatSolverType");
  } else if (served) {
    check(PCSetType(pc, PCGAMG), "PCSetType");
  } else if (!small) {
    check(KSPSetType(ksp, KSPGMRES), "KSPSetType");
    check(PCSetType(pc, PCBJACOBI), "PCSetType");
  } else {
    check(PCSetType(pc, PCBJACOBI), "PCSetType");
    // Incomplete Cholesky in each rank's block, shifted to stay positive definite: PETSc's default
    // ILU(0) there is not always positive, and CG broke down on it (KSP reason -8) on the
    // benchmark's 933,141-equation brain.
    PetscBool subTypeGiven = PETSC_FALSE;
    check(PetscOptionsHasName(nullptr, nullptr, "-sub_pc_type", &subTypeGiven), "PetscOptionsHasName");
    if (!subTypeGiven) check(PetscOptionsSetValue(nullptr, "-sub_pc_type", "icc"), "PetscOptionsSetValue");
  }
}

/// The prepared problem: partitioned, assembled, fixed dofs eliminated, solver set up. Only the
/// imposed values change between solves (one right-hand side each), so a served worker keeps it.
class PreparedProblem {
public:
  /// `served`: the problem is prepared once and solved for many sets of values (--serve).
  PreparedProblem(const FiniteElementJob& job, int rank, int size, bool served)
    : job_(job), rank_(rank), size_(size)
  {
    result_.ranks = size;
    n_ = PetscInt(job.nodeCount());
    result_.equations = 3 * std::int64_t(n_);
    double clock = MPI_Wtime();

    progress(rank, "partition", 0.0);
    numbering_ = partitionNodes(job, rank, size);
    result_.partitioner = numbering_.partitioner;
    first_ = numbering_.firstOwned;
    owned_ = numbering_.ownedCount;

    const AssemblyShare share = assemblyShare();
    createPreallocatedMatrix(share);
    progress(rank, "assembly", 0.0);
    assemble(share);
    // The assembled matrix before elimination gives the right-hand side of each new set of values.
    check(MatDuplicate(A_, MAT_COPY_VALUES, &assembled_), "MatDuplicate");
    eliminate(job.fixedNodes); // keeping A symmetric
    setRigidBodyModes();
    result_.assemblySeconds = maxOverRanks(MPI_Wtime() - clock);

    clock = MPI_Wtime();
    progress(rank, "setup", 0.0);
    setUpSolver(served);
    result_.setupSeconds = maxOverRanks(MPI_Wtime() - clock);
    check(MatCreateVecs(A_, &x_, &b_), "MatCreateVecs");
    if (served) requireEveryOptionRead(true);
  }

  ~PreparedProblem()
  {
    KSPDestroy(&ksp_);
    VecDestroy(&x_);
    VecDestroy(&b_);
    VecDestroy(&softRightHandSide_);
    MatDestroy(&constrained_);
    MatDestroy(&assembled_);
    MatDestroy(&A_);
  }

  /// The soft constraints marked active join the operator (H^T W H, within the pattern: a
  /// constraint couples the nodes of one tetrahedron) and the right-hand side (H^T W target); the
  /// fixed dofs are eliminated anew and the solver set up again. No constraint and none before:
  /// nothing to do beyond a change of fixed nodes.
  void constrain(const std::vector<SoftConstraint>& constraints, const std::vector<char>& active,
                 const std::vector<std::int32_t>& fixedNodes)
  {
    const bool any = std::find(active.begin(), active.end(), char(1)) != active.end();
    if (!any && !softActive_) {
      if (fixedNodes != fixedNodes_) refix(fixedNodes);
      return;
    }
    const double clock = MPI_Wtime();
    if (!constrained_) {
      check(MatDuplicate(assembled_, MAT_COPY_VALUES, &constrained_), "MatDuplicate");
      check(VecDuplicate(b_, &softRightHandSide_), "VecDuplicate");
    } else {
      check(MatCopy(assembled_, constrained_, SAME_NONZERO_PATTERN), "MatCopy");
    }
    check(VecSet(softRightHandSide_, 0.0), "VecSet");
    for (std::size_t i = 0; i < constraints.size(); ++i) {
      if (!active[i]) continue;
      const SoftConstraint& c = constraints[i];
      PetscInt blocks[4];
      for (int k = 0; k < 4; ++k) blocks[k] = numbering_.newOfOld[std::size_t(job_.tetrahedra[4 * std::size_t(c.tetrahedron) + k])];
      if (!mine(blocks[0])) continue; // assembled by the owner of the first node, as the tetrahedron
      const double W[3][3] = {{c.stiffness[0], c.stiffness[1], c.stiffness[2]},
                              {c.stiffness[1], c.stiffness[3], c.stiffness[4]},
                              {c.stiffness[2], c.stiffness[4], c.stiffness[5]}};
      double block[144], rhs[12];
      for (int a = 0; a < 4; ++a) {
        for (int r = 0; r < 3; ++r) {
          rhs[3 * a + r] = c.weights[a] * (W[r][0] * c.target[0] + W[r][1] * c.target[1] + W[r][2] * c.target[2]);
          for (int b = 0; b < 4; ++b) {
            for (int q = 0; q < 3; ++q) block[(3 * a + r) * 12 + 3 * b + q] = c.weights[a] * c.weights[b] * W[r][q];
          }
        }
      }
      check(MatSetValuesBlocked(constrained_, 4, blocks, 4, blocks, block, ADD_VALUES), "MatSetValuesBlocked");
      check(VecSetValuesBlocked(softRightHandSide_, 4, blocks, rhs, ADD_VALUES), "VecSetValuesBlocked");
    }
    check(MatAssemblyBegin(constrained_, MAT_FINAL_ASSEMBLY), "MatAssemblyBegin");
    check(MatAssemblyEnd(constrained_, MAT_FINAL_ASSEMBLY), "MatAssemblyEnd");
    check(VecAssemblyBegin(softRightHandSide_), "VecAssemblyBegin");
    check(VecAssemblyEnd(softRightHandSide_), "VecAssemblyEnd");
    softActive_ = any;
    check(MatCopy(softActive_ ? constrained_ : assembled_, A_, SAME_NONZERO_PATTERN), "MatCopy");
    eliminate(fixedNodes);
    check(KSPSetOperators(ksp_, A_, A_), "KSPSetOperators");
    check(KSPSetUp(ksp_), "KSPSetUp");
    check(KSPSetUpOnBlocks(ksp_), "KSPSetUpOnBlocks");
    result_.setupSeconds = maxOverRanks(MPI_Wtime() - clock);
  }

  /// Another set of fixed nodes on the same mesh (a later scan imposes other nodes): the
  /// elimination is redone from the assembled matrix, and the preconditioner (or factorisation) set
  /// up again; partition, preallocation and assembly are kept.
  void refix(const std::vector<std::int32_t>& fixedNodes)
  {
    const double clock = MPI_Wtime();
    check(MatCopy(softActive_ ? constrained_ : assembled_, A_, SAME_NONZERO_PATTERN), "MatCopy");
    eliminate(fixedNodes);
    check(KSPSetOperators(ksp_, A_, A_), "KSPSetOperators");
    check(KSPSetUp(ksp_), "KSPSetUp");
    check(KSPSetUpOnBlocks(ksp_), "KSPSetUpOnBlocks");
    fixedNodes_ = fixedNodes;
    result_.setupSeconds = maxOverRanks(MPI_Wtime() - clock);
  }

  const std::vector<std::int32_t>& fixedNodes() const { return fixedNodes_; }

  /// Solves for one set of imposed values (3 per fixed node, in the job's order). `warmStart`: an
  /// iterative solver starts from the last solution (a round of rejection changes it little).
  FiniteElementResult solveFor(const std::vector<double>& values, bool warmStart = false)
  {
    FiniteElementResult result = result_;
    const double clock = MPI_Wtime();
    progress(rank_, "solve", 0.0);
    // x: the imposed values on the fixed dofs, 0 elsewhere; b = -A0 x, then the values on the fixed rows.
    Vec start = nullptr;
    if (warmStart) {
      check(VecDuplicate(x_, &start), "VecDuplicate");
      check(VecCopy(x_, start), "VecCopy");
    }
    check(VecSet(x_, 0.0), "VecSet");
    for (const auto& [row, index] : fixedRows_) check(VecSetValue(x_, row, values[index], INSERT_VALUES), "VecSetValue");
    check(VecAssemblyBegin(x_), "VecAssemblyBegin");
    check(VecAssemblyEnd(x_), "VecAssemblyEnd");
    check(MatMult(softActive_ ? constrained_ : assembled_, x_, b_), "MatMult");
    check(VecScale(b_, -1.0), "VecScale");
    if (softActive_) check(VecAXPY(b_, 1.0, softRightHandSide_), "VecAXPY");
    for (const auto& [row, index] : fixedRows_) check(VecSetValue(b_, row, values[index], INSERT_VALUES), "VecSetValue");
    check(VecAssemblyBegin(b_), "VecAssemblyBegin");
    check(VecAssemblyEnd(b_), "VecAssemblyEnd");
    if (start) { // the last solution, its fixed dofs the imposed values
      check(VecCopy(start, x_), "VecCopy");
      VecDestroy(&start);
      for (const auto& [row, index] : fixedRows_) check(VecSetValue(x_, row, values[index], INSERT_VALUES), "VecSetValue");
      check(VecAssemblyBegin(x_), "VecAssemblyBegin");
      check(VecAssemblyEnd(x_), "VecAssemblyEnd");
    }
    check(KSPSolve(ksp_, b_, x_), "KSPSolve");
    result.solveSeconds = maxOverRanks(MPI_Wtime() - clock);
    const KSPConvergedReason reason = convergedReasonOverRanks();
    result.convergedReason = int(reason);
    PetscInt iterations;
    check(KSPGetIterationNumber(ksp_, &iterations), "KSPGetIterationNumber");
    result.iterations = int(iterations);
    result.relativeResidual = trueRelativeResidual();
    if (reason <= 0) {
      throw WorkerFailure(3, "the solver (" + result.solver + ") did not converge: KSP reason " + std::to_string(int(reason)) +
                               " after " + std::to_string(result.iterations) + " iterations, relative residual " +
                               numberText(result.relativeResidual) + preconditionerFailure(reason));
    }
    requireTrueResidual(result);
    // The imposed values exactly (the solver met them only to its tolerance).
    for (const auto& [row, index] : fixedRows_) check(VecSetValue(x_, row, values[index], INSERT_VALUES), "VecSetValue");
    check(VecAssemblyBegin(x_), "VecAssemblyBegin");
    check(VecAssemblyEnd(x_), "VecAssemblyEnd");

    // The displacements, back in the job's node order, on rank 0.
    VecScatter toZero;
    Vec gathered;
    check(VecScatterCreateToZero(x_, &toZero, &gathered), "VecScatterCreateToZero");
    check(VecScatterBegin(toZero, x_, gathered, INSERT_VALUES, SCATTER_FORWARD), "VecScatterBegin");
    check(VecScatterEnd(toZero, x_, gathered, INSERT_VALUES, SCATTER_FORWARD), "VecScatterEnd");
    if (rank_ == 0) {
      const PetscScalar* g;
      check(VecGetArrayRead(gathered, &g), "VecGetArrayRead");
      result.displacements.resize(std::size_t(3 * n_));
      for (PetscInt old = 0; old < n_; ++old) {
        const PetscInt node = numbering_.newOfOld[std::size_t(old)];
        for (int d = 0; d < 3; ++d) result.displacements[std::size_t(3 * old + d)] = double(g[3 * node + d]);
      }
      check(VecRestoreArrayRead(gathered, &g), "VecRestoreArrayRead");
    }
    VecScatterDestroy(&toZero);
    VecDestroy(&gathered);
    progress(rank_, "done", 1.0);
    return result;
  }

private:
  /// This rank's part of the assembly: the tetrahedra it assembles (those whose first node it
  /// owns) and, for each node it owns, how many neighbouring nodes' blocks of 3 fall in its own
  /// columns and in other ranks' (the preallocation).
  struct AssemblyShare {
    std::vector<std::size_t> tetrahedra;
    std::vector<PetscInt> diagonalBlocks, offDiagonalBlocks;
  };

  AssemblyShare assemblyShare() const
  {
    AssemblyShare share;
    std::vector<std::vector<PetscInt>> blockNeighbours(static_cast<std::size_t>(owned_));
    for (std::size_t t = 0; t < job_.tetrahedronCount(); ++t) {
      PetscInt v[4];
      for (int k = 0; k < 4; ++k) v[k] = numbering_.newOfOld[std::size_t(job_.tetrahedra[4 * t + k])];
      if (mine(v[0])) share.tetrahedra.push_back(t);
      for (int a = 0; a < 4; ++a) {
        if (!mine(v[a])) continue;
        for (int b = 0; b < 4; ++b) blockNeighbours[std::size_t(v[a] - first_)].push_back(v[b]);
      }
    }
    share.diagonalBlocks.assign(static_cast<std::size_t>(owned_), 0);
    share.offDiagonalBlocks.assign(static_cast<std::size_t>(owned_), 0);
    for (PetscInt i = 0; i < owned_; ++i) {
      auto& list = blockNeighbours[std::size_t(i)];
      std::sort(list.begin(), list.end());
      list.erase(std::unique(list.begin(), list.end()), list.end());
      for (PetscInt c : list) (mine(c) ? share.diagonalBlocks : share.offDiagonalBlocks)[std::size_t(i)] += 1;
      if (list.empty()) share.diagonalBlocks[std::size_t(i)] = 1; // a node in no tetrahedron (kept solvable)
      std::vector<PetscInt>().swap(list);
    }
    return share;
  }

  /// The stiffness matrix, empty: block rows of 3, exactly preallocated (a new nonzero is an error).
  void createPreallocatedMatrix(const AssemblyShare& share)
  {
    check(MatCreate(PETSC_COMM_WORLD, &A_), "MatCreate");
    check(MatSetSizes(A_, 3 * owned_, 3 * owned_, 3 * n_, 3 * n_), "MatSetSizes");
    check(MatSetBlockSize(A_, 3), "MatSetBlockSize");
    check(MatSetType(A_, MATAIJ), "MatSetType");
    check(MatSetOptionsPrefix(A_, "elasticity_"), "MatSetOptionsPrefix");
    check(MatSetFromOptions(A_), "MatSetFromOptions");
    check(MatXAIJSetPreallocation(A_, 3, share.diagonalBlocks.data(), share.offDiagonalBlocks.data(), nullptr, nullptr),
          "MatXAIJSetPreallocation");
    check(MatSetOption(A_, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE), "MatSetOption");
  }

  /// Each tetrahedron's stiffness added in; a node in no tetrahedron gets the identity.
  void assemble(const AssemblyShare& share)
  {
    for (std::size_t t : share.tetrahedra) {
      double p[4][3];
      PetscInt blocks[4];
      for (int k = 0; k < 4; ++k) {
        const std::size_t old = std::size_t(job_.tetrahedra[4 * t + k]);
        for (int d = 0; d < 3; ++d) p[k][d] = job_.nodes[3 * old + d];
        blocks[k] = numbering_.newOfOld[old];
      }
      double K[144];
      tetrahedronStiffness(p, job_.materials[std::size_t(job_.materialOfTetrahedron[t])], K);
      check(MatSetValuesBlocked(A_, 4, blocks, 4, blocks, K, ADD_VALUES), "MatSetValuesBlocked");
    }
    for (PetscInt i = 0; i < owned_; ++i) {
      if (share.offDiagonalBlocks[std::size_t(i)] == 0 && share.diagonalBlocks[std::size_t(i)] == 1) {
        const PetscInt row = first_ + i;
        const double identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
        check(MatSetValuesBlocked(A_, 1, &row, 1, &row, identity, ADD_VALUES), "MatSetValuesBlocked");
      }
    }
    check(MatAssemblyBegin(A_, MAT_FINAL_ASSEMBLY), "MatAssemblyBegin");
    check(MatAssemblyEnd(A_, MAT_FINAL_ASSEMBLY), "MatAssemblyEnd");
    // Symmetric positive definite, and stays so through every elimination (1 on the diagonal of a
    // fixed dof) and soft constraint (H^T W H added): said once for good. (Positive definite as long
    // as the fixed nodes pin every piece of the mesh, as the surface's imposed nodes do; a piece
    // left free is singular either way, and its solve fails its true-residual check.) A factorisation then
    // takes it without pivoting (MUMPS's SYM=1, not the symmetric indefinite SYM=2, whose pivots
    // follow the rounding of the ranks' sums and once outgrew MUMPS's memory estimate: KSP reason
    // -11 in a fresh-clone run of FiniteElementSessionTest).
    check(MatSetOption(A_, MAT_SPD, PETSC_TRUE), "MatSetOption");
    check(MatSetOption(A_, MAT_SPD_ETERNAL, PETSC_TRUE), "MatSetOption");
    std::int64_t mineCount = std::int64_t(share.tetrahedra.size());
    result_.tetrahedraPerRank.resize(std::size_t(size_));
    MPI_Allgather(&mineCount, 1, MPI_INT64_T, result_.tetrahedraPerRank.data(), 1, MPI_INT64_T, PETSC_COMM_WORLD);
  }

  /// The rigid body modes as the operator's near-nullspace, for the multigrid (coordinates in the
  /// new numbering).
  void setRigidBodyModes()
  {
    Vec coordinates;
    check(VecCreateMPI(PETSC_COMM_WORLD, 3 * owned_, 3 * n_, &coordinates), "VecCreateMPI");
    check(VecSetBlockSize(coordinates, 3), "VecSetBlockSize");
    PetscScalar* c;
    check(VecGetArray(coordinates, &c), "VecGetArray");
    for (PetscInt old = 0; old < n_; ++old) {
      const PetscInt node = numbering_.newOfOld[std::size_t(old)];
      if (!mine(node)) continue;
      for (int d = 0; d < 3; ++d) c[3 * (node - first_) + d] = job_.nodes[3 * std::size_t(old) + std::size_t(d)];
    }
    check(VecRestoreArray(coordinates, &c), "VecRestoreArray");
    MatNullSpace rigidBodyModes;
    check(MatNullSpaceCreateRigidBody(coordinates, &rigidBodyModes), "MatNullSpaceCreateRigidBody");
    check(MatSetNearNullSpace(A_, rigidBodyModes), "MatSetNearNullSpace");
    MatNullSpaceDestroy(&rigidBodyModes);
    VecDestroy(&coordinates);
  }

  /// The solver: the tuned default, then the job's options over it; set up once, here.
  void setUpSolver(bool served)
  {
    check(KSPCreate(PETSC_COMM_WORLD, &ksp_), "KSPCreate");
    check(KSPSetOperators(ksp_, A_, A_), "KSPSetOperators");
    PC pc;
    check(KSPGetPC(ksp_, &pc), "KSPGetPC");
    setTunedDefault(ksp_, pc, result_.equations, size_, served);
    if (KSPSetFromOptions(ksp_)) throw WorkerFailure(2, "the solver options are refused (" + job_.solverOptions + ")");
    KSPType kspType;
    check(KSPGetType(ksp_, &kspType), "KSPGetType");
    // The imposed values are a good start for an iterative solver (a direct one takes none).
    check(KSPSetInitialGuessNonzero(ksp_, std::string(kspType) == KSPPREONLY ? PETSC_FALSE : PETSC_TRUE), "KSPSetInitialGuessNonzero");
    check(KSPSetUp(ksp_), "KSPSetUp");
    check(PCSetUp(pc), "PCSetUp");
    // Block preconditioners (block Jacobi, ASM) factor their blocks on the first solve unless told
    // now: that work belongs to the preparation.
    check(KSPSetUpOnBlocks(ksp_), "KSPSetUpOnBlocks");
    result_.solver = solverName(kspType, pc);
  }

  /// What solves, for the report: e.g. cg+bjacobi/icc (block Jacobi and what each block holds),
  /// cholesky+cholmod (a factorisation and its package).
  static std::string solverName(KSPType kspType, PC pc)
  {
    PCType pcType;
    check(PCGetType(pc, &pcType), "PCGetType");
    if (std::string(pcType) == PCCHOLESKY || std::string(pcType) == PCLU) {
      MatSolverType package = nullptr;
      check(PCFactorGetMatSolverType(pc, &package), "PCFactorGetMatSolverType");
      return std::string(pcType) + "+" + (package ? package : MATSOLVERPETSC);
    }
    std::string name = std::string(kspType) + "+" + pcType;
    if (std::string(pcType) == PCBJACOBI) {
      PetscInt blocks = 0;
      KSP* subSolvers = nullptr;
      check(PCBJacobiGetSubKSP(pc, &blocks, nullptr, &subSolvers), "PCBJacobiGetSubKSP");
      if (blocks > 0) {
        PC subPc;
        PCType subType;
        check(KSPGetPC(subSolvers[0], &subPc), "KSPGetPC");
        check(PCGetType(subPc, &subType), "PCGetType");
        name += std::string("/") + subType;
      }
    }
    return name;
  }

  bool mine(PetscInt newNode) const { return newNode >= first_ && newNode < first_ + owned_; }

  /// Whatever reason PETSc gives (a Richardson run stopped by -ksp_max_it, a NaN from absurd
  /// moduli), the solution must satisfy the equations: the true relative residual within the
  /// solver's tolerance, with kResidualSlack for the gap between the preconditioned residual
  /// the solver watched and the true one.
  void requireTrueResidual(const FiniteElementResult& result) const
  {
    PetscReal rtol = kRelativeTolerance, abstol = 0, dtol = 0;
    PetscInt maxits = 0;
    check(KSPGetTolerances(ksp_, &rtol, &abstol, &dtol, &maxits), "KSPGetTolerances");
    const double allowed = std::max(double(rtol), 1e-12) * kResidualSlack;
    if (!std::isfinite(result.relativeResidual) || !(result.relativeResidual <= allowed)) {
      char text[256];
      std::snprintf(text, sizeof text, "the solution does not satisfy the equations: true relative residual %.3g, above %.3g "
                    "(%g times the tolerance %.3g); the solver (%s) stopped after %d iterations with KSP reason %d",
                    result.relativeResidual, allowed, kResidualSlack, double(rtol), result.solver.c_str(), result.iterations,
                    result.convergedReason);
      throw WorkerFailure(3, text);
    }
  }

public:
  /// Every solver option given was read by PETSc: a misspelt or unknown one (-ksp_typo) would
  /// otherwise be ignored in silence. `beforeSolve`: the options PETSc reads only in KSPSolve
  /// (views, monitors of the reason) are still to come and not counted. A direct solve (preonly)
  /// meets any tolerance: its tolerances and iteration limits, unread, are not counted either.
  void requireEveryOptionRead(bool beforeSolve) const
  {
    KSPType type;
    check(KSPGetType(ksp_, &type), "KSPGetType");
    const bool direct = std::string(type) == KSPPREONLY;
    PetscInt count = 0;
    char** names = nullptr;
    char** values = nullptr;
    check(PetscOptionsLeftGet(nullptr, &count, &names, &values), "PetscOptionsLeftGet");
    std::string unread;
    for (PetscInt i = 0; i < count; ++i) {
      const std::string name = names[i];
      if (name == "-serve") continue; // the worker's own argument (--serve JOB), which PETSc also parses
      if (direct && (name == "ksp_rtol" || name == "ksp_atol" || name == "ksp_divtol" || name == "ksp_max_it")) continue;
      if (beforeSolve && (name.rfind("ksp_view", 0) == 0 || name.rfind("ksp_converged_reason", 0) == 0)) continue;
      unread += (unread.empty() ? "-" : ", -") + name + (values[i] ? std::string(" ") + values[i] : std::string());
    }
    check(PetscOptionsLeftRestore(nullptr, &count, &names, &values), "PetscOptionsLeftRestore");
    if (!unread.empty()) {
      throw WorkerFailure(2, "unknown or unused solver option " + unread +
                               " (not a PETSc option of this solver; see the KSP and PC manual pages)");
    }
  }

private:
  /// The solve's reason, the same on every rank: a preconditioner that fails on some ranks only
  /// (preonly with a rank's own block) sets it there only, so the ranks take the worst, and all
  /// fail together (and all come to the collective of preconditionerFailure).
  KSPConvergedReason convergedReasonOverRanks() const
  {
    KSPConvergedReason reason;
    check(KSPGetConvergedReason(ksp_, &reason), "KSPGetConvergedReason");
    const int local = int(reason);
    int worst = local;
    MPI_Allreduce(&local, &worst, 1, MPI_INT, MPI_MIN, PETSC_COMM_WORLD);
    return worst <= 0 ? KSPConvergedReason(worst) : reason;
  }

  /// ||b - A x|| / ||b||, whatever norm the solver watched (||b - A x|| when b is 0).
  double trueRelativeResidual() const
  {
    Vec r;
    check(VecDuplicate(b_, &r), "VecDuplicate");
    check(MatMult(A_, x_, r), "MatMult");
    check(VecAYPX(r, -1.0, b_), "VecAYPX");
    PetscReal residual, rhs;
    check(VecNorm(r, NORM_2, &residual), "VecNorm");
    check(VecNorm(b_, NORM_2, &rhs), "VecNorm");
    VecDestroy(&r);
    return rhs > 0 ? double(residual / rhs) : double(residual);
  }

  /// Why the preconditioner failed (KSP reason -11), for the message: PETSc's reason on any rank
  /// and, for a MUMPS factorisation, MUMPS's own error code (INFOG(1), INFOG(2)); empty otherwise.
  std::string preconditionerFailure(KSPConvergedReason reason) const
  {
    if (reason != KSP_DIVERGED_PC_FAILED) return {}; // reduced over the ranks: all or none come here
    PC pc = nullptr;
    PCFailedReason local = PC_NOERROR;
    if (KSPGetPC(ksp_, &pc) || PCGetFailedReasonRank(pc, &local)) local = PC_NOERROR;
    // The ranks agree on the KSP reason, not on the PC's: a rank's failure, whichever (none: -1000).
    const int mine = local == PC_NOERROR ? -1000 : int(local);
    int any = mine;
    MPI_Allreduce(&mine, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    std::string text = "; the preconditioner failed: " + std::string(any == -1000 ? "on no rank's own account" : PCFailedReasons[any]);
    MatSolverType package = nullptr;
    Mat factor = nullptr;
    PetscInt infog1 = 0, infog2 = 0;
    if (!PCFactorGetMatSolverType(pc, &package) && package && std::strcmp(package, MATSOLVERMUMPS) == 0 &&
        !PCFactorGetMatrix(pc, &factor) && !MatMumpsGetInfog(factor, 1, &infog1) && !MatMumpsGetInfog(factor, 2, &infog2)) {
      text += " (MUMPS INFOG(1) " + std::to_string(infog1) + ", INFOG(2) " + std::to_string(infog2) + ")";
    }
    return text;
  }

  /// Zeroes the rows and columns of the fixed dofs of A (1 on the diagonal), keeping it symmetric.
  void eliminate(const std::vector<std::int32_t>& fixedNodes)
  {
    fixedRows_.clear();
    for (std::size_t f = 0; f < fixedNodes.size(); ++f) {
      const PetscInt node = numbering_.newOfOld[std::size_t(fixedNodes[f])];
      if (!mine(node)) continue;
      for (int d = 0; d < 3; ++d) fixedRows_.push_back({3 * node + d, 3 * f + std::size_t(d)});
    }
    std::vector<PetscInt> rows;
    for (const auto& r : fixedRows_) rows.push_back(r.first);
    check(MatZeroRowsColumns(A_, PetscInt(rows.size()), rows.data(), 1.0, nullptr, nullptr), "MatZeroRowsColumns");
    fixedNodes_ = fixedNodes;
  }

  const FiniteElementJob& job_;
  int rank_, size_;
  PetscInt n_ = 0, first_ = 0, owned_ = 0;
  Numbering numbering_;
  FiniteElementResult result_;
  Mat A_ = nullptr, assembled_ = nullptr;
  Mat constrained_ = nullptr;            ///< assembled_ + H^T W H of the active soft constraints
  Vec softRightHandSide_ = nullptr;      ///< H^T W target of the active soft constraints
  bool softActive_ = false;
  Vec x_ = nullptr, b_ = nullptr;
  KSP ksp_ = nullptr;
  std::vector<std::pair<PetscInt, std::size_t>> fixedRows_; ///< owned fixed dof, index into the values
  std::vector<std::int32_t> fixedNodes_;
};

/// The misfit of each soft constraint under a solution, in mm along the directions it constrains:
/// sqrt(r^T W r / lambda_max(W)), r = u(p) - target (|r| for an isotropic W).
std::vector<double> softConstraintMisfits(const FiniteElementJob& mesh, const std::vector<SoftConstraint>& constraints,
                                          const std::vector<double>& displacements)
{
  std::vector<double> misfits(constraints.size(), 0.0);
  for (std::size_t i = 0; i < constraints.size(); ++i) {
    const SoftConstraint& c = constraints[i];
    const std::array<double, 3> r = softConstraintResidual(mesh, c, displacements);
    const double W[3][3] = {{c.stiffness[0], c.stiffness[1], c.stiffness[2]},
                            {c.stiffness[1], c.stiffness[3], c.stiffness[4]},
                            {c.stiffness[2], c.stiffness[4], c.stiffness[5]}};
    double v[3] = {1, 1, 1}, largest = 0; // the largest eigenvalue by power iteration (W is 3x3, PSD)
    for (int iteration = 0; iteration < 30; ++iteration) {
      double w[3];
      for (int a = 0; a < 3; ++a) w[a] = W[a][0] * v[0] + W[a][1] * v[1] + W[a][2] * v[2];
      largest = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
      if (!(largest > 0)) break;
      for (int a = 0; a < 3; ++a) v[a] = w[a] / largest;
    }
    double rWr = 0;
    for (int a = 0; a < 3; ++a) rWr += r[a] * (W[a][0] * r[0] + W[a][1] * r[1] + W[a][2] * r[2]);
    misfits[i] = largest > 0 ? std::sqrt(std::max(0.0, rWr / largest)) : std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
  }
  return misfits;
}

/// One round of the robust approximation: the active constraints whose misfit exceeds both the
/// floor and the median plus `outlierFactor` robust standard deviations lose their activity, the
/// worst first, at most `fractionPerRound` of the active ones. Returns how many went.
std::size_t rejectOutliers(const std::vector<double>& misfits, std::vector<char>& active, const SoftConstraintRejection& rejection)
{
  std::vector<double> values;
  for (std::size_t i = 0; i < misfits.size(); ++i) if (active[i]) values.push_back(misfits[i]);
  if (values.size() < 4) return 0;
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  const double middle = median(values);
  std::vector<double> deviations;
  for (double v : values) deviations.push_back(std::abs(v - middle));
  const double threshold = std::max(rejection.floorMm, middle + rejection.outlierFactor * 1.4826 * median(deviations));
  std::vector<std::size_t> outliers;
  for (std::size_t i = 0; i < misfits.size(); ++i) if (active[i] && misfits[i] > threshold) outliers.push_back(i);
  std::sort(outliers.begin(), outliers.end(), [&misfits](std::size_t a, std::size_t b) { return misfits[a] > misfits[b]; });
  const std::size_t limit = std::size_t(std::floor(rejection.fractionPerRound * double(values.size())));
  if (outliers.size() > limit) outliers.resize(limit);
  for (std::size_t i : outliers) active[i] = 0;
  return outliers.size();
}

/// Solves with the boundary conditions and soft constraints of `values` on the prepared mesh: the
/// first solve with every constraint, then rounds of rejection of the worst (Clatz et al. 2005),
/// until a round rejects none or the rounds are spent. Rank 0's result carries the outcome.
FiniteElementResult solveWithSoftConstraints(PreparedProblem& problem, const FiniteElementJob& mesh, const FiniteElementJob& values, int rank)
{
  const std::vector<SoftConstraint>& constraints = values.softConstraints;
  std::vector<char> active(constraints.size(), 1);
  std::vector<std::int64_t> keptPerRound;
  std::vector<double> rmsPerRound;
  double setupSeconds = 0, solveSeconds = 0;
  int iterations = 0;
  for (int round = 0;; ++round) {
    problem.constrain(constraints, active, values.fixedNodes);
    FiniteElementResult result = problem.solveFor(values.fixedDisplacements, round > 0);
    setupSeconds += result.setupSeconds;
    solveSeconds += result.solveSeconds;
    iterations += result.iterations;
    int finished = 1;
    std::vector<double> misfits;
    if (rank == 0 && !constraints.empty()) {
      misfits = softConstraintMisfits(mesh, constraints, result.displacements);
      double sum = 0;
      std::int64_t kept = 0;
      for (std::size_t i = 0; i < misfits.size(); ++i) {
        if (active[i]) { sum += misfits[i] * misfits[i]; ++kept; }
      }
      keptPerRound.push_back(kept);
      rmsPerRound.push_back(kept ? std::sqrt(sum / double(kept)) : 0.0);
      finished = round >= values.rejection.rounds || rejectOutliers(misfits, active, values.rejection) == 0;
    }
    MPI_Bcast(&finished, 1, MPI_INT, 0, PETSC_COMM_WORLD);
    if (finished) {
      if (rank == 0 && !constraints.empty()) {
        result.softConstraintKept.assign(active.begin(), active.end());
        result.softConstraintMisfitMm = misfits;
        result.keptPerRound = keptPerRound;
        result.rmsMisfitPerRoundMm = rmsPerRound;
      }
      result.setupSeconds = setupSeconds;
      result.solveSeconds = solveSeconds;
      result.iterations = iterations; // of every solve
      return result;
    }
    MPI_Bcast(active.data(), int(active.size()), MPI_CHAR, 0, PETSC_COMM_WORLD);
  }
}

/// Serves solves: "solve VALUES RESULT" (VALUES: a job-format file of the fixed nodes and their
/// displacements; other fixed nodes than the last solve's are eliminated anew first) and "quit",
/// one per line on standard input; answers "solved" or "failed".
void serve(const FiniteElementJob& job, int rank, int size)
{
  PreparedProblem problem(job, rank, size, true);
  if (rank == 0) {
    std::printf("ready\n");
    std::fflush(stdout);
  }
  for (;;) {
    char line[4096] = {0};
    if (rank == 0 && !std::fgets(line, sizeof(line), stdin)) std::strcpy(line, "quit");
    // Between scans the other ranks wait here for minutes. A blocking broadcast would have them
    // poll at full speed (Open MPI's shared-memory transport spins), taking a core from the
    // pipeline's other stages; a test every millisecond costs nothing and answers within one.
    MPI_Request request;
    MPI_Ibcast(line, sizeof(line), MPI_CHAR, 0, PETSC_COMM_WORLD, &request);
    for (int done = 0;;) {
      MPI_Test(&request, &done, MPI_STATUS_IGNORE);
      if (done) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    char command[16] = {0}, valuesFile[2048] = {0}, resultFile[2048] = {0};
    std::sscanf(line, "%15s %2047s %2047s", command, valuesFile, resultFile);
    if (std::strcmp(command, "quit") == 0) return;
    if (std::strcmp(command, "solve") != 0) continue;
    try {
      const FiniteElementJob values = readFiniteElementJob(valuesFile);
      if (values.fixedDisplacements.size() != 3 * values.fixedNodes.size() || values.fixedNodes.empty()) {
        throw WorkerFailure(2, std::string(valuesFile) + ": not 3 displacements per fixed node");
      }
      for (std::int32_t node : values.fixedNodes) {
        if (node < 0 || std::size_t(node) >= job.nodeCount()) {
          throw WorkerFailure(2, std::string(valuesFile) + ": fixed node " + std::to_string(node) + " is not a node of the mesh");
        }
      }
      try {
        values.validateSoftConstraints(job.tetrahedronCount());
      } catch (const std::invalid_argument& e) {
        throw WorkerFailure(2, std::string(valuesFile) + ": " + e.what());
      }
      const FiniteElementResult result = solveWithSoftConstraints(problem, job, values, rank);
      if (rank == 0) {
        writeFiniteElementResult(result, resultFile);
        std::printf("solved\n");
        std::fflush(stdout);
      }
    } catch (const std::exception& e) {
      if (rank == 0) {
        std::printf("failed %s\n", e.what());
        std::fflush(stdout);
      }
    }
  }
}

} // namespace

int main(int argc, char** argv)
{
  if (PetscInitialize(&argc, &argv, nullptr, nullptr)) return 1;
  int rank = 0, size = 1;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  int status = 0;
  try {
    const bool served = argc == 3 && std::strcmp(argv[1], "--serve") == 0;
    if (argc != 3) throw WorkerFailure(2, "usage: brainshift-fe-worker JOB RESULT | brainshift-fe-worker --serve JOB");
    const char* jobFile = served ? argv[2] : argv[1];
    FiniteElementJob job;
    try {
      job = readFiniteElementJob(jobFile);
      job.validate();
    } catch (const std::exception& e) {
      throw WorkerFailure(2, std::string(jobFile) + ": " + e.what());
    }
    if (PetscOptionsInsertString(nullptr, job.solverOptions.c_str())) {
      throw WorkerFailure(2, "the solver options cannot be parsed: " + job.solverOptions);
    }
    if (served) {
      serve(job, rank, size);
    } else {
      PreparedProblem problem(job, rank, size, false);
      const FiniteElementResult result = solveWithSoftConstraints(problem, job, job, rank);
      problem.requireEveryOptionRead(false);
      if (rank == 0) writeFiniteElementResult(result, argv[2]);
    }
  } catch (const WorkerFailure& e) {
    if (rank == 0) std::fprintf(stderr, "brainshift-fe-worker: %s\n", e.what());
    status = e.status;
  } catch (const std::exception& e) {
    if (rank == 0) std::fprintf(stderr, "brainshift-fe-worker: %s\n", e.what());
    status = 1;
  }
  PetscFinalize();
  return status;
}
