// brainshift bench simulate: the finite element solve of the simulate stage on brain meshes of the
// built-in case, at the sizes of the issue (about 20,000, 77,511, 253,308 and 1,000,000 equations),
// for the candidate solvers on 1 and 2 ranks, as a prepared session: what can be done before
// surgery (assembly, elimination, preconditioner setup or factorisation) and the during-surgery
// solve for a new set of surface values, timed apart. Each solution is compared with a reference
// solution of the same problem (the direct factorisation where it fits in memory, else CG + GAMG
// at a relative tolerance of 1e-12), so speed is charted against accuracy; a tolerance sweep at one
// size gives the iterative solvers' error against their time. Charts: Testing/Benchmarks/simulate/.
#include "ActiveSurfaceLogic.h"
#include "AtomicFile.h"
#include "BiomechanicalModel.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "Configuration.h"
#include "FiniteElementSolver.h"
#include "LabelMapMesher.h"
#include "RunReport.h"

#include <vtkDataArray.h>
#include <vtkPointData.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

namespace brainshift::cli {
namespace fs = std::filesystem;

namespace {

struct SimulateBenchOptions {
  fs::path outputDir;
  std::vector<double> equations{20000, 77511, 253308, 1000000};
  std::vector<int> ranks{1, 2};
  std::vector<std::string> solvers{"cg+gamg", "cg+hypre", "cg+icc", "cg+bjacobi", "gmres+bjacobi", "cholesky+cholmod", "cholesky+mumps"};
  double rtol = 1e-5;                 ///< of the iterative solvers in the size sweep (the stage's default)
  std::vector<double> sweepTolerances{1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-10};
  double sweepEquations = 77511;      ///< the size of the tolerance sweep (0: none)
  double directLimit = 300000;        ///< no direct factorisation above this many equations (memory)
  std::uint64_t seed = 2000;
};

bool isDirect(const std::string& solver) { return solver.rfind("cholesky+", 0) == 0; }

/// PETSc options of a candidate solver. The tolerance applies to the iterative ones.
std::string solverOptionsFor(const std::string& solver, double rtol)
{
  char tolerance[64];
  std::snprintf(tolerance, sizeof tolerance, " -ksp_rtol %.3g", rtol);
  if (solver == "cg+gamg") return std::string("-ksp_type cg -pc_type gamg") + tolerance;
  if (solver == "cg+hypre") return std::string("-ksp_type cg -pc_type hypre -pc_hypre_type boomeramg") + tolerance;
  // Block Jacobi, one block per rank: with ILU(0) in each block (not always positive: CG can break
  // down on it), or with incomplete Cholesky, shifted to stay positive definite. ILU named: on the
  // matrix the worker declares SPD, PETSc's default in the blocks is incomplete Cholesky.
  if (solver == "cg+bjacobi") return std::string("-ksp_type cg -pc_type bjacobi -sub_pc_type ilu -ksp_max_it 20000") + tolerance;
  if (solver == "cg+icc") return std::string("-ksp_type cg -pc_type bjacobi -sub_pc_type icc -ksp_max_it 20000") + tolerance;
  if (solver == "gmres+bjacobi") return std::string("-ksp_type gmres -pc_type bjacobi -sub_pc_type ilu -ksp_max_it 20000") + tolerance;
  if (solver == "cholesky+cholmod") return "-ksp_type preonly -pc_type cholesky -pc_factor_mat_solver_type cholmod";
  if (solver == "cholesky+mumps") return "-ksp_type preonly -pc_type cholesky -pc_factor_mat_solver_type mumps";
  throw InputError("--solvers: unknown solver '" + solver +
                   "' (cg+gamg, cg+hypre, cg+icc, cg+bjacobi, gmres+bjacobi, cholesky+cholmod, cholesky+mumps)");
}

/// CHOLMOD is sequential: one rank only.
bool runsOn(const std::string& solver, int ranks) { return solver != "cholesky+cholmod" || ranks == 1; }

/// The simulate stage's problem on the built-in case at one size: the preoperative brain (parenchyma,
/// ventricles, tumour) meshed by the lattice mesher, its surface moved onto the true intraoperative
/// brain by the active surface (free where the tumour was resected or nothing matches), the
/// configuration's materials. The resolution is found from the wanted equation count (equations
/// grow as h^-3) and corrected once by the count it gave.
struct BrainProblem {
  FiniteElementJob job;
  double resolutionMm = 0;
  std::size_t freeSurfaceNodes = 0;
};

BrainProblem brainProblem(const SimulatedCase& c, double wantedEquations)
{
  const Configuration configuration;
  MeshingParameters meshing;
  meshing.labels = configuration.meshLabels;
  meshing.resolutionMm = configuration.meshResolutionMm * std::cbrt(95610.0 / wantedEquations); // 4 mm: 95,610 equations
  LabelMapMesh mesh;
  for (int attempt = 0; attempt < 3; ++attempt) {
    mesh = meshLabelMap(*c.preopLabels, meshing);
    const double equations = 3.0 * double(mesh.quality.nodes);
    if (std::abs(equations / wantedEquations - 1) < 0.08) break;
    meshing.resolutionMm *= std::cbrt(equations / wantedEquations);
  }
  const ActiveSurfaceResult surface =
    deformBrainSurface(mesh.mesh, c.preopLabels, *c.intraopLabels, c.intraopImage, *c.rigidIntraopToPreop, ActiveSurfaceParameters{});
  BrainProblem problem;
  problem.job = finiteElementJobFromModel(mesh.mesh, surface.surface, configuration, "the brain mesh", "the brain surface");
  problem.resolutionMm = meshing.resolutionMm;
  problem.freeSurfaceNodes = surface.surfaceNodes - surface.imposedNodes;
  return problem;
}

/// Largest nodal distance (mm) between two solutions of the same mesh.
double largestDifferenceMm(const std::vector<double>& a, const std::vector<double>& b)
{
  if (a.size() != b.size() || a.empty()) return std::nan("");
  double largest = 0;
  for (std::size_t v = 0; v + 2 < a.size(); v += 3) {
    const double dx = a[v] - b[v], dy = a[v + 1] - b[v + 1], dz = a[v + 2] - b[v + 2];
    largest = std::max(largest, std::sqrt(dx * dx + dy * dy + dz * dz));
  }
  return largest;
}

struct Measurement {
  FiniteElementResult result; ///< of the during-surgery solve (the second set of values)
  double prepareWallSeconds = 0;
  bool converged = false;
  std::string failure;
};

/// A prepared session: the first scan's values, then the next scan's (the one timed).
Measurement measure(const FiniteElementJob& problem, const std::vector<double>& nextScan, const std::string& options, int ranks)
{
  FiniteElementJob job = problem;
  job.solverOptions = options;
  FiniteElementRunOptions run;
  run.worker = workerBesideExecutable();
  run.ranks = ranks;
  run.timeoutSeconds = 1800;
  Measurement m;
  try {
    FiniteElementSession session(job, run);
    m.prepareWallSeconds = session.prepareSeconds();
    session.solve(job.fixedDisplacements);
    m.result = session.solve(nextScan);
    m.converged = true;
  } catch (const MethodError& e) {
    m.failure = e.what();
  }
  return m;
}

void runSimulateBench(const SimulateBenchOptions& o)
{
  for (const auto& s : o.solvers) solverOptionsFor(s, o.rtol);
  CaseParameters parameters;
  parameters.seed = o.seed;
  std::printf("bench simulate: the built-in case (full)\n");
  std::fflush(stdout);
  const SimulatedCase c = simulateCase(parameters);

  std::ostringstream csv;
  csv << "sweep,target_equations,equations,tetrahedra,imposed_nodes,free_surface_nodes,mesh_resolution_mm,solver,ranks,rtol,"
         "assembly_seconds,setup_seconds,solve_seconds,prepare_wall_seconds,iterations,relative_residual,error_mm,reference,converged\n";
  std::vector<double> sizes = o.equations;
  if (o.sweepEquations > 0 && std::find(sizes.begin(), sizes.end(), o.sweepEquations) == sizes.end()) sizes.push_back(o.sweepEquations);
  for (double target : sizes) {
    const bool inSizeSweep = std::find(o.equations.begin(), o.equations.end(), target) != o.equations.end();
    const BrainProblem problem = brainProblem(c, target);
    const FiniteElementJob& job = problem.job;
    const double equations = 3.0 * double(job.nodeCount());
    std::printf("bench simulate: %.0f equations wanted, h = %.2f mm: %zu nodes (%.0f equations), %zu tetrahedra, %zu imposed, "
                "%zu surface nodes free\n",
                target, problem.resolutionMm, job.nodeCount(), equations, job.tetrahedronCount(), job.fixedNodes.size(),
                problem.freeSurfaceNodes);
    std::fflush(stdout);
    // The next scan: the surface sunk 20 % further (only the right-hand side changes).
    std::vector<double> nextScan = job.fixedDisplacements;
    for (double& d : nextScan) d *= 1.2;

    // The reference solution of the next scan's problem.
    const bool directFits = equations <= o.directLimit;
    const std::string referenceName = directFits ? "cholesky+cholmod" : "cg+gamg rtol 1e-12";
    const Measurement reference =
      measure(job, nextScan, directFits ? solverOptionsFor("cholesky+cholmod", 0) : solverOptionsFor("cg+gamg", 1e-12), 1);
    if (!reference.converged) throw MethodError("bench simulate: the reference solve failed: " + reference.failure);

    auto row = [&](const char* sweep, const std::string& solver, int ranks, double rtol) {
      const Measurement m = measure(job, nextScan, solverOptionsFor(solver, rtol), ranks);
      const FiniteElementResult& r = m.result;
      const double error = m.converged ? largestDifferenceMm(r.displacements, reference.result.displacements) : std::nan("");
      csv << sweep << ',' << std::llround(target) << ',' << std::llround(equations) << ',' << job.tetrahedronCount() << ','
          << job.fixedNodes.size() << ',' << problem.freeSurfaceNodes << ',' << problem.resolutionMm << ',' << solver << ',' << ranks
          << ',';
      if (!isDirect(solver)) csv << rtol;
      csv << ',' << r.assemblySeconds << ',' << r.setupSeconds << ',' << r.solveSeconds << ',' << m.prepareWallSeconds << ','
          << r.iterations << ',' << r.relativeResidual << ',' << error << ',' << referenceName << ',' << m.converged << '\n';
      if (m.converged) {
        std::printf("  %-5s %-16s %d rank(s) rtol %-6.0e: assembly %.2f s, setup %.2f s, solve %.3f s (%d iterations), error %.1e mm\n",
                    sweep, solver.c_str(), ranks, isDirect(solver) ? 0.0 : rtol, r.assemblySeconds, r.setupSeconds, r.solveSeconds,
                    r.iterations, error);
      } else {
        std::printf("  %-5s %-16s %d rank(s): %s\n", sweep, solver.c_str(), ranks, m.failure.c_str());
      }
      std::fflush(stdout);
      writeTextFileAtomically(o.outputDir / "simulate_bench.csv", csv.str()); // each row kept as it comes
    };

    if (inSizeSweep) {
      for (const std::string& solver : o.solvers) {
        if (isDirect(solver) && equations > o.directLimit) continue;
        for (int ranks : o.ranks) {
          if (runsOn(solver, ranks)) row("size", solver, ranks, o.rtol);
        }
      }
    }
    if (target == o.sweepEquations) {
      for (const std::string& solver : o.solvers) {
        if (isDirect(solver)) continue;
        for (double rtol : o.sweepTolerances) row("rtol", solver, 1, rtol);
      }
    }
  }
}

} // namespace

void addSimulateBenchCommand(CLI::App& bench)
{
  auto o = std::make_shared<SimulateBenchOptions>();
  CLI::App* command = bench.add_subcommand(
    "simulate", "Finite element solve on brain meshes: time against size and error against time for the candidate solvers, "
                "1 and 2 ranks, prepared before surgery and solved during it");
  command->add_option("--output-dir", o->outputDir, "where the measurements go")->required();
  command->add_option("--equations", o->equations, "problem sizes (equations)")->delimiter(',')->capture_default_str();
  command->add_option("--ranks", o->ranks, "rank counts")->delimiter(',')->capture_default_str();
  command->add_option("--solvers", o->solvers, "solvers")->delimiter(',')->capture_default_str();
  command->add_option("--rtol", o->rtol, "relative tolerance of the iterative solvers over the sizes")->capture_default_str();
  command->add_option("--sweep-tolerances", o->sweepTolerances, "tolerances of the sweep")->delimiter(',')->capture_default_str();
  command->add_option("--sweep-equations", o->sweepEquations, "problem size of the tolerance sweep (0: no sweep)")->capture_default_str();
  command->add_option("--direct-limit", o->directLimit, "no direct factorisation above this many equations")->capture_default_str();
  command->add_option("--seed", o->seed, "seed of the case")->capture_default_str();
  command->callback([o] {
    for (double e : o->equations) {
      if (!(e >= 1000 && e <= 5e6)) throw InputError("--equations: each must be within 1000 to 5000000");
    }
    if (!(o->sweepEquations == 0 || (o->sweepEquations >= 1000 && o->sweepEquations <= 5e6))) {
      throw InputError("--sweep-equations: must be 0 or within 1000 to 5000000");
    }
    for (int r : o->ranks) {
      if (r < 1 || r > 64) throw InputError("--ranks: each must be within 1 to 64");
    }
    for (double t : o->sweepTolerances) {
      if (!(t > 0 && t < 1)) throw InputError("--sweep-tolerances: each must be within (0, 1)");
    }
    if (!(o->rtol > 0 && o->rtol < 1)) throw InputError("--rtol: must be within (0, 1)");
    runSimulateBench(*o);
  });
}

} // namespace brainshift::cli
