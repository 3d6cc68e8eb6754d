// brainshift bench: measurements of speed and accuracy against the built-in case's truth.
// Charts and the comparison with other tools are made by the scripts in Testing/Benchmarks/.
#include "AtomicFile.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "LandmarkEvaluation.h"
#include "RigidRegistrationLogic.h"
#include "LabelOverlap.h"
#include "RunReport.h"
#include "TissueClassificationLogic.h"
#include "VolumeIO.h"

#include <itkEuler3DTransform.h>
#include <itkMatrixOffsetTransformBase.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <sstream>

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

void requireRigidBenchOptions(const RigidBenchOptions& o)
{
  if (o.trials == 0 || o.runs == 0) throw InputError("--trials and --runs must be at least 1");
  for (double r : o.rotations) {
    if (!(r >= 0 && r <= 180)) throw InputError("--rotations: each must be within 0 to 180 degrees");
  }
  for (double t : o.translations) {
    if (!(t >= 0 && t <= 50)) throw InputError("--translations: each must be within 0 to 50 mm");
  }
}

/// Accuracy and speed on the case with its default misalignment, timed from the files as a user
/// (and elastix in the comparison) meets them: rigid_accuracy.json and the last run's transform.
void benchDefaultMisalignment(const RigidBenchOptions& o, const CaseParameters& defaults, const RigidRegistrationParameters& registration)
{
  std::printf("bench rigid: %s case, %u runs\n", o.size.c_str(), o.runs);
  const SimulatedCase simulated = simulateCase(defaults);
  writeCase(simulated, defaults, o.outputDir / "case");
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
}

/// A unit vector of a seeded random direction.
std::array<double, 3> randomDirection(std::mt19937_64& rng, std::normal_distribution<double>& gauss)
{
  std::array<double, 3> v{gauss(rng), gauss(rng), gauss(rng)};
  const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (double& x : v) x /= n;
  return v;
}

/// The case misaligned by a rotation about `axis` and a translation along `direction` (the axis
/// and angle as the Euler angles the case takes).
CaseParameters misalignedCase(const CaseParameters& defaults, double rotation, const std::array<double, 3>& axis, double translation,
                              const std::array<double, 3>& direction)
{
  auto euler = itk::Euler3DTransform<double>::New();
  itk::Versor<double> versor;
  itk::Versor<double>::VectorType versorAxis;
  for (int i = 0; i < 3; ++i) versorAxis[i] = axis[i];
  versor.Set(versorAxis, rotation * M_PI / 180.0);
  euler->SetMatrix(versor.GetMatrix());
  CaseParameters parameters = defaults;
  parameters.rotationDegrees = {euler->GetAngleX() * 180.0 / M_PI, euler->GetAngleY() * 180.0 / M_PI, euler->GetAngleZ() * 180.0 / M_PI};
  for (int i = 0; i < 3; ++i) parameters.translationMillimetres[i] = translation * direction[i];
  return parameters;
}

/// One trial of the capture range: registers the case, appends its row; whether it succeeded.
bool captureTrial(const CaseParameters& parameters, const RigidRegistrationParameters& registration, double rotation,
                  double translation, unsigned trial, std::ostringstream& csv)
{
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
  csv << rotation << ',' << translation << ',' << trial << ',' << success << ',' << trustworthy << ',' << a.headMeanMm << ','
      << a.headMaxMm << ',' << a.rotationErrorDegrees << ',' << clock.seconds() << ',' << r.normalizedMutualInformation << ','
      << r.overlap << '\n';
  return success;
}

/// The capture range: random axes and directions (seeded) at each rotation and translation size
/// (capture_range.csv).
void benchCaptureRange(const RigidBenchOptions& o, const CaseParameters& defaults, const RigidRegistrationParameters& registration)
{
  std::ostringstream csv;
  csv << "rotation_degrees,translation_mm,trial,success,trustworthy,head_tre_mean_mm,head_tre_max_mm,"
         "rotation_error_degrees,wall_seconds,nmi,overlap\n";
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  for (double rotation : o.rotations) {
    for (double translation : o.translations) {
      unsigned successes = 0;
      for (unsigned trial = 0; trial < o.trials; ++trial) {
        const auto axis = randomDirection(rng, gauss);
        const auto direction = randomDirection(rng, gauss);
        const CaseParameters parameters = misalignedCase(defaults, rotation, axis, translation, direction);
        successes += captureTrial(parameters, registration, rotation, translation, trial, csv);
      }
      std::printf("  rotation %4.0f deg, translation %4.0f mm: %u/%u\n", rotation, translation, successes, o.trials);
      std::fflush(stdout);
    }
  }
  writeTextFileAtomically(o.outputDir / "capture_range.csv", csv.str());
}

void runRigidBench(const RigidBenchOptions& o)
{
  requireRigidBenchOptions(o);
  const CaseParameters defaults = caseOfSize(o.size, o.seed);
  const RigidRegistrationParameters registration;
  benchDefaultMisalignment(o, defaults, registration);
  if (o.captureRange) benchCaptureRange(o, defaults, registration);
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
  takePreoperativeImage(parameters, *c.preopImage, *c.preopLabels, *rigid.intraopToPreop);
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

  addSimulateBenchCommand(*bench);
  addFuzzBenchCommand(*bench);

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
