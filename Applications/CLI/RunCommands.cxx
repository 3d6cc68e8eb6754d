#include "RunCommands.h"

#include "BrainShiftErrors.h"
#include "VolumeIO.h"

#include <iostream>

namespace brainshift::cli {
namespace fs = std::filesystem;

void addRunOptions(CLI::App* command, RunOptions& options, unsigned requiredInputs, unsigned offeredInputs,
                   bool solverFlags, bool meshFlags, bool classificationFlags)
{
  auto input = [&](InputFlag flag, const char* name, fs::path& target, const char* help) {
    if (!(offeredInputs & unsigned(flag))) return;
    CLI::Option* option = command->add_option(name, target, help);
    if (requiredInputs & unsigned(flag)) option->required();
  };
  input(InputFlag::PreopImage, "--preop-image", options.preopImage, "preoperative MRI (NIfTI, NRRD, MetaImage or a DICOM folder)");
  input(InputFlag::PreopLabels, "--preop-labels", options.preopLabels,
        "preoperative label map on the preoperative image's grid (0 background, 1 head, 2 parenchyma, 3 ventricles, 4 tumour)");
  input(InputFlag::IntraopImage, "--intraop-image", options.intraopImage, "intraoperative MRI");
  if (offeredInputs & unsigned(InputFlag::Overlays)) {
    command->add_option("--overlay", options.overlays,
                        "NAME=FILE: another preoperative volume (fMRI statistics, MRA) to warp; repeatable");
  }
  command->add_option("--output-dir", options.outputDir, "the case's output folder")->required();
  command->add_option("--config", options.config, "JSON configuration (materials, mesh, solver); flags override it");
  if (classificationFlags) {
    command->add_option("--prototypes", options.prototypes,
                        "classification prototypes: a previous scan's classification_prototypes.json, or a .mrk.json of "
                        "points named by tissue (parenchyma-1, ventricles-2, ...); default: chosen automatically");
  }
  if (meshFlags) {
    command->add_option("--mesh-resolution", options.meshResolutionMm, "target tetrahedron edge length in mm (default 4)");
    command->add_option("--mesh-backend", options.meshBackend,
                        "lattice (Kuhn lattice, boundary nodes snapped; default) or cgal (CGAL Mesh_3)");
  }
  if (solverFlags) {
    command->add_option("--ranks", options.ranks, "MPI ranks of the finite element worker (default 1)");
    command->add_option("--solver-options", options.solverOptions,
                        "PETSc options over the tuned default, e.g. \"-ksp_type gmres -pc_type bjacobi\"");
  }
}

Configuration configurationFor(const RunOptions& options)
{
  Configuration configuration = options.config.empty() ? Configuration{} : Configuration::load(options.config);
  if (options.meshResolutionMm) configuration.meshResolutionMm = *options.meshResolutionMm;
  if (options.meshBackend) configuration.meshBackend = *options.meshBackend;
  if (options.solverOptions) configuration.solverOptions = *options.solverOptions;
  if (options.ranks) configuration.ranks = *options.ranks;
  configuration.validate(options.config.empty() ? "command line" : "command line and " + options.config.string());
  return configuration;
}

RunContext::RunContext(RunOptions options, Configuration configuration, RunReport& report)
  : options_(std::move(options))
  , configuration_(std::move(configuration))
  , report_(report)
{
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

void RunContext::loadAllInputs()
{
  RegistrationInputPaths paths{options_.preopImage, options_.preopLabels, options_.intraopImage, {}};
  for (const std::string& overlay : options_.overlays) paths.overlays.push_back(parseOverlayArgument(overlay));
  inputs_ = loadRegistrationInputs(paths);
  preopImage_ = inputs_->preopImage;
  preopLabels_ = inputs_->preopLabels;
  intraopImage_ = inputs_->intraopImage;
  report_.addWarnings(inputs_->warnings);
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
    {"warp", "dense deformation and warped preoperative volumes (writes intraop_to_preop.h5, "
             "displacement_intraop_to_preop.nrrd, warped_*.nii.gz, scene.mrml)", runWarpStage},
  };
  return stages;
}

void runPipeline(RunContext& context)
{
  for (const PipelineStage& stage : pipelineStages()) {
    if (!stage.run) {
      throw NotAvailableError("stage '" + stage.name + "' (" + stage.summary.substr(0, stage.summary.find(" (")) +
                              ") is not available yet in this build");
    }
    std::cout << "[" << stage.name << "]\n" << std::flush;
    stage.run(context);
    context.report().save();
  }
}

} // namespace brainshift::cli
