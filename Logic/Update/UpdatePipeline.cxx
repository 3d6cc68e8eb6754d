#include "UpdatePipeline.h"

#include "PreparationAhead.h"

#include "BrainShiftErrors.h"
#include "LabelContract.h"
#include "OutputFolder.h"
#include "VolumeIO.h"

#include <algorithm>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iostream>

namespace brainshift {
namespace fs = std::filesystem;

Configuration configurationFor(const RunOptions& options)
{
  Configuration configuration = options.config.empty() ? Configuration{} : Configuration::load(options.config);
  if (options.meshResolutionMm) configuration.meshResolutionMm = *options.meshResolutionMm;
  if (options.meshBackend) configuration.meshBackend = *options.meshBackend;
  if (options.meshGrading) configuration.meshGrading = *options.meshGrading;
  if (!options.meshRegionOfInterest.empty()) {
    if (options.meshRegionOfInterest.size() != 4) throw InputError("--mesh-roi needs four numbers: X,Y,Z,R (LPS mm)");
    for (int d = 0; d < 3; ++d) configuration.meshRegionOfInterestCenterLps[std::size_t(d)] = options.meshRegionOfInterest[std::size_t(d)];
    configuration.meshRegionOfInterestRadiusMm = options.meshRegionOfInterest[3];
    if (!(configuration.meshRegionOfInterestRadiusMm > 0)) throw InputError("--mesh-roi: the radius must be positive");
  }
  if (options.solverOptions) configuration.solverOptions = *options.solverOptions;
  if (options.ranks) configuration.ranks = *options.ranks;
  if (options.tumourResected) configuration.classificationTumourResected = *options.tumourResected;
  configuration.validate(options.config.empty() ? "command line" : "command line and " + options.config.string());
  return configuration;
}

RunContext::RunContext(RunOptions options, Configuration configuration, RunReport& report)
  : options_(std::move(options))
  , configuration_(std::move(configuration))
  , report_(report)
{
}

void RunContext::say(const char* format, ...)
{
  char line[1024];
  va_list arguments;
  va_start(arguments, format);
  std::vsnprintf(line, sizeof line, format, arguments);
  va_end(arguments);
  std::string text = line;
  while (!text.empty() && text.back() == '\n') text.pop_back();
  if (!progress_) {
    std::cout << "  " << text << "\n" << std::flush;
    return;
  }
  UpdateProgress step = current_;
  step.message = text;
  progress_(step);
}

void RunContext::stageStarts(const std::string& stage, std::size_t index, std::size_t count)
{
  current_ = {stage, index, count, ""};
  if (progress_) {
    progress_(current_);
  } else {
    std::cout << "[" << stage << "]\n" << std::flush;
  }
}

const std::vector<LoadedOverlay>& RunContext::overlays()
{
  if (!overlays_) {
    if (inputs_) {
      overlays_ = inputs_->overlays;
    } else {
      std::vector<LoadedOverlay> loaded;
      for (const std::string& overlay : options_.overlays) {
        const OverlayInput input = parseOverlayArgument(overlay);
        Warnings warnings;
        loaded.push_back({input.name, readScalarVolume(input.file, &warnings)});
        report_.addWarnings(warnings);
      }
      overlays_ = std::move(loaded);
    }
  }
  return *overlays_;
}

void RunContext::loadPreoperativeInputs()
{
  if (session_ && session_->preoperative) {
    inputs_ = *session_->preoperative;
  } else {
    RegistrationInputPaths paths{options_.preopImage, options_.preopLabels, {}, {}};
    for (const std::string& overlay : options_.overlays) paths.overlays.push_back(parseOverlayArgument(overlay));
    inputs_ = loadRegistrationInputs(paths);
    requireKnownLabels(*inputs_->preopLabels, options_.preopLabels, configuration_);
    report_.addWarnings(inputs_->warnings);
    if (session_) session_->preoperative = *inputs_;
  }
  preopImage_ = inputs_->preopImage;
  preopLabels_ = inputs_->preopLabels;
}

void RunContext::loadAllInputs()
{
  if (session_ && session_->preoperative) { // a later scan of the session: only the new image is read
    inputs_ = *session_->preoperative;
    inputs_->warnings.clear();
    inputs_->intraopImage = readIntensityImage(options_.intraopImage, &inputs_->warnings);
    preopImage_ = inputs_->preopImage;
    preopLabels_ = inputs_->preopLabels;
    intraopImage_ = inputs_->intraopImage;
    report_.addWarnings(inputs_->warnings);
    return;
  }
  RegistrationInputPaths paths{options_.preopImage, options_.preopLabels, options_.intraopImage, {}};
  for (const std::string& overlay : options_.overlays) paths.overlays.push_back(parseOverlayArgument(overlay));
  inputs_ = loadRegistrationInputs(paths);
  requireKnownLabels(*inputs_->preopLabels, options_.preopLabels, configuration_);
  preopImage_ = inputs_->preopImage;
  preopLabels_ = inputs_->preopLabels;
  intraopImage_ = inputs_->intraopImage;
  report_.addWarnings(inputs_->warnings);
  if (session_) {
    session_->preoperative = *inputs_;
    session_->preoperative->intraopImage = nullptr;
  }
}

namespace {
/// 64-bit FNV-1a of bytes, continued from `hash`.
std::uint64_t fnv1a(const void* data, std::size_t size, std::uint64_t hash)
{
  const auto* bytes = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) {
    hash ^= bytes[i];
    hash *= 1099511628211ull;
  }
  return hash;
}

/// Of an image's voxels and geometry: the same data in another file or format is the same.
template <typename Image>
std::string fingerprintOf(const Image& image)
{
  std::uint64_t hash = 14695981039346656037ull;
  const auto size = image.GetLargestPossibleRegion().GetSize();
  for (unsigned d = 0; d < 3; ++d) {
    const double geometry[3] = {double(size[d]), image.GetSpacing()[d], image.GetOrigin()[d]};
    hash = fnv1a(geometry, sizeof geometry, hash);
    for (unsigned e = 0; e < 3; ++e) {
      const double direction = image.GetDirection()[d][e];
      hash = fnv1a(&direction, sizeof direction, hash);
    }
  }
  hash = fnv1a(image.GetBufferPointer(), image.GetLargestPossibleRegion().GetNumberOfPixels() * sizeof(*image.GetBufferPointer()), hash);
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(hash));
  return text;
}

nlohmann::json readReportOf(const fs::path& folder)
{
  const fs::path file = folder / "report.json";
  std::ifstream in(file);
  if (!in) return nlohmann::json();
  try {
    return nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    throw InputError(file.string() + ": not a BrainShift report (" + e.what() + ")");
  }
}

/// Whether two fingerprints are of the same preoperative data.
bool sameCase(const nlohmann::json& a, const nlohmann::json& b)
{
  if (!a.is_object() || !b.is_object()) return false;
  for (const char* key : {"preop_image", "preop_labels"}) {
    if (!a.contains(key) || !b.contains(key) || !a[key].is_object() || !b[key].is_object()) return false;
    const auto fingerprint = [&](const nlohmann::json& entry) {
      return entry.contains("fingerprint") && entry["fingerprint"].is_string() ? entry["fingerprint"].get<std::string>() : std::string();
    };
    if (fingerprint(a[key]).empty() || fingerprint(a[key]) != fingerprint(b[key])) return false;
  }
  return true;
}

/// Whether `recorded` (a report's "case_inputs") is of another case than `given`: a preoperative
/// input that both name with different data. An input only one of them names (a stage run with the
/// labels alone) does not tell.
bool anotherCase(const nlohmann::json& recorded, const nlohmann::json& given)
{
  if (!recorded.is_object()) return true;
  for (const char* key : {"preop_image", "preop_labels"}) {
    if (!recorded.contains(key) || !given.contains(key)) continue;
    const nlohmann::json &a = recorded[key], &b = given[key];
    if (!a.is_object() || !a.contains("fingerprint") || a["fingerprint"] != b["fingerprint"]) return true;
  }
  return false;
}

/// Refuses (InputError) a report of another case unless --overwrite, which starts it afresh.
void refuseAnotherCase(RunContext& context, const nlohmann::json& given)
{
  const nlohmann::json& existing = context.report().document();
  if (!existing.contains("case_inputs") || !anotherCase(existing["case_inputs"], given)) return;
  if (!context.options().overwrite) {
    throw InputError(context.options().outputDir.string() +
                     ": holds the results of another case (its preoperative image or labels differ); choose another "
                     "--output-dir, or pass --overwrite to replace them");
  }
  context.report().clear();
}
} // namespace

namespace {
nlohmann::json fingerprintEntry(const fs::path& path, const std::string& fingerprint)
{
  return nlohmann::json{{"path", fs::absolute(path).lexically_normal().string()}, {"fingerprint", fingerprint}};
}
} // namespace

nlohmann::json preoperativeFingerprint(RunContext& context)
{
  SerialScanSession* session = context.session();
  if (session && session->preoperativeFingerprint.is_object()) return session->preoperativeFingerprint;
  const RunOptions& options = context.options();
  nlohmann::json fingerprint = {{"preop_image", fingerprintEntry(options.preopImage, fingerprintOf(context.preopImage("register")))},
                                {"preop_labels", fingerprintEntry(options.preopLabels, fingerprintOf(context.preopLabels("register")))}};
  if (session && session->preoperative) session->preoperativeFingerprint = fingerprint;
  return fingerprint;
}

nlohmann::json caseFingerprint(RunContext& context)
{
  nlohmann::json fingerprint = preoperativeFingerprint(context);
  fingerprint["intraop_image"] = fingerprintEntry(context.options().intraopImage, fingerprintOf(context.intraopImage("register")));
  return fingerprint;
}

void claimCaseForStage(RunContext& context, const std::string& stage)
{
  const RunOptions& options = context.options();
  auto entry = [](const fs::path& path, const std::string& fingerprint) {
    return nlohmann::json{{"path", fs::absolute(path).lexically_normal().string()}, {"fingerprint", fingerprint}};
  };
  nlohmann::json given = nlohmann::json::object();
  if (!options.preopImage.empty()) given["preop_image"] = entry(options.preopImage, fingerprintOf(context.preopImage(stage)));
  if (!options.preopLabels.empty()) given["preop_labels"] = entry(options.preopLabels, fingerprintOf(context.preopLabels(stage)));
  if (!options.intraopImage.empty()) {
    given["intraop_image"] = entry(options.intraopImage, fingerprintOf(context.intraopImage(stage)));
  }
  if (given.empty()) return; // nothing names the case (simulate works on the folder's own files)
  refuseAnotherCase(context, given);
  const nlohmann::json& existing = context.report().document();
  nlohmann::json recorded = existing.contains("case_inputs") ? existing["case_inputs"] : nlohmann::json::object();
  for (const auto& [key, value] : given.items()) recorded[key] = value;
  context.report().set("case_inputs", recorded);
}

void RunContext::usePreviousScan(const nlohmann::json& fingerprint)
{
  const fs::path& folder = options_.previous;
  if (folder.empty()) return;
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder.string() + ": --previous is not a folder");
  previousReport_ = readReportOf(folder);
  if (!previousReport_.is_object() || !previousReport_.contains("case_inputs")) {
    throw InputError(folder.string() + ": --previous holds no report.json of an earlier `brainshift register`");
  }
  if (!sameCase(previousReport_["case_inputs"], fingerprint)) {
    throw InputError(folder.string() + ": --previous is another case's output (its preoperative image or labels differ from "
                     "--preop-image and --preop-labels)");
  }
}

std::optional<fs::path> RunContext::previousFile(const std::string& fileName) const
{
  if (options_.previous.empty()) return std::nullopt;
  const fs::path file = options_.previous / fileName;
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return std::nullopt;
  return file;
}

namespace {
ScalarImage::Pointer readRequired(const fs::path& path, const char* flag, const std::string& stage, RunReport& report)
{
  if (path.empty()) throw InputError("stage '" + stage + "' needs " + flag);
  Warnings warnings;
  ScalarImage::Pointer image = readIntensityImage(path, &warnings);
  report.addWarnings(warnings);
  return image;
}
} // namespace

const ScalarImage& RunContext::preopImage(const std::string& stage)
{
  if (!preopImage_) preopImage_ = readRequired(options_.preopImage, "--preop-image", stage, report_);
  return *preopImage_;
}

const ScalarImage& RunContext::intraopImage(const std::string& stage)
{
  if (!intraopImage_) intraopImage_ = readRequired(options_.intraopImage, "--intraop-image", stage, report_);
  return *intraopImage_;
}

const LabelImage* RunContext::preopLabelsIfGiven()
{
  if (!preopLabels_ && !options_.preopLabels.empty()) {
    Warnings warnings;
    preopLabels_ = readLabelVolume(options_.preopLabels, &warnings);
    requireKnownLabels(*preopLabels_, options_.preopLabels, configuration_);
    report_.addWarnings(warnings);
  }
  return preopLabels_.GetPointer();
}

const LabelImage& RunContext::preopLabels(const std::string& stage)
{
  if (options_.preopLabels.empty()) throw InputError("stage '" + stage + "' needs --preop-labels");
  return *preopLabelsIfGiven();
}

const std::vector<PipelineStage>& pipelineStages()
{
  static const std::vector<PipelineStage> stages = {
    {"rigid", "rigid registration of the intraoperative to the preoperative MRI by mutual information "
              "(writes rigid_intraop_to_preop.tfm)", runRigidStage},
    {"classify", "intraoperative tissue classification, k-NN with spatial context (writes intraop_labels.nii.gz)",
     runClassifyStage},
    {"mesh", "tetrahedral mesh of the preoperative label map (writes mesh.vtu)", runMeshStage},
    {"surface", "active surface carrying the preoperative brain surface onto the intraoperative brain "
                "(writes brain_surface.vtp)", runSurfaceStage},
    {"simulate", "linear elastic finite element solve in a PETSc/MPI worker (adds Displacement to mesh.vtu)",
     runSimulateStage},
    {"refine", "the classification follows the brain: the tumour decided by the image is looked at again where the solve put it "
               "(decided otherwise there: classify, surface and simulate run once more), then the preoperative labels warped by the solve become the "
               "spatial prior and classify, surface and simulate run again until the brain boundary settles (rewrites their files)",
     runRefineStage},
    {"warp", "dense deformation and warped preoperative volumes (writes intraop_to_preop.h5, "
             "displacement_intraop_to_preop.nrrd, warped_*.nii.gz, scene.mrml)", runWarpStage},
  };
  return stages;
}

void runRegistration(RunContext& context)
{
  claimOutputFolder(context.options().outputDir); // one writer per folder; a no-op when the command did
  context.loadAllInputs();
  const nlohmann::json fingerprint = caseFingerprint(context);
  refuseAnotherCase(context, fingerprint);
  context.usePreviousScan(fingerprint);
  context.report().set("case_inputs", fingerprint);
  if (!context.options().previous.empty()) {
    context.report().set(context.options().previousIsPreparation ? "prepared_case" : "previous_scan",
                         fs::absolute(context.options().previous).lexically_normal().string());
  }
  try {
    runPipeline(context);
  } catch (const MethodError& e) {
    context.report().addWarning(e.what());
    context.report().save();
    throw;
  }
}

RegistrationEnd runRegistrationForEvaluation(RunContext& context)
{
  RegistrationEnd end;
  try {
    runRegistration(context);
    end.pipelineComplete = true;
  } catch (const NotAvailableError& e) {
    end.notAvailable = e;
  } catch (const MethodError& e) {
    if (nonrigidUpdateTrustIn(context.report().document()) != "rejected") throw;
    end.rejected = e;
  }
  return end;
}

std::string nonrigidUpdateTrustIn(const nlohmann::json& report)
{
  if (report.contains("trust") && report["trust"].contains("nonrigid") && report["trust"]["nonrigid"].is_string()) {
    return report["trust"]["nonrigid"].get<std::string>();
  }
  return "not assessed";
}

void runPipeline(RunContext& context)
{
  Stopwatch clock;
  context.setWholePipeline(true);
  // The mesh and the preoperative boundary, made on the core the rigid registration leaves idle;
  // abandoned (and its thread joined) when the pipeline ends, however it ends.
  context.setPreparationAhead(PreparationAhead::startFor(context));
  struct Release {
    RunContext& context;
    ~Release() { context.setPreparationAhead(nullptr); }
  } release{context};
  for (const PipelineStage& stage : pipelineStages()) {
    if (!stage.run) {
      throw NotAvailableError("stage '" + stage.name + "' (" + stage.summary.substr(0, stage.summary.find(" (")) +
                              ") is not available yet in this build");
    }
    throwIfCancelled(context.cancelFlag(), "the update");
    context.stageStarts(stage.name, std::size_t(&stage - pipelineStages().data()), pipelineStages().size());
    stage.run(context);
    // The stages' own figures count a repeated stage once, in its last pass: this is every pass,
    // from the first stage's start to the last one's end (the inputs read before it).
    context.report().set("pipeline_wall_seconds", clock.seconds());
    context.report().save();
  }
}

} // namespace brainshift
