#pragma once
// The exchange between the biomechanics logic and its MPI/PETSc worker: a linear elastic problem on
// linear tetrahedra with displacement (Dirichlet) boundary conditions, and its solution. Plain
// C++ with no library behind it, so that the worker links PETSc alone.
//
// Units inside a job: length mm, displacement mm, Young's modulus N/mm^2 (the configuration's Pa
// are converted once, by the logic: 1 Pa = 1e-6 N/mm^2).
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace brainshift {

struct ElasticMaterial {
  double youngsModulus = 3e-3; ///< N/mm^2
  double poissonRatio = 0.45;
};

/// A soft constraint (a match of the image inside the brain): the displacement at a point inside a
/// tetrahedron, u(p) = sum_k weights[k] u(node k of the tetrahedron), should be `target`; the misfit costs
/// 1/2 (u(p) - target)^T W (u(p) - target), W symmetric positive semi-definite (N/mm; stored
/// xx, xy, xz, yy, yz, zz). Added to the elastic energy, H^T W H joins the stiffness (which stays
/// symmetric positive definite: the nodes of one tetrahedron are coupled already) and H^T W target
/// the right-hand side.
struct SoftConstraint {
  std::int32_t tetrahedron = 0;
  std::array<double, 4> weights{}; ///< barycentric, in the tetrahedron's node order
  std::array<double, 3> target{};
  std::array<double, 6> stiffness{};
};

/// The robust approximation of Clatz et al. (2005): after each solve the constraints that the
/// solution misses the most are dropped and the problem solved again, `rounds` times. In a round a
/// constraint is an outlier when its misfit (in mm, measured along the directions it constrains)
/// exceeds both `floorMm` and the active constraints' median plus `outlierFactor` robust standard
/// deviations (1.4826 MAD); at most `fractionPerRound` of the active ones, the worst first, go.
struct SoftConstraintRejection {
  int rounds = 0;
  double fractionPerRound = 0.1;
  double outlierFactor = 2.5;
  double floorMm = 1.0;
};

struct FiniteElementJob {
  std::vector<double> nodes;                  ///< x, y, z per node (LPS mm)
  std::vector<std::int32_t> tetrahedra;       ///< 4 node indices per tetrahedron
  std::vector<std::int32_t> materialOfTetrahedron;
  std::vector<ElasticMaterial> materials;
  std::vector<std::int32_t> fixedNodes;       ///< nodes whose displacement is imposed
  std::vector<double> fixedDisplacements;     ///< 3 per fixed node
  std::string solverOptions;                  ///< PETSc options over the worker's defaults
  std::vector<SoftConstraint> softConstraints; ///< none: the boundary conditions alone
  SoftConstraintRejection rejection;

  std::size_t nodeCount() const { return nodes.size() / 3; }
  std::size_t tetrahedronCount() const { return tetrahedra.size() / 4; }
  /// std::invalid_argument naming the first problem: sizes, indices out of range, non-finite
  /// values, moduli <= 0, Poisson ratios outside [0, 0.5), no boundary condition, a fixed node
  /// given twice, inverted or degenerate tetrahedra, soft constraints in no tetrahedron, whose weights do not sum to 1 or whose stiffness is not finite and positive
  /// semi-definite on its diagonal.
  void validate() const;
  /// The soft constraints and the rejection alone, for a mesh of `tetrahedra` tetrahedra (a served
  /// solve's values carry no mesh).
  void validateSoftConstraints(std::size_t tetrahedra) const;
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
  /// With soft constraints: per constraint whether the final solve kept it (1) or rejected it (0),
  /// and its misfit |u(p) - target| in mm under the final solution (rejected ones included);
  /// per solve (round) the constraints it kept and their root mean square misfit after it.
  std::vector<std::uint8_t> softConstraintKept;
  std::vector<double> softConstraintMisfitMm;
  std::vector<std::int64_t> keptPerRound;
  std::vector<double> rmsMisfitPerRoundMm;
};

/// u(p) - target of a soft constraint under nodal displacements (3 per node of `mesh`), mm.
std::array<double, 3> softConstraintResidual(const FiniteElementJob& mesh, const SoftConstraint& constraint,
                                             const std::vector<double>& displacements);

/// Binary, little-endian, with a magic and a version; atomic write.
void writeFiniteElementJob(const FiniteElementJob& job, const std::filesystem::path& path);
FiniteElementJob readFiniteElementJob(const std::filesystem::path& path);
void writeFiniteElementResult(const FiniteElementResult& result, const std::filesystem::path& path);
FiniteElementResult readFiniteElementResult(const std::filesystem::path& path);

/// The 12x12 stiffness of a linear tetrahedron (row-major; dofs x0 y0 z0 x1 ...), and its volume
/// (positive for the orientation (p1 - p0) . ((p2 - p0) x (p3 - p0)) > 0).
double tetrahedronStiffness(const double p[4][3], const ElasticMaterial& material, double stiffness[144]);

} // namespace brainshift
