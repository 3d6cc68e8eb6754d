// brainshift demo: the built-in case (Logic/CaseSimulation/BuiltInCaseFiles.h) built and written,
// register run on it (Logic/Update/UpdatePipeline.h), and what it wrote evaluated against the case's
// truth (Logic/CaseSimulation/UpdateEvaluationAgainstTruth.h). This file parses the options, calls
// the logic and prints.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BuiltInCaseFiles.h"
#include "RunCommands.h"
#include "UpdateEvaluationAgainstTruth.h"

#include <array>
#include <cstdio>
#include <memory>
#include <set>

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
  double tumourDepth = 22.0;
  bool cavityRim = false;
  std::string fieldOfView = "whole-head";
  /// The options given on the command line (they override the scenario's values).
  std::set<std::string> given;
};

/// The options given on the command line as values over the scenario's.
CaseParameterOverrides caseOverridesOf(const DemoOptions& o)
{
  auto given = [&](const char* option) { return o.given.count(option) > 0; };
  CaseParameterOverrides overrides;
  if (given("--seed")) overrides.seed = o.seed;
  if (given("--shift")) overrides.shiftMillimetres = o.shift;
  if (given("--craniotomy")) overrides.craniotomy = craniotomySiteFromString(o.craniotomy);
  if (given("--no-resection")) overrides.resection = !o.noResection;
  if (given("--rotation")) overrides.rotationDegrees = std::array<double, 3>{o.rotation[0], o.rotation[1], o.rotation[2]};
  if (given("--translation")) {
    overrides.translationMillimetres = std::array<double, 3>{o.translation[0], o.translation[1], o.translation[2]};
  }
  if (given("--noise")) overrides.noiseFraction = o.noise;
  if (given("--bias")) overrides.biasStrength = o.bias;
  if (given("--contrast")) overrides.contrast = intraopContrastFromString(o.contrast);
  if (given("--tumour")) overrides.tumourAppearance = tumourAppearanceFromString(o.tumour);
  if (given("--tumour-depth")) overrides.tumourDepthMm = o.tumourDepth;
  if (given("--gap")) overrides.gap = gapContentFromString(o.gap);
  if (given("--cavity-rim")) overrides.cavityRim = o.cavityRim;
  if (given("--truth")) overrides.truth = truthModelFromString(o.truth);
  if (given("--field-of-view")) overrides.fieldOfView = fieldOfViewFromString(o.fieldOfView);
  return overrides;
}

/// The scenario's parameters with the options given on the command line over them.
CaseParameters caseParametersOf(const DemoOptions& o)
{
  if (o.size != "full" && o.size != "small") throw InputError("--size: '" + o.size + "' is neither full nor small");
  return builtInCaseParameters(o.scenario, o.size == "full" ? CaseSize::Full : CaseSize::Small, caseOverridesOf(o));
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
  command->add_option("--tumour-depth", o.tumourDepth,
                      "the tumour's centre below the cortex at the craniotomy, mm (13: it reaches the cortex)")->capture_default_str();
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

/// Builds the case and writes it (with its scene) to `files`, saying so.
BuiltInCase buildCase(const CaseParameters& parameters, const DemoOptions& o, const CaseFiles& files)
{
  std::printf("building the built-in case, scenario %s (%s, seed %llu, shift %.1f mm, %s craniotomy%s, %s contrast, %s gap) ...\n",
              o.scenario.c_str(), o.size.c_str(), static_cast<unsigned long long>(parameters.seed), parameters.shiftMillimetres,
              toString(parameters.craniotomy).c_str(), parameters.resection ? ", resection" : "", toString(parameters.contrast).c_str(),
              toString(parameters.gap).c_str());
  std::fflush(stdout);
  BuiltInCase built = buildBuiltInCaseFiles(parameters, files);
  const CaseFigures& f = built.simulated.figures;
  std::printf("  %zu landmarks, max brain displacement %.2f mm, gap %.1f ml, cavity %.1f ml (%.1f s)\n", built.simulated.landmarks.size(),
              f.maxBrainDisplacementMm, f.gapVolumeMl, f.cavityVolumeMl, built.seconds);
  return built;
}

/// The register inputs of the built-in case: its images and labels, its fMRI as an overlay.
RunOptions registrationOptionsFor(const CaseFiles& files, RunOptions run)
{
  run.preopImage = files.preopImage;
  run.preopLabels = files.preopLabels;
  run.intraopImage = files.intraopImage;
  run.overlays = {"fmri=" + files.preopFmri.string()};
  return run;
}

/// Runs register on the case; a missing tool is noted (the demo evaluates what exists).
RegistrationEnd registerCase(RunContext& context)
{
  const RegistrationEnd end = runRegistrationForEvaluation(context);
  if (end.notAvailable) {
    context.report().addWarning(std::string(end.notAvailable->what()) + "; the demo evaluates what exists");
    std::printf("note: %s\n", end.notAvailable->what());
  }
  return end;
}

/// The classification, surface and confidence map figures of evaluation.json, a line each.
void printEvaluationAgainstTruth(const json& evaluation)
{
  if (evaluation.contains("classification")) {
    const json& c = evaluation["classification"];
    std::printf("classification: brain Dice %.3f, ventricles %.3f, brain surface distance %.2f mm\n", c["brain_dice"].get<double>(),
                c["ventricle_dice"].get<double>(), c["brain_surface_distance_mm"].get<double>());
  }
  if (evaluation.contains("surface")) {
    const json& a = evaluation["surface"];
    std::printf("surface: displacement error mean %.2f mm, p95 %.2f mm (true mean %.2f, max %.2f mm); "
                "where it moves > 2 mm: %.2f mm of %.2f mm; residual to the true boundary %.2f mm\n",
                a["mean_error_mm"].get<double>(), a["p95_error_mm"].get<double>(), a["true_mean_displacement_mm"].get<double>(),
                a["true_max_displacement_mm"].get<double>(), a["moving_mean_error_mm"].get<double>(),
                a["moving_true_mean_displacement_mm"].get<double>(), a["residual_to_true_boundary_mm"].get<double>());
  }
  if (const json& b = evaluation.value("boundary_under_craniotomy", json::object()); b.contains("shown") && b["shown"].contains("brainshift")) {
    const json &s = b["shown"], &n = b.value("imposed_nodes", json::object());
    const json& rigid = s.value("brainshift_rigid", s["truth_rigid"]);
    std::printf("brain boundary under the craniotomy (%.0f mm radius) to the true one: update mean %.2f mm, p95 %.2f mm "
                "(from the shown boundary %.2f / %.2f mm; both ways %.2f mm); rigid %.2f / %.2f mm; surface nodes %.2f / %.2f mm\n",
                b["radius_mm"].get<double>(), s["brainshift"]["mean_abs_mm"].get<double>(), s["brainshift"]["p95_abs_mm"].get<double>(),
                s["brainshift"]["from_shown"]["mean_abs_mm"].get<double>(), s["brainshift"]["from_shown"]["p95_abs_mm"].get<double>(),
                s["brainshift"].value("symmetric_mean_abs_mm", json()).is_number() ? s["brainshift"]["symmetric_mean_abs_mm"].get<double>() : std::nan(""),
                rigid["mean_abs_mm"].get<double>(), rigid["p95_abs_mm"].get<double>(),
                n.value("mean_abs_mm", 0.0), n.value("p95_abs_mm", 0.0));
  }
  if (evaluation.contains("uncertainty")) {
    const json& u = evaluation["uncertainty"];
    std::printf("confidence map: rank correlation with the true error %.2f over %zu brain voxels; %.0f %% called below 1 mm, "
                "%.0f %% of them truly below 1.5 mm\n",
                u["rank_correlation"].get<double>(), u["voxels"].get<std::size_t>(), 100 * u["share_called_below_1mm"].get<double>(),
                100 * u["called_below_1mm_truly_below_1_5mm"].get<double>());
  }
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
  const BuiltInCase built = buildCase(parameters, options, files);

  RunReport report(reportFile);
  report.set("demo", {{"case_folder", "case"},
                      {"case_seconds", built.seconds},
                      {"size", options.size},
                      {"seed", parameters.seed},
                      {"scenario", options.scenario},
                      {"shift_mm", parameters.shiftMillimetres}});
  if (const auto folds = foldedTruthWarning(built.simulated.figures)) {
    report.addWarning(*folds);
    std::printf("warning: %s\n", folds->c_str());
  }
  RunContext context(registrationOptionsFor(files, options.run), configuration, report);
  const RegistrationEnd end = registerCase(context);

  const json evaluation = evaluateUpdateAgainstTruth(built.simulated, out, "case/landmarks.csv", end.pipelineComplete);
  printEvaluationAgainstTruth(evaluation);
  writeTextFileAtomically(out / "evaluation.json", evaluation.dump(2) + "\n");
  report.save();
  printTargetRegistrationErrors(evaluation["transforms"], built.simulated.landmarks.size());
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
                             "--bias", "--contrast", "--tumour", "--tumour-depth", "--gap", "--cavity-rim", "--truth", "--field-of-view"}) {
      if (command->count(name) > 0) options->given.insert(name);
    }
    runDemo(*options);
  });
}

} // namespace brainshift::cli
