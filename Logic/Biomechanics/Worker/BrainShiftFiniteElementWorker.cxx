// brainshift-fe-worker JOB RESULT: solves a linear elastic problem on linear tetrahedra with
// imposed displacements (FiniteElementJob.h) in parallel with PETSc, as an MPI program.
//
// Every rank reads the job. The node graph is partitioned (PETSc's MatPartitioning, PT-Scotch when
// there are several ranks; nodes weighted by the tetrahedra around them, which is the assembly
// work), nodes are renumbered so that each rank owns a contiguous block, each tetrahedron is
// assembled by the owner of its first node, the fixed dofs are eliminated keeping the matrix
// symmetric (MatZeroRowsColumns), and the system is solved with CG and algebraic multigrid (GAMG
// with the rigid body modes as near-nullspace) unless the job's options say otherwise. The
// convergence reason is checked. Progress goes to stdout as "progress <stage> <fraction>" lines.
// Exit status: 0 solved, 2 bad job, 3 the solver did not converge, 1 anything else.
#include "FiniteElementJob.h"

#include <petscksp.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <numeric>
#include <set>
#include <stdexcept>
#include <string>
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

Numbering partitionNodes(const FiniteElementJob& job, int rank, int size)
{
  const PetscInt n = PetscInt(job.nodeCount());
  Numbering numbering;
  numbering.newOfOld.resize(std::size_t(n));
  if (size == 1) {
    std::iota(numbering.newOfOld.begin(), numbering.newOfOld.end(), 0);
    numbering.ownedCount = n;
    numbering.rangeStarts = {0, n};
    numbering.partitioner = "none (one rank)";
    return numbering;
  }
  // The node graph, rows split in contiguous blocks, for the partitioner.
  const PetscInt first = n * rank / size, last = n * (rank + 1) / size;
  std::vector<std::set<PetscInt>> neighbours(static_cast<std::size_t>(last - first));
  std::vector<PetscInt> work(static_cast<std::size_t>(last - first), 0);
  for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
    for (int a = 0; a < 4; ++a) {
      const PetscInt v = job.tetrahedra[4 * t + a];
      if (v < first || v >= last) continue;
      work[std::size_t(v - first)] += 1;
      for (int b = 0; b < 4; ++b) {
        if (a != b) neighbours[std::size_t(v - first)].insert(job.tetrahedra[4 * t + b]);
      }
    }
  }
  PetscInt *rowStarts, *columns, *weights;
  PetscInt total = 0;
  for (const auto& s : neighbours) total += PetscInt(s.size());
  check(PetscMalloc1(last - first + 1, &rowStarts), "PetscMalloc1");
  check(PetscMalloc1(std::max<PetscInt>(total, 1), &columns), "PetscMalloc1");
  check(PetscMalloc1(std::max<PetscInt>(last - first, 1), &weights), "PetscMalloc1");
  rowStarts[0] = 0;
  for (PetscInt i = 0; i < last - first; ++i) {
    rowStarts[i + 1] = rowStarts[i] + PetscInt(neighbours[std::size_t(i)].size());
    std::copy(neighbours[std::size_t(i)].begin(), neighbours[std::size_t(i)].end(), columns + rowStarts[i]);
    weights[i] = std::max<PetscInt>(1, work[std::size_t(i)]);
  }
  Mat adjacency;
  check(MatCreateMPIAdj(PETSC_COMM_WORLD, last - first, n, rowStarts, columns, nullptr, &adjacency), "MatCreateMPIAdj");
  MatPartitioning partitioning;
  check(MatPartitioningCreate(PETSC_COMM_WORLD, &partitioning), "MatPartitioningCreate");
  check(MatPartitioningSetAdjacency(partitioning, adjacency), "MatPartitioningSetAdjacency");
  check(MatPartitioningSetVertexWeights(partitioning, weights), "MatPartitioningSetVertexWeights");
#if defined(PETSC_HAVE_PTSCOTCH)
  check(MatPartitioningSetType(partitioning, MATPARTITIONINGPTSCOTCH), "MatPartitioningSetType");
#else
  check(MatPartitioningSetType(partitioning, MATPARTITIONINGAVERAGE), "MatPartitioningSetType");
#endif
  check(MatPartitioningSetFromOptions(partitioning), "MatPartitioningSetFromOptions");
  MatPartitioningType type;
  check(MatPartitioningGetType(partitioning, &type), "MatPartitioningGetType");
  numbering.partitioner = type;
  IS ownerOfNode, newNumber;
  check(MatPartitioningApply(partitioning, &ownerOfNode), "MatPartitioningApply");
  check(ISPartitioningToNumbering(ownerOfNode, &newNumber), "ISPartitioningToNumbering");
  std::vector<PetscInt> counts(static_cast<std::size_t>(size));
  check(ISPartitioningCount(ownerOfNode, size, counts.data()), "ISPartitioningCount");
  IS all;
  check(ISAllGather(newNumber, &all), "ISAllGather");
  const PetscInt* values;
  check(ISGetIndices(all, &values), "ISGetIndices");
  std::copy(values, values + n, numbering.newOfOld.begin());
  check(ISRestoreIndices(all, &values), "ISRestoreIndices");
  numbering.rangeStarts.assign(std::size_t(size) + 1, 0);
  for (int r = 0; r < size; ++r) numbering.rangeStarts[std::size_t(r) + 1] = numbering.rangeStarts[std::size_t(r)] + counts[std::size_t(r)];
  numbering.firstOwned = numbering.rangeStarts[std::size_t(rank)];
  numbering.ownedCount = counts[std::size_t(rank)];
  ISDestroy(&all);
  ISDestroy(&newNumber);
  ISDestroy(&ownerOfNode);
  MatPartitioningDestroy(&partitioning); // frees the weights
  MatDestroy(&adjacency);                 // frees rowStarts and columns
  return numbering;
}

FiniteElementResult solve(const FiniteElementJob& job, int rank, int size)
{
  FiniteElementResult result;
  result.ranks = size;
  const PetscInt n = PetscInt(job.nodeCount());
  result.equations = 3 * std::int64_t(n);
  double clock = MPI_Wtime();

  // -- Partition and renumber.
  progress(rank, "partition", 0.0);
  const Numbering numbering = partitionNodes(job, rank, size);
  result.partitioner = numbering.partitioner;
  const PetscInt first = numbering.firstOwned, owned = numbering.ownedCount;
  auto mine = [&](PetscInt newNode) { return newNode >= first && newNode < first + owned; };

  // -- Preallocation (block rows of 3) and the tetrahedra this rank assembles.
  std::vector<std::vector<PetscInt>> blockNeighbours(static_cast<std::size_t>(owned));
  std::vector<std::size_t> myTetrahedra;
  for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
    PetscInt v[4];
    for (int k = 0; k < 4; ++k) v[k] = numbering.newOfOld[std::size_t(job.tetrahedra[4 * t + k])];
    if (mine(v[0])) myTetrahedra.push_back(t);
    for (int a = 0; a < 4; ++a) {
      if (!mine(v[a])) continue;
      for (int b = 0; b < 4; ++b) blockNeighbours[std::size_t(v[a] - first)].push_back(v[b]);
    }
  }
  std::vector<PetscInt> diagonalBlocks(static_cast<std::size_t>(owned)), offDiagonalBlocks(static_cast<std::size_t>(owned));
  for (PetscInt i = 0; i < owned; ++i) {
    auto& list = blockNeighbours[std::size_t(i)];
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    for (PetscInt c : list) (mine(c) ? diagonalBlocks : offDiagonalBlocks)[std::size_t(i)] += 1;
    if (list.empty()) diagonalBlocks[std::size_t(i)] = 1; // a node in no tetrahedron (kept solvable)
    std::vector<PetscInt>().swap(list);
  }
  Mat A;
  check(MatCreate(PETSC_COMM_WORLD, &A), "MatCreate");
  check(MatSetSizes(A, 3 * owned, 3 * owned, 3 * n, 3 * n), "MatSetSizes");
  check(MatSetBlockSize(A, 3), "MatSetBlockSize");
  check(MatSetType(A, MATAIJ), "MatSetType");
  check(MatSetOptionsPrefix(A, "elasticity_"), "MatSetOptionsPrefix");
  check(MatSetFromOptions(A), "MatSetFromOptions");
  check(MatXAIJSetPreallocation(A, 3, diagonalBlocks.data(), offDiagonalBlocks.data(), nullptr, nullptr), "MatXAIJSetPreallocation");
  check(MatSetOption(A, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE), "MatSetOption");

  // -- Assembly.
  progress(rank, "assembly", 0.0);
  for (std::size_t e = 0; e < myTetrahedra.size(); ++e) {
    const std::size_t t = myTetrahedra[e];
    double p[4][3];
    PetscInt blocks[4];
    for (int k = 0; k < 4; ++k) {
      const std::size_t old = std::size_t(job.tetrahedra[4 * t + k]);
      for (int d = 0; d < 3; ++d) p[k][d] = job.nodes[3 * old + d];
      blocks[k] = numbering.newOfOld[old];
    }
    double K[144];
    tetrahedronStiffness(p, job.materials[std::size_t(job.materialOfTetrahedron[t])], K);
    check(MatSetValuesBlocked(A, 4, blocks, 4, blocks, K, ADD_VALUES), "MatSetValuesBlocked");
  }
  // Nodes in no tetrahedron: an identity block keeps the matrix regular.
  for (PetscInt i = 0; i < owned; ++i) {
    if (offDiagonalBlocks[std::size_t(i)] == 0 && diagonalBlocks[std::size_t(i)] == 1) {
      const PetscInt row = first + i;
      const double identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
      check(MatSetValuesBlocked(A, 1, &row, 1, &row, identity, ADD_VALUES), "MatSetValuesBlocked");
    }
  }
  check(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY), "MatAssemblyBegin");
  check(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY), "MatAssemblyEnd");
  {
    std::int64_t mineCount = std::int64_t(myTetrahedra.size());
    result.tetrahedraPerRank.resize(std::size_t(size));
    MPI_Allgather(&mineCount, 1, MPI_INT64_T, result.tetrahedraPerRank.data(), 1, MPI_INT64_T, PETSC_COMM_WORLD);
  }

  // -- Boundary conditions: eliminate the fixed dofs, keeping A symmetric.
  Vec x, b;
  check(MatCreateVecs(A, &x, &b), "MatCreateVecs");
  check(VecSet(b, 0.0), "VecSet");
  check(VecSet(x, 0.0), "VecSet");
  std::vector<PetscInt> fixedRows;
  for (std::size_t f = 0; f < job.fixedNodes.size(); ++f) {
    const PetscInt node = numbering.newOfOld[std::size_t(job.fixedNodes[f])];
    if (!mine(node)) continue;
    for (int d = 0; d < 3; ++d) {
      const PetscInt row = 3 * node + d;
      fixedRows.push_back(row);
      check(VecSetValue(x, row, job.fixedDisplacements[3 * f + std::size_t(d)], INSERT_VALUES), "VecSetValue");
    }
  }
  check(VecAssemblyBegin(x), "VecAssemblyBegin");
  check(VecAssemblyEnd(x), "VecAssemblyEnd");
  check(MatZeroRowsColumns(A, PetscInt(fixedRows.size()), fixedRows.data(), 1.0, x, b), "MatZeroRowsColumns");

  // Rigid body modes for the multigrid (coordinates in the new numbering).
  Vec coordinates;
  check(VecCreateMPI(PETSC_COMM_WORLD, 3 * owned, 3 * n, &coordinates), "VecCreateMPI");
  check(VecSetBlockSize(coordinates, 3), "VecSetBlockSize");
  {
    PetscScalar* c;
    check(VecGetArray(coordinates, &c), "VecGetArray");
    for (PetscInt old = 0; old < n; ++old) {
      const PetscInt node = numbering.newOfOld[std::size_t(old)];
      if (!mine(node)) continue;
      for (int d = 0; d < 3; ++d) c[3 * (node - first) + d] = job.nodes[3 * std::size_t(old) + std::size_t(d)];
    }
    check(VecRestoreArray(coordinates, &c), "VecRestoreArray");
  }
  MatNullSpace rigidBodyModes;
  check(MatNullSpaceCreateRigidBody(coordinates, &rigidBodyModes), "MatNullSpaceCreateRigidBody");
  check(MatSetNearNullSpace(A, rigidBodyModes), "MatSetNearNullSpace");
  result.assemblySeconds = maxOverRanks(MPI_Wtime() - clock);

  // -- Solver: the tuned default, then the job's options over it.
  clock = MPI_Wtime();
  progress(rank, "setup", 0.0);
  KSP ksp;
  check(KSPCreate(PETSC_COMM_WORLD, &ksp), "KSPCreate");
  check(KSPSetOperators(ksp, A, A), "KSPSetOperators");
  check(KSPSetType(ksp, KSPCG), "KSPSetType");
  check(KSPSetTolerances(ksp, 1e-8, PETSC_DEFAULT, PETSC_DEFAULT, 5000), "KSPSetTolerances");
  PC pc;
  check(KSPGetPC(ksp, &pc), "KSPGetPC");
  check(PCSetType(pc, PCGAMG), "PCSetType");
  check(KSPSetFromOptions(ksp), "KSPSetFromOptions");
  {
    // x holds the imposed values: a good start for an iterative solver (a direct one takes none).
    KSPType type;
    check(KSPGetType(ksp, &type), "KSPGetType");
    check(KSPSetInitialGuessNonzero(ksp, std::string(type) == KSPPREONLY ? PETSC_FALSE : PETSC_TRUE), "KSPSetInitialGuessNonzero");
  }
  check(KSPSetUp(ksp), "KSPSetUp");
  check(PCSetUp(pc), "PCSetUp");
  result.setupSeconds = maxOverRanks(MPI_Wtime() - clock);
  {
    KSPType kspType;
    PCType pcType;
    KSPGetType(ksp, &kspType);
    PCGetType(pc, &pcType);
    result.solver = std::string(kspType) + "+" + pcType;
  }

  clock = MPI_Wtime();
  progress(rank, "solve", 0.0);
  check(KSPSolve(ksp, b, x), "KSPSolve");
  result.solveSeconds = maxOverRanks(MPI_Wtime() - clock);
  KSPConvergedReason reason;
  check(KSPGetConvergedReason(ksp, &reason), "KSPGetConvergedReason");
  result.convergedReason = int(reason);
  PetscInt iterations;
  check(KSPGetIterationNumber(ksp, &iterations), "KSPGetIterationNumber");
  result.iterations = int(iterations);
  {
    // The true relative residual, whatever norm the solver watched.
    Vec r;
    check(VecDuplicate(b, &r), "VecDuplicate");
    check(MatMult(A, x, r), "MatMult");
    check(VecAYPX(r, -1.0, b), "VecAYPX");
    PetscReal residual, rhs;
    check(VecNorm(r, NORM_2, &residual), "VecNorm");
    check(VecNorm(b, NORM_2, &rhs), "VecNorm");
    result.relativeResidual = rhs > 0 ? double(residual / rhs) : double(residual);
    VecDestroy(&r);
  }
  if (reason <= 0) {
    throw WorkerFailure(3, "the solver (" + result.solver + ") did not converge: KSP reason " + std::to_string(int(reason)) +
                             " after " + std::to_string(result.iterations) + " iterations, relative residual " +
                             std::to_string(result.relativeResidual));
  }

  // The imposed values exactly (the solver met them only to its tolerance).
  for (std::size_t f = 0; f < job.fixedNodes.size(); ++f) {
    const PetscInt node = numbering.newOfOld[std::size_t(job.fixedNodes[f])];
    if (!mine(node)) continue;
    for (int d = 0; d < 3; ++d) check(VecSetValue(x, 3 * node + d, job.fixedDisplacements[3 * f + std::size_t(d)], INSERT_VALUES), "VecSetValue");
  }
  check(VecAssemblyBegin(x), "VecAssemblyBegin");
  check(VecAssemblyEnd(x), "VecAssemblyEnd");

  // -- The displacements, back in the job's node order, on rank 0.
  VecScatter toZero;
  Vec gathered;
  check(VecScatterCreateToZero(x, &toZero, &gathered), "VecScatterCreateToZero");
  check(VecScatterBegin(toZero, x, gathered, INSERT_VALUES, SCATTER_FORWARD), "VecScatterBegin");
  check(VecScatterEnd(toZero, x, gathered, INSERT_VALUES, SCATTER_FORWARD), "VecScatterEnd");
  if (rank == 0) {
    const PetscScalar* g;
    check(VecGetArrayRead(gathered, &g), "VecGetArrayRead");
    result.displacements.resize(std::size_t(3 * n));
    for (PetscInt old = 0; old < n; ++old) {
      const PetscInt node = numbering.newOfOld[std::size_t(old)];
      for (int d = 0; d < 3; ++d) result.displacements[std::size_t(3 * old + d)] = double(g[3 * node + d]);
    }
    check(VecRestoreArrayRead(gathered, &g), "VecRestoreArrayRead");
  }
  VecScatterDestroy(&toZero);
  VecDestroy(&gathered);
  MatNullSpaceDestroy(&rigidBodyModes);
  VecDestroy(&coordinates);
  KSPDestroy(&ksp);
  VecDestroy(&x);
  VecDestroy(&b);
  MatDestroy(&A);
  progress(rank, "done", 1.0);
  return result;
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
    if (argc != 3) throw WorkerFailure(2, "usage: brainshift-fe-worker JOB RESULT");
    FiniteElementJob job;
    try {
      job = readFiniteElementJob(argv[1]);
      job.validate();
    } catch (const std::exception& e) {
      throw WorkerFailure(2, std::string(argv[1]) + ": " + e.what());
    }
    if (PetscOptionsInsertString(nullptr, job.solverOptions.c_str())) {
      throw WorkerFailure(2, "the solver options cannot be parsed: " + job.solverOptions);
    }
    const FiniteElementResult result = solve(job, rank, size);
    if (rank == 0) writeFiniteElementResult(result, argv[2]);
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
