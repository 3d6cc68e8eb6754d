#pragma once
// The exchange between the biomechanics logic and its MPI/PETSc worker: a linear elastic problem on
// linear tetrahedra with displacement (Dirichlet) boundary conditions, and its solution. Plain
// C++ with no library behind it, so that the worker links PETSc alone.
//
// Units inside a job: length mm, displacement mm, Young's modulus N/mm^2 (the configuration's Pa
// are converted once, by the logic: 1 Pa = 1e-6 N/mm^2).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace brainshift {

struct ElasticMaterial {
  double youngsModulus = 3e-3; ///< N/mm^2
  double poissonRatio = 0.45;
};

struct FiniteElementJob {
  std::vector<double> nodes;                  ///< x, y, z per node (LPS mm)
  std::vector<std::int32_t> tetrahedra;       ///< 4 node indices per tetrahedron
  std::vector<std::int32_t> materialOfTetrahedron;
  std::vector<ElasticMaterial> materials;
  std::vector<std::int32_t> fixedNodes;       ///< nodes whose displacement is imposed
  std::vector<double> fixedDisplacements;     ///< 3 per fixed node
  std::string solverOptions;                  ///< PETSc options over the worker's defaults

  std::size_t nodeCount() const { return nodes.size() / 3; }
  std::size_t tetrahedronCount() const { return tetrahedra.size() / 4; }
  /// std::invalid_argument naming the first problem: sizes, indices out of range, non-finite
  /// values, moduli <= 0, Poisson ratios outside [0, 0.5), no boundary condition, a fixed node
  /// given twice, inverted or degenerate tetrahedra.
  void validate() const;
};

struct FiniteElementResult {
  std::vector<double> displacements; ///< x, y, z per node (mm)
  std::int64_t equations = 0;        ///< unknowns of the solve (3 per node)
  int ranks = 0;
  int iterations = 0;
  double relativeResidual = 0;       ///< ||b - A x|| / ||b|| after elimination of the fixed dofs
  int convergedReason = 0;           ///< PETSc's KSPConvergedReason (> 0: converged)
  double assemblySeconds = 0, setupSeconds = 0, solveSeconds = 0;
  std::string solver;                ///< "cg+gamg", ...
  std::string partitioner;
  std::vector<std::int64_t> tetrahedraPerRank; ///< the work balance
};

/// Binary, little-endian, with a magic and a version; atomic write.
void writeFiniteElementJob(const FiniteElementJob& job, const std::filesystem::path& path);
FiniteElementJob readFiniteElementJob(const std::filesystem::path& path);
void writeFiniteElementResult(const FiniteElementResult& result, const std::filesystem::path& path);
FiniteElementResult readFiniteElementResult(const std::filesystem::path& path);

/// The 12x12 stiffness of a linear tetrahedron (row-major; dofs x0 y0 z0 x1 ...), and its volume
/// (positive for the orientation (p1 - p0) . ((p2 - p0) x (p3 - p0)) > 0).
double tetrahedronStiffness(const double p[4][3], const ElasticMaterial& material, double stiffness[144]);

} // namespace brainshift
