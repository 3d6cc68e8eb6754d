// brainshift bench: measurements of speed and accuracy against the built-in case's truth.
// Charts and the comparison with other tools are made by the scripts in Testing/Benchmarks/.
#include "AtomicFile.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "LandmarkEvaluation.h"
#include "RigidRegistrationLogic.h"
#include "FiniteElementSolver.h"
#include "LabelOverlap.h"
#include "RunReport.h"
#include "TissueClassificationLogic.h"
#include "VolumeIO.h"

#include <itkEuler3DTransform.h>
#include <itkMatrixOffsetTransformBase.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstring>
#include <cstdio>
#include <memory>
#include <random>
#include <sstream>
#include <unordered_map>

namespace brainshift::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct RigidBenchOptions {
  fs::path outputDir;
  std::string size = "full";
  bool captureRange = false;
  std::vector<double> rotations{0, 10, 20, 30, 40, 45, 60, 75, 90};
  std::vector<double> translations{0, 10, 20, 30, 40, 50};
  unsigned trials = 3, runs = 3;
  std::uint64_t seed = 2000;
};

/// How far a rigid result is from the truth: TRE on the head landmarks (only the rigid motion
/// applies there), the rotation between them, and their distance at the intraop image centre.
struct RigidAccuracy {
  double headMeanMm = 0, headMaxMm = 0, rotationErrorDegrees = 0, translationErrorMm = 0;
  bool success(double maxTreMm = 1.0, double maxRotationDegrees = 0.5) const
  {
    return headMaxMm <= maxTreMm && rotationErrorDegrees <= maxRotationDegrees;
  }
};

RigidAccuracy accuracyOf(const SpatialTransform& estimate, const SimulatedCase& c)
{
  std::vector<LandmarkPair> head;
  for (const LandmarkPair& pair : c.landmarks) {
    if (pair.name.rfind("head-", 0) == 0) head.push_back(pair);
  }
  const RegistrationError error = evaluateTransform(estimate, head);
  RigidAccuracy accuracy;
  accuracy.headMeanMm = error.overall.meanMm;
  accuracy.headMaxMm = error.overall.maxMm;
  accuracy.rotationErrorDegrees = rotationDifferenceDegrees(estimate, *c.rigidIntraopToPreop);
  // At the truth's centre of rotation (as Testing/Benchmarks/rigid measures elastix).
  const auto* truth = dynamic_cast<const itk::MatrixOffsetTransformBase<double, 3, 3>*>(c.rigidIntraopToPreop.GetPointer());
  const PhysicalPoint centre = truth ? truth->GetCenter() : PhysicalPoint();
  accuracy.translationErrorMm = estimate.TransformPoint(centre).EuclideanDistanceTo(c.rigidIntraopToPreop->TransformPoint(centre));
  return accuracy;
}

CaseParameters caseOfSize(const std::string& size, std::uint64_t seed)
{
  if (size != "full" && size != "small") throw InputError("--size: '" + size + "' is neither full nor small");
  CaseParameters parameters;
  parameters.size = size == "full" ? CaseSize::Full : CaseSize::Small;
  parameters.seed = seed;
  return parameters;
}

void runRigidBench(const RigidBenchOptions& o)
{
  if (o.trials == 0 || o.runs == 0) throw InputError("--trials and --runs must be at least 1");
  for (double r : o.rotations) {
    if (!(r >= 0 && r <= 180)) throw InputError("--rotations: each must be within 0 to 180 degrees");
  }
  for (double t : o.translations) {
    if (!(t >= 0 && t <= 50)) throw InputError("--translations: each must be within 0 to 50 mm");
  }
  const CaseParameters defaults = caseOfSize(o.size, o.seed);
  RigidRegistrationParameters registration;

  // Accuracy and speed on the case with its default misalignment.
  std::printf("bench rigid: %s case, %u runs\n", o.size.c_str(), o.runs);
  const SimulatedCase simulated = simulateCase(defaults);
  writeCase(simulated, defaults, o.outputDir / "case");
  // Timed from the files, as a user (and elastix in the comparison) meets them.
  const CaseFiles files(o.outputDir / "case");
  std::vector<double> seconds;
  RigidRegistrationResult result;
  for (unsigned run = 0; run < o.runs; ++run) {
    Stopwatch clock;
    const ScalarImage::Pointer intraop = readScalarVolume(files.intraopImage);
    const ScalarImage::Pointer preop = readScalarVolume(files.preopImage);
    const LabelImage::Pointer labels = readLabelVolume(files.preopLabels);
    result = registerRigidly(*intraop, *preop, labels, registration);
    seconds.push_back(clock.seconds());
  }
  writeTransform(result.intraopToPreop, o.outputDir / "rigid_intraop_to_preop.tfm");
  const RigidAccuracy accuracy = accuracyOf(*result.intraopToPreop, simulated);
  std::vector<double> sorted = seconds;
  std::sort(sorted.begin(), sorted.end());
  const json summary = {{"size", o.size},
                        {"runs", o.runs},
                        {"wall_seconds", seconds},
                        {"wall_seconds_median", sorted[sorted.size() / 2]},
                        {"head_tre_mean_mm", accuracy.headMeanMm},
                        {"head_tre_max_mm", accuracy.headMaxMm},
                        {"rotation_error_degrees", accuracy.rotationErrorDegrees},
                        {"translation_error_mm", accuracy.translationErrorMm},
                        {"trustworthy", result.trustworthy},
                        {"nmi", result.normalizedMutualInformation},
                        {"iterations_per_level", result.iterationsPerLevel}};
  writeTextFileAtomically(o.outputDir / "rigid_accuracy.json", summary.dump(2) + "\n");
  std::printf("  head TRE mean %.3f max %.3f mm, rotation error %.3f degrees, median %.2f s\n", accuracy.headMeanMm,
              accuracy.headMaxMm, accuracy.rotationErrorDegrees, sorted[sorted.size() / 2]);
  if (!o.captureRange) return;

  // The capture range: random axes and directions (seeded) at each rotation and translation size.
  std::ostringstream csv;
  csv << "rotation_degrees,translation_mm,trial,success,trustworthy,head_tre_mean_mm,head_tre_max_mm,"
         "rotation_error_degrees,wall_seconds,nmi,overlap\n";
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  auto randomDirection = [&] {
    std::array<double, 3> v{gauss(rng), gauss(rng), gauss(rng)};
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (double& x : v) x /= n;
    return v;
  };
  for (double rotation : o.rotations) {
    for (double translation : o.translations) {
      unsigned successes = 0;
      for (unsigned trial = 0; trial < o.trials; ++trial) {
        const auto axis = randomDirection();
        const auto direction = randomDirection();
        // Axis and angle as the Euler angles the case takes.
        auto euler = itk::Euler3DTransform<double>::New();
        itk::Versor<double> versor;
        itk::Versor<double>::VectorType versorAxis;
        for (int i = 0; i < 3; ++i) versorAxis[i] = axis[i];
        versor.Set(versorAxis, rotation * M_PI / 180.0);
        euler->SetMatrix(versor.GetMatrix());
        CaseParameters parameters = defaults;
        parameters.rotationDegrees = {euler->GetAngleX() * 180.0 / M_PI, euler->GetAngleY() * 180.0 / M_PI,
                                      euler->GetAngleZ() * 180.0 / M_PI};
        for (int i = 0; i < 3; ++i) parameters.translationMillimetres[i] = translation * direction[i];
        const SimulatedCase trialCase = simulateCase(parameters);
        Stopwatch clock;
        RigidRegistrationResult r;
        bool trustworthy = true;
        RigidAccuracy a{1e9, 1e9, 180, 1e9};
        try {
          r = registerRigidly(*trialCase.intraopImage, *trialCase.preopImage, trialCase.preopLabels, registration);
          trustworthy = r.trustworthy;
          a = accuracyOf(*r.intraopToPreop, trialCase);
        } catch (const MethodError&) {
          trustworthy = false; // refused outright: detected
        }
        const bool success = a.success();
        successes += success;
        csv << rotation << ',' << translation << ',' << trial << ',' << success << ',' << trustworthy << ','
            << a.headMeanMm << ',' << a.headMaxMm << ',' << a.rotationErrorDegrees << ',' << clock.seconds() << ','
            << r.normalizedMutualInformation << ',' << r.overlap << '\n';
      }
      std::printf("  rotation %4.0f deg, translation %4.0f mm: %u/%u\n", rotation, translation, successes, o.trials);
      std::fflush(stdout);
    }
  }
  writeTextFileAtomically(o.outputDir / "capture_range.csv", csv.str());
}

struct ClassifyBenchOptions {
  fs::path outputDir;
  std::string size = "full";
  std::vector<double> noise{0, 0.03, 0.06, 0.1, 0.15, 0.2, 0.3};
  std::vector<double> bias{0, 0.2, 0.4, 0.6, 0.8};
  unsigned runs = 3;
  std::uint64_t seed = 2000;
};

struct ClassificationScore {
  double brainDice, ventricleDice, parenchymaDice, surfaceMm, seconds;
  TissueClassificationResult result;
};

/// Rigid registration, then classification, scored against the case's true labels.
ClassificationScore classifyCase(const SimulatedCase& c, bool n4)
{
  const RigidRegistrationResult rigid = registerRigidly(*c.intraopImage, *c.preopImage, c.preopLabels, {});
  TissueClassificationParameters parameters;
  parameters.biasCorrection = n4;
  Stopwatch clock;
  ClassificationScore score{};
  score.result = classifyTissues(*c.intraopImage, *c.preopLabels, *rigid.intraopToPreop, std::nullopt, parameters);
  score.seconds = clock.seconds();
  score.brainDice = diceCoefficient(*score.result.labels, *c.intraopLabels, {2, 3, 4});
  score.ventricleDice = diceCoefficient(*score.result.labels, *c.intraopLabels, {3});
  score.parenchymaDice = diceCoefficient(*score.result.labels, *c.intraopLabels, {2});
  score.surfaceMm = meanSurfaceDistanceMm(*score.result.labels, *c.intraopLabels, {2, 3, 4});
  return score;
}

void runClassifyBench(const ClassifyBenchOptions& o)
{
  if (o.runs == 0) throw InputError("--runs must be at least 1");
  const CaseParameters defaults = caseOfSize(o.size, o.seed);
  std::printf("bench classify: %s case, %u runs\n", o.size.c_str(), o.runs);
  const SimulatedCase simulated = simulateCase(defaults);
  std::vector<double> knn, stage;
  ClassificationScore score{};
  for (unsigned run = 0; run < o.runs; ++run) {
    score = classifyCase(simulated, false);
    knn.push_back(score.result.knnSeconds);
    stage.push_back(score.seconds);
  }
  auto medianOf = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const json speed = {{"size", o.size},
                      {"runs", o.runs},
                      {"noise", defaults.noiseFraction},
                      {"bias", defaults.biasStrength},
                      {"voxels", score.result.voxels},
                      {"knn_queries", score.result.knnQueries},
                      {"knn_seconds", knn},
                      {"stage_seconds", stage},
                      {"knn_seconds_median", medianOf(knn)},
                      {"stage_seconds_median", medianOf(stage)},
                      {"brain_dice", score.brainDice},
                      {"ventricle_dice", score.ventricleDice},
                      {"parenchyma_dice", score.parenchymaDice},
                      {"brain_surface_distance_mm", score.surfaceMm}};
  writeTextFileAtomically(o.outputDir / "classification_speed.json", speed.dump(2) + "\n");
  std::printf("  brain Dice %.3f, ventricles %.3f, surface %.2f mm; k-NN %.2f s, stage %.2f s\n", score.brainDice,
              score.ventricleDice, score.surfaceMm, medianOf(knn), medianOf(stage));

  std::ostringstream csv;
  csv << "variable,value,n4,brain_dice,ventricle_dice,parenchyma_dice,brain_surface_distance_mm,stage_seconds\n";
  auto row = [&](const char* variable, double value, bool n4, const CaseParameters& parameters) {
    const SimulatedCase c = simulateCase(parameters);
    const ClassificationScore s = classifyCase(c, n4);
    csv << variable << ',' << value << ',' << n4 << ',' << s.brainDice << ',' << s.ventricleDice << ',' << s.parenchymaDice
        << ',' << s.surfaceMm << ',' << s.seconds << '\n';
    std::printf("  %s %.2f%s: brain %.3f, ventricles %.3f, surface %.2f mm\n", variable, value, n4 ? " (N4)" : "", s.brainDice,
                s.ventricleDice, s.surfaceMm);
    std::fflush(stdout);
  };
  for (double noise : o.noise) {
    CaseParameters parameters = defaults;
    parameters.noiseFraction = noise;
    row("noise", noise, false, parameters);
  }
  for (double bias : o.bias) {
    CaseParameters parameters = defaults;
    parameters.biasStrength = bias;
    row("bias", bias, false, parameters);
    row("bias", bias, true, parameters);
  }
  writeTextFileAtomically(o.outputDir / "classification_sweep.csv", csv.str());
}

struct SimulateBenchOptions {
  fs::path outputDir;
  std::vector<double> equations{20000, 77511, 253308, 1000000};
  std::vector<int> ranks{1, 2};
  std::vector<std::string> solvers{"cg+gamg", "cg+hypre", "gmres+bjacobi", "cholesky+mumps"};
  double directLimit = 300000;   ///< no direct factorisation above this many equations (memory)
  double gmresLimit = 300000;    ///< the paper's solver is slow: not above this
};

/// A brain-sized ellipsoid (semi-axes 70, 85, 60 mm) cut from a Kuhn lattice of spacing h, its
/// surface nodes imposed with a sag under a craniotomy (10 mm peak, Gaussian, 25 mm) and zero
/// elsewhere: the shape of the problem BrainShift solves, at a chosen size.
FiniteElementJob ellipsoidPhantom(double h)
{
  const double a = 70, b = 85, c = 60;
  const int nx = int(std::ceil(2 * a / h)), ny = int(std::ceil(2 * b / h)), nz = int(std::ceil(2 * c / h));
  auto inside = [&](double x, double y, double z) { return (x * x) / (a * a) + (y * y) / (b * b) + (z * z) / (c * c) <= 1.0; };
  auto position = [&](int i, int j, int k) { return std::array<double, 3>{-a + i * h, -b + j * h, -c + k * h}; };
  auto latticeId = [&](int i, int j, int k) { return std::int64_t(i) + std::int64_t(nx + 1) * (std::int64_t(j) + std::int64_t(ny + 1) * k); };
  std::unordered_map<std::int64_t, std::int32_t> nodeOf;
  FiniteElementJob job;
  auto node = [&](int i, int j, int k) {
    const std::int64_t key = latticeId(i, j, k);
    auto [at, inserted] = nodeOf.emplace(key, std::int32_t(job.nodeCount()));
    if (inserted) {
      const auto p = position(i, j, k);
      job.nodes.insert(job.nodes.end(), p.begin(), p.end());
    }
    return at->second;
  };
  const int paths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < nz; ++k) {
    for (int j = 0; j < ny; ++j) {
      for (int i = 0; i < nx; ++i) {
        for (const auto& path : paths) {
          int corner[4][3];
          int cc[3] = {i, j, k};
          std::copy(cc, cc + 3, corner[0]);
          for (int s = 0; s < 3; ++s) {
            cc[path[s]] += 1;
            std::copy(cc, cc + 3, corner[s + 1]);
          }
          double centroid[3] = {0, 0, 0};
          for (const auto& q : corner) {
            const auto p = position(q[0], q[1], q[2]);
            for (int d = 0; d < 3; ++d) centroid[d] += p[d] / 4;
          }
          if (!inside(centroid[0], centroid[1], centroid[2])) continue;
          std::int32_t tet[4];
          for (int v = 0; v < 4; ++v) tet[v] = node(corner[v][0], corner[v][1], corner[v][2]);
          const double* p0 = &job.nodes[3 * std::size_t(tet[0])];
          double e[3][3];
          for (int v = 1; v < 4; ++v) {
            for (int d = 0; d < 3; ++d) e[v - 1][d] = job.nodes[3 * std::size_t(tet[v]) + std::size_t(d)] - p0[d];
          }
          const double det = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                             e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
          if (det < 0) std::swap(tet[2], tet[3]);
          job.tetrahedra.insert(job.tetrahedra.end(), tet, tet + 4);
          job.materialOfTetrahedron.push_back(0);
        }
      }
    }
  }
  job.materials = {{3000 * 1e-6, 0.45}};
  // Surface nodes: on a face that belongs to one tetrahedron only.
  std::unordered_map<std::string, int> faceCount;
  auto faceKey = [](std::int32_t x, std::int32_t y, std::int32_t z) {
    std::int32_t f[3] = {x, y, z};
    std::sort(f, f + 3);
    return std::string(reinterpret_cast<const char*>(f), sizeof(f));
  };
  const int faces[4][3] = {{0, 1, 2}, {0, 1, 3}, {0, 2, 3}, {1, 2, 3}};
  for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
    for (const auto& f : faces) faceCount[faceKey(job.tetrahedra[4 * t + f[0]], job.tetrahedra[4 * t + f[1]], job.tetrahedra[4 * t + f[2]])] += 1;
  }
  std::vector<char> onSurface(job.nodeCount(), 0);
  for (const auto& [key, count] : faceCount) {
    if (count != 1) continue;
    std::int32_t f[3];
    std::memcpy(f, key.data(), sizeof(f));
    for (std::int32_t v : f) onSurface[std::size_t(v)] = 1;
  }
  const double craniotomy[3] = {-40, -40, 35}; // right frontal, superior
  for (std::size_t v = 0; v < job.nodeCount(); ++v) {
    if (!onSurface[v]) continue;
    const double* p = &job.nodes[3 * v];
    const double r2 = (p[0] - craniotomy[0]) * (p[0] - craniotomy[0]) + (p[1] - craniotomy[1]) * (p[1] - craniotomy[1]) +
                      (p[2] - craniotomy[2]) * (p[2] - craniotomy[2]);
    const double sag = 10.0 * std::exp(-r2 / (2 * 25.0 * 25.0));
    job.fixedNodes.push_back(std::int32_t(v));
    // Sinking along the inward direction of the craniotomy.
    const double norm = std::sqrt(craniotomy[0] * craniotomy[0] + craniotomy[1] * craniotomy[1] + craniotomy[2] * craniotomy[2]);
    for (int d = 0; d < 3; ++d) job.fixedDisplacements.push_back(-sag * craniotomy[d] / norm);
  }
  return job;
}

std::string solverOptionsFor(const std::string& solver)
{
  if (solver == "cg+gamg") return "";
  if (solver == "cg+hypre") return "-ksp_type cg -pc_type hypre -pc_hypre_type boomeramg";
  if (solver == "gmres+bjacobi") return "-ksp_type gmres -pc_type bjacobi -ksp_max_it 20000";
  if (solver == "cholesky+mumps") return "-ksp_type preonly -pc_type cholesky -pc_factor_mat_solver_type mumps";
  throw InputError("--solvers: unknown solver '" + solver + "' (cg+gamg, cg+hypre, gmres+bjacobi, cholesky+mumps)");
}

void runSimulateBench(const SimulateBenchOptions& o)
{
  for (const auto& s : o.solvers) solverOptionsFor(s);
  std::ostringstream csv;
  csv << "target_equations,equations,tetrahedra,imposed_nodes,solver,ranks,assembly_seconds,setup_seconds,solve_seconds,"
         "prepare_wall_seconds,iterations,relative_residual,converged\n";
  const double volume = 4.0 / 3.0 * M_PI * 70 * 85 * 60;
  for (double target : o.equations) {
    const double h = std::cbrt(3.0 * volume / target);
    const FiniteElementJob mesh = ellipsoidPhantom(h);
    std::printf("bench simulate: %.0f equations wanted, h = %.2f mm: %zu nodes (%zu equations), %zu tetrahedra, %zu imposed\n",
                target, h, mesh.nodeCount(), 3 * mesh.nodeCount(), mesh.tetrahedronCount(), mesh.fixedNodes.size());
    std::fflush(stdout);
    // A second set of surface values: the next scan (the sag grown by 20 %).
    std::vector<double> nextScan = mesh.fixedDisplacements;
    for (double& d : nextScan) d *= 1.2;
    for (const std::string& solver : o.solvers) {
      const double equations = 3.0 * double(mesh.nodeCount());
      if (solver == "cholesky+mumps" && equations > o.directLimit) continue;
      if (solver == "gmres+bjacobi" && equations > o.gmresLimit) continue;
      for (int ranks : o.ranks) {
        FiniteElementJob job = mesh;
        job.solverOptions = solverOptionsFor(solver);
        FiniteElementRunOptions run;
        run.worker = workerBesideExecutable();
        run.ranks = ranks;
        run.timeoutSeconds = 1800;
        FiniteElementResult result;
        double prepare = 0;
        bool converged = true;
        try {
          FiniteElementSession session(job, run);
          prepare = session.prepareSeconds();
          session.solve(job.fixedDisplacements);
          result = session.solve(nextScan); // the during-surgery solve, warm
        } catch (const MethodError& e) {
          converged = false;
          std::printf("  %s, %d rank(s): %s\n", solver.c_str(), ranks, e.what());
        }
        csv << std::llround(target) << ',' << 3 * mesh.nodeCount() << ',' << mesh.tetrahedronCount() << ',' << mesh.fixedNodes.size() << ','
            << solver << ',' << ranks << ',' << result.assemblySeconds << ',' << result.setupSeconds << ',' << result.solveSeconds
            << ',' << prepare << ',' << result.iterations << ',' << result.relativeResidual << ',' << converged << '\n';
        if (converged) {
          std::printf("  %-15s %d rank(s): assembly %.2f s, setup %.2f s, solve %.3f s (%d iterations)\n", solver.c_str(), ranks,
                      result.assemblySeconds, result.setupSeconds, result.solveSeconds, result.iterations);
        }
        std::fflush(stdout);
        writeTextFileAtomically(o.outputDir / "simulate_bench.csv", csv.str());
      }
    }
  }
}

} // namespace


void addBenchCommand(CLI::App& app)
{
  CLI::App* bench = app.add_subcommand("bench", "Speed and accuracy measurements against the built-in case's truth "
                                                "(charts: Testing/Benchmarks/)");
  bench->require_subcommand(1);
  addMeshBenchCommand(*bench);

  auto rigid = std::make_shared<RigidBenchOptions>();
  CLI::App* command = bench->add_subcommand("rigid", "Rigid registration: accuracy and speed, and the capture range");
  command->add_option("--output-dir", rigid->outputDir, "where the measurements go")->required();
  command->add_option("--size", rigid->size, "full or small case")->capture_default_str();
  command->add_flag("--capture-range", rigid->captureRange, "also measure the success rate over initial misalignments");
  command->add_option("--rotations", rigid->rotations, "rotation sizes, degrees")->delimiter(',')->capture_default_str();
  command->add_option("--translations", rigid->translations, "translation sizes, mm")->delimiter(',')->capture_default_str();
  command->add_option("--trials", rigid->trials, "random axes and directions per cell")->capture_default_str();
  command->add_option("--runs", rigid->runs, "timed runs on the default case")->capture_default_str();
  command->add_option("--seed", rigid->seed, "seed of the cases and directions")->capture_default_str();
  command->callback([rigid] { runRigidBench(*rigid); });

  auto classify = std::make_shared<ClassifyBenchOptions>();
  CLI::App* classifyCommand = bench->add_subcommand(
    "classify", "Tissue classification: speed, and Dice against noise and bias (with and without N4)");
  classifyCommand->add_option("--output-dir", classify->outputDir, "where the measurements go")->required();
  classifyCommand->add_option("--size", classify->size, "full or small case")->capture_default_str();
  classifyCommand->add_option("--noise", classify->noise, "noise fractions")->delimiter(',')->capture_default_str();
  classifyCommand->add_option("--bias", classify->bias, "bias field strengths")->delimiter(',')->capture_default_str();
  classifyCommand->add_option("--runs", classify->runs, "timed runs on the default case")->capture_default_str();
  classifyCommand->add_option("--seed", classify->seed, "seed of the cases")->capture_default_str();
  addSurfaceBenchCommand(*bench);
  addUpdateBenchCommand(*bench);

  auto simulate = std::make_shared<SimulateBenchOptions>();
  CLI::App* simulateCommand = bench->add_subcommand(
    "simulate", "Finite element solve: time against size for the candidate solvers, 1 and 2 ranks, prepared and solved");
  simulateCommand->add_option("--output-dir", simulate->outputDir, "where the measurements go")->required();
  simulateCommand->add_option("--equations", simulate->equations, "problem sizes")->delimiter(',')->capture_default_str();
  simulateCommand->add_option("--ranks", simulate->ranks, "rank counts")->delimiter(',')->capture_default_str();
  simulateCommand->add_option("--solvers", simulate->solvers, "solvers")->delimiter(',')->capture_default_str();
  simulateCommand->callback([simulate] {
    for (double e : simulate->equations) {
      if (!(e >= 1000 && e <= 5e6)) throw InputError("--equations: each must be within 1000 to 5000000");
    }
    for (int r : simulate->ranks) {
      if (r < 1 || r > 64) throw InputError("--ranks: each must be within 1 to 64");
    }
    runSimulateBench(*simulate);
  });

  classifyCommand->callback([classify] {
    for (double v : classify->noise) {
      if (!(v >= 0 && v <= 0.5)) throw InputError("--noise: each must be within 0 to 0.5");
    }
    for (double v : classify->bias) {
      if (!(v >= 0 && v <= 1)) throw InputError("--bias: each must be within 0 to 1");
    }
    runClassifyBench(*classify);
  });
}

} // namespace brainshift::cli
