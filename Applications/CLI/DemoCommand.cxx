#include "AtomicFile.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "LabelOverlap.h"
#include "ModelIO.h"
#include "SurfaceDisplacementEvaluation.h"
#include "LandmarkEvaluation.h"
#include "UncertaintyEvaluation.h"
#include "VolumeIO.h"
#include "RunCommands.h"
#include "SceneIO.h"

#include <itkIdentityTransform.h>

#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <set>
#include <utility>

namespace brainshift::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct DemoOptions {
  RunOptions run;
  std::string size = "full";
  std::uint64_t seed = 2000;
  double shift = 10.0;
  std::string craniotomy = "right-frontal";
  bool noResection = false;
  std::vector<double> rotation{4.0, -3.0, 6.0};
  std::vector<double> translation{6.0, -8.0, 5.0};
  double noise = 0.03, bias = 0.2;
  std::string scenario = "default";
  std::string contrast = "t1", tumour = "rim-enhancing", gap = "dark", truth = "kinematic";
  bool cavityRim = false;
  std::string fieldOfView = "whole-head";
  /// The options given on the command line (they override the scenario's values).
  std::set<std::string> given;
};

/// The scenario's parameters with the options given on the command line over them.
CaseParameters caseParametersOf(const DemoOptions& o)
{
  CaseParameters p = caseScenario(o.scenario).parameters;
  if (o.size != "full" && o.size != "small") throw InputError("--size: '" + o.size + "' is neither full nor small");
  p.size = o.size == "full" ? CaseSize::Full : CaseSize::Small;
  auto given = [&](const char* option) { return o.given.count(option) > 0; };
  if (given("--seed")) p.seed = o.seed;
  if (given("--shift")) p.shiftMillimetres = o.shift;
  if (given("--craniotomy")) p.craniotomy = craniotomySiteFromString(o.craniotomy);
  if (given("--no-resection")) p.resection = !o.noResection;
  for (int i = 0; i < 3; ++i) {
    if (given("--rotation")) p.rotationDegrees[i] = o.rotation[i];
    if (given("--translation")) p.translationMillimetres[i] = o.translation[i];
  }
  if (given("--noise")) p.noiseFraction = o.noise;
  if (given("--bias")) p.biasStrength = o.bias;
  if (given("--contrast")) p.contrast = intraopContrastFromString(o.contrast);
  if (given("--tumour")) p.tumourAppearance = tumourAppearanceFromString(o.tumour);
  if (given("--gap")) p.gap = gapContentFromString(o.gap);
  if (given("--cavity-rim")) p.cavityRim = o.cavityRim;
  if (given("--truth")) p.truth = truthModelFromString(o.truth);
  if (given("--field-of-view")) p.fieldOfView = fieldOfViewFromString(o.fieldOfView);
  p.validate();
  return p;
}

/// The case as a 3D Slicer scene: the intraoperative scan in the world, the preoperative data
/// under the true intraop_to_preop transform (so they overlay it), the truth labels, the landmarks.
void writeCaseScene(const SimulatedCase& simulated, const CaseFiles& files)
{
  Scene scene;
  auto stored = [](auto node, const fs::path& file) {
    node->setStorageFile(fs::absolute(file));
    node->markStored();
    return node;
  };
  auto truth = scene.add(stored(TransformNode::create("truth intraop_to_preop", simulated.intraopToPreop), files.truthTransform));
  truth->setRole("truth");
  auto intraop = scene.add(stored(ScalarVolumeNode::create("intraop image", simulated.intraopImage), files.intraopImage));
  intraop->setRole("intraop");
  auto preop = scene.add(stored(ScalarVolumeNode::create("preop image", simulated.preopImage), files.preopImage));
  preop->setRole("preop");
  preop->setParentTransformId(truth->id());
  auto labels = scene.add(stored(LabelMapVolumeNode::create("preop labels", simulated.preopLabels), files.preopLabels));
  labels->setRole("preop");
  labels->setParentTransformId(truth->id());
  auto fmri = scene.add(stored(ScalarVolumeNode::create("preop fmri", simulated.preopFmri), files.preopFmri));
  fmri->setRole("overlay");
  fmri->setDisplay(VolumeDisplay::statisticalMap());
  fmri->setParentTransformId(truth->id());
  auto truthLabels = scene.add(stored(LabelMapVolumeNode::create("truth intraop labels", simulated.intraopLabels), files.truthIntraopLabels));
  truthLabels->setRole("truth");
  auto landmarks = scene.add(LandmarksNode::create("landmarks", simulated.landmarks));
  landmarks->setRole("truth");
  landmarks->setParentTransformId(truth->id());
  // Slicer opens on the intraoperative scan with the true intraoperative labels over it.
  SliceViewLayers layers;
  layers.backgroundVolumeId = intraop->id();
  layers.labelVolumeId = truthLabels->id();
  scene.setSliceViewLayers(layers);
  writeScene(scene, files.folder / "scene.mrml");
}

json evaluationOf(const SpatialTransform& transform, const std::vector<LandmarkPair>& landmarks)
{
  return json::parse(toJsonText(evaluateTransform(transform, landmarks)));
}

void addCaseOptions(CLI::App* command, DemoOptions& o)
{
  command->add_option("--size", o.size, "full (1 mm preop, 256x256x60 intraop) or small (for tests)")->capture_default_str();
  command->add_option("--seed", o.seed, "random seed of the case (noise, tumour shape, landmarks)")->capture_default_str();
  command->add_option("--shift", o.shift, "peak sinking of the brain under the craniotomy, mm")->capture_default_str();
  command->add_option("--craniotomy", o.craniotomy, "right-frontal, left-frontal, right-parietal, left-parietal or vertex")->capture_default_str();
  command->add_flag("--no-resection", o.noResection, "keep the tumour in the intraoperative scan");
  command->add_option("--rotation", o.rotation, "head rotation in the scanner about L, P, S, degrees")->capture_default_str()->expected(3);
  command->add_option("--translation", o.translation, "head translation in the scanner, LPS mm")->capture_default_str()->expected(3);
  command->add_option("--noise", o.noise, "Rician noise sigma as a fraction of white matter")->capture_default_str();
  command->add_option("--bias", o.bias, "bias field strength (log amplitude)")->capture_default_str();
  std::string scenarioNames;
  for (const CaseScenario& scenario : caseScenarios()) scenarioNames += (scenarioNames.empty() ? "" : ", ") + scenario.name;
  command->add_option("--scenario", o.scenario, "a named variant of the case (the options above and below override its values): " + scenarioNames)
    ->capture_default_str();
  command->add_option("--contrast", o.contrast, "intraoperative contrast: t1, low-field-t1, t2, flair or t1-post-contrast")->capture_default_str();
  command->add_option("--tumour", o.tumour, "tumour look: rim-enhancing, hypointense or nearly-isointense")->capture_default_str();
  command->add_option("--gap", o.gap, "what fills the gap under the craniotomy: dark or fluid-and-air")->capture_default_str();
  command->add_flag("--cavity-rim", o.cavityRim, "a bright rim of blood products on the resection cavity's wall");
  command->add_option("--truth", o.truth,
                      "the truth deformation: kinematic (analytic subsidence) or finite-element-sliding (CalculiX, sliding "
                      "brain surface, fixed skull base; about 30 s more)")->capture_default_str();
  command->add_option("--field-of-view", o.fieldOfView,
                      "what the intraoperative scan covers: whole-head, or slab (30 axial slices of 2.5 mm around the "
                      "craniotomy and the tumour)")->capture_default_str();
}

void addRegisterOptions(CLI::App* command, RunOptions& run)
{
  command->add_option("--config", run.config, "JSON configuration for register");
  command->add_option("--mesh-resolution", run.meshResolutionMm, "for register: tetrahedron edge length, mm");
  command->add_option("--mesh-grading", run.meshGrading, "for register: mesh grading (0: uniform)");
  command->add_option("--ranks", run.ranks, "for register: MPI ranks of the finite element worker");
  command->add_option("--solver-options", run.solverOptions, "for register: PETSc options");
}

/// A report.json already in the output folder must be an earlier demo's (then it is removed).
void removeEarlierDemoReport(const fs::path& out, const fs::path& reportFile)
{
  std::error_code ec;
  if (!fs::exists(reportFile, ec)) return;
  RunReport previous(reportFile);
  if (!previous.document().contains("demo")) {
    throw InputError(out.string() + ": holds the results of another run (not a demo); choose another --output-dir");
  }
  fs::remove(reportFile);
}

/// Builds the case and writes it (with its scene) to `files`; returns it and the seconds it took.
std::pair<SimulatedCase, double> buildCase(const CaseParameters& parameters, const DemoOptions& o, const CaseFiles& files)
{
  Stopwatch caseClock;
  std::printf("building the built-in case, scenario %s (%s, seed %llu, shift %.1f mm, %s craniotomy%s, %s contrast, %s gap) ...\n",
              o.scenario.c_str(), o.size.c_str(), static_cast<unsigned long long>(parameters.seed), parameters.shiftMillimetres,
              toString(parameters.craniotomy).c_str(), parameters.resection ? ", resection" : "", toString(parameters.contrast).c_str(),
              toString(parameters.gap).c_str());
  std::fflush(stdout);
  SimulatedCase simulated = simulateCase(parameters);
  writeCase(simulated, parameters, files.folder);
  writeCaseScene(simulated, files);
  const double caseSeconds = caseClock.seconds();
  const CaseFigures& f = simulated.figures;
  std::printf("  %zu landmarks, max brain displacement %.2f mm, gap %.1f ml, cavity %.1f ml (%.1f s)\n", simulated.landmarks.size(),
              f.maxBrainDisplacementMm, f.gapVolumeMl, f.cavityVolumeMl, caseSeconds);
  return {std::move(simulated), caseSeconds};
}

/// How register ended on the case: complete, or stopped by a missing tool (noted), or with its
/// non-rigid update rejected by the trust assessment (`rejected`: the rigid result replaced it in
/// every file; the demo still evaluates it, and the update set aside, then fails with its reason).
struct RegistrationEnd {
  bool pipelineComplete = false;
  std::optional<MethodError> rejected;
};

RegistrationEnd registerCase(RunContext& context, RunReport& report)
{
  RegistrationEnd end;
  try {
    runRegistration(context);
    end.pipelineComplete = true;
  } catch (const NotAvailableError& e) {
    report.addWarning(std::string(e.what()) + "; the demo evaluates what exists");
    std::printf("note: %s\n", e.what());
  } catch (const MethodError& e) {
    report.addWarning(e.what());
    report.save();
    const json& document = report.document();
    const bool fellBack = document.contains("stages") && document["stages"].contains("warp") &&
                          document["stages"]["warp"].value("rigid_fallback", false);
    if (!fellBack) throw;
    end.rejected = e;
  }
  return end;
}

/// Target registration errors of the reference transforms and of those the run wrote.
json transformEvaluations(const SimulatedCase& simulated, const fs::path& out)
{
  json transforms = json::object();
  auto identity = itk::IdentityTransform<double, 3>::New();
  transforms["identity"] = evaluationOf(*identity, simulated.landmarks);
  transforms["truth_rigid"] = evaluationOf(*simulated.rigidIntraopToPreop, simulated.landmarks);
  transforms["truth"] = evaluationOf(*simulated.intraopToPreop, simulated.landmarks);
  std::error_code ec;
  for (const auto& [key, file] : {std::pair<std::string, fs::path>{"brainshift_rigid", out / "rigid_intraop_to_preop.tfm"},
                                  {"brainshift", out / "intraop_to_preop.h5"},
                                  {"brainshift_rejected_update", out / "rejected_intraop_to_preop.h5"}}) {
    if (fs::exists(file, ec)) transforms[key] = evaluationOf(*readTransform(file), simulated.landmarks);
  }
  return transforms;
}

json classificationEvaluation(const SimulatedCase& simulated, const fs::path& classifiedFile)
{
  const LabelImage::Pointer classified = readLabelVolume(classifiedFile);
  const LabelImage& truthLabels = *simulated.intraopLabels;
  const json c = {{"brain_dice", diceCoefficient(*classified, truthLabels, {2, 3, 4})},
                  {"ventricle_dice", diceCoefficient(*classified, truthLabels, {3})},
                  {"parenchyma_dice", diceCoefficient(*classified, truthLabels, {2})},
                  {"brain_surface_distance_mm", meanSurfaceDistanceMm(*classified, truthLabels, {2, 3, 4})}};
  std::printf("classification: brain Dice %.3f, ventricles %.3f, brain surface distance %.2f mm\n", c["brain_dice"].get<double>(),
              c["ventricle_dice"].get<double>(), c["brain_surface_distance_mm"].get<double>());
  return c;
}

/// The surface's displacements against the truth, in the model frame of the rigid result used;
/// nothing when the surface file holds no surface.
std::optional<json> surfaceEvaluation(const SimulatedCase& simulated, const fs::path& out)
{
  vtkSmartPointer<vtkPolyData> surface = vtkPolyData::SafeDownCast(readModel(out / "brain_surface.vtp"));
  const SpatialTransform::Pointer rigid = readTransform(out / "rigid_intraop_to_preop.tfm");
  if (!surface) return std::nullopt;
  const SurfaceDisplacementAccuracy a = evaluateSurfaceDisplacement(surface, *simulated.intraopToPreop, *rigid, *simulated.preopLabels);
  std::printf("surface: displacement error mean %.2f mm, p95 %.2f mm (true mean %.2f, max %.2f mm); "
              "where it moves > 2 mm: %.2f mm of %.2f mm; residual to the true boundary %.2f mm\n",
              a.meanErrorMm, a.p95ErrorMm, a.meanTrueDisplacementMm, a.maxTrueDisplacementMm, a.movingMeanErrorMm,
              a.movingMeanTrueDisplacementMm, a.meanResidualMm);
  return json{{"imposed_nodes", a.nodes},
              {"mean_error_mm", a.meanErrorMm},
              {"median_error_mm", a.medianErrorMm},
              {"p95_error_mm", a.p95ErrorMm},
              {"max_error_mm", a.maxErrorMm},
              {"true_mean_displacement_mm", a.meanTrueDisplacementMm},
              {"true_max_displacement_mm", a.maxTrueDisplacementMm},
              {"moving_nodes", a.movingNodes},
              {"moving_mean_error_mm", a.movingMeanErrorMm},
              {"moving_p95_error_mm", a.movingP95ErrorMm},
              {"moving_true_mean_displacement_mm", a.movingMeanTrueDisplacementMm},
              {"residual_to_true_boundary_mm", a.meanResidualMm},
              {"p95_residual_to_true_boundary_mm", a.p95ResidualMm}};
}

/// The confidence map against the true error (written as true_error_mm.nii.gz).
json uncertaintyEvaluation(const SimulatedCase& simulated, const fs::path& out)
{
  const UncertaintyValidation u =
    validateUncertainty(*readDisplacementField(out / "displacement_intraop_to_preop.nrrd"), *simulated.intraopToPreop,
                        *readScalarVolume(out / "displacement_uncertainty_mm.nii.gz"), *simulated.intraopLabels);
  const json evaluation = {{"voxels", u.voxels},
                           {"rank_correlation", u.rankCorrelation},
                           {"mean_true_error_mm", u.meanTrueErrorMm},
                           {"mean_estimate_mm", u.meanEstimateMm},
                           {"share_called_below_1mm", u.shareCalledBelow1Mm},
                           {"called_below_1mm_truly_below_1_5mm", u.calledBelow1MmTrulyBelow1_5Mm},
                           {"true_error_where_called_above_2mm", u.trueErrorWhereCalledAbove2MmMm},
                           {"true_error_file", "true_error_mm.nii.gz"}};
  writeScalarVolume(u.trueError, out / "true_error_mm.nii.gz");
  std::printf("confidence map: rank correlation with the true error %.2f over %zu brain voxels; %.0f %% called below 1 mm, "
              "%.0f %% of them truly below 1.5 mm\n",
              u.rankCorrelation, u.voxels, 100 * u.shareCalledBelow1Mm, 100 * u.calledBelow1MmTrulyBelow1_5Mm);
  return evaluation;
}

/// evaluation.json: the transforms' target registration errors, and the classification, surface
/// and confidence map against the truth where the run wrote them.
json evaluationAgainstTruth(const SimulatedCase& simulated, const fs::path& out, bool pipelineComplete)
{
  json evaluation = {{"landmarks", "case/landmarks.csv"},
                     {"pairs", simulated.landmarks.size()},
                     {"pipeline_complete", pipelineComplete},
                     {"transforms", transformEvaluations(simulated, out)}};
  std::error_code ec;
  if (fs::exists(out / "intraop_labels.nii.gz", ec)) {
    evaluation["classification"] = classificationEvaluation(simulated, out / "intraop_labels.nii.gz");
  }
  if (fs::exists(out / "brain_surface.vtp", ec) && fs::exists(out / "rigid_intraop_to_preop.tfm", ec)) {
    if (std::optional<json> surface = surfaceEvaluation(simulated, out)) evaluation["surface"] = *surface;
  }
  if (fs::exists(out / "displacement_uncertainty_mm.nii.gz", ec) && fs::exists(out / "displacement_intraop_to_preop.nrrd", ec)) {
    evaluation["uncertainty"] = uncertaintyEvaluation(simulated, out);
  }
  return evaluation;
}

void printTargetRegistrationErrors(const json& transforms, std::size_t landmarks)
{
  std::printf("target registration error on %zu landmarks (mm):\n", landmarks);
  for (auto it = transforms.begin(); it != transforms.end(); ++it) {
    std::printf("  %-18s mean %7.3f  p95 %7.3f  max %7.3f\n", it.key().c_str(), it.value()["mean_mm"].get<double>(),
                it.value()["p95_mm"].get<double>(), it.value()["max_mm"].get<double>());
  }
}

/// The demo: builds the case, runs register on it, evaluates what it wrote against the truth.
void runDemo(const DemoOptions& options)
{
  const CaseParameters parameters = caseParametersOf(options);
  const Configuration configuration = configurationFor(options.run);
  const fs::path out = options.run.outputDir;
  const fs::path reportFile = out / "report.json";
  removeEarlierDemoReport(out, reportFile);
  const CaseFiles files(out / "case");
  const auto [simulated, caseSeconds] = buildCase(parameters, options, files);

  RunReport report(reportFile);
  report.set("demo", {{"case_folder", "case"},
                      {"case_seconds", caseSeconds},
                      {"size", options.size},
                      {"seed", parameters.seed},
                      {"scenario", options.scenario},
                      {"shift_mm", parameters.shiftMillimetres}});
  RunOptions run = options.run;
  run.preopImage = files.preopImage;
  run.preopLabels = files.preopLabels;
  run.intraopImage = files.intraopImage;
  run.overlays = {"fmri=" + files.preopFmri.string()};
  RunContext context(run, configuration, report);
  const RegistrationEnd end = registerCase(context, report);

  const json evaluation = evaluationAgainstTruth(simulated, out, end.pipelineComplete);
  writeTextFileAtomically(out / "evaluation.json", evaluation.dump(2) + "\n");
  report.save();
  printTargetRegistrationErrors(evaluation["transforms"], simulated.landmarks.size());
  std::printf("wrote %s (report.json, evaluation.json, case/)\n", out.c_str());
  if (end.rejected) throw *end.rejected;
}

} // namespace

void addDemoCommand(CLI::App& app)
{
  auto options = std::make_shared<DemoOptions>();
  options->run.outputDir = "brainshift-demo";
  CLI::App* command = app.add_subcommand(
    "demo", "The main job on the built-in case: Colin27 with a simulated brain shift of known truth; runs "
            "register on it and evaluates the result");
  command->add_option("--output-dir", options->run.outputDir, "output folder (the case goes to its case/)")->capture_default_str();
  addCaseOptions(command, *options);
  addRegisterOptions(command, options->run);
  command->callback([command, options] {
    for (const char* name : {"--seed", "--shift", "--craniotomy", "--no-resection", "--rotation", "--translation", "--noise",
                             "--bias", "--contrast", "--tumour", "--gap", "--cavity-rim", "--truth", "--field-of-view"}) {
      if (command->count(name) > 0) options->given.insert(name);
    }
    runDemo(*options);
  });
}

} // namespace brainshift::cli
