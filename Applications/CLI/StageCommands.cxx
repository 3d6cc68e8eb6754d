#include "BrainShiftErrors.h"
#include "DicomSeriesExport.h"
#include "OutputFolder.h"
#include "RunCommands.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

#include <cstdio>
#include <memory>

namespace brainshift::cli {
namespace fs = std::filesystem;

namespace {
constexpr unsigned PreopImage = unsigned(InputFlag::PreopImage), PreopLabels = unsigned(InputFlag::PreopLabels),
                   IntraopImage = unsigned(InputFlag::IntraopImage), Overlays = unsigned(InputFlag::Overlays);

RegistrationInputPaths inputPathsOf(const RunOptions& options)
{
  RegistrationInputPaths paths{options.preopImage, options.preopLabels, options.intraopImage, {}};
  for (const std::string& overlay : options.overlays) paths.overlays.push_back(parseOverlayArgument(overlay));
  return paths;
}

/// Reads and checks the inputs a stage was given (all of them when the three images are given).
void checkGivenInputs(const RunOptions& options)
{
  if (!options.preopImage.empty() && !options.preopLabels.empty() && !options.intraopImage.empty()) {
    loadRegistrationInputs(inputPathsOf(options));
    return;
  }
  if (!options.preopImage.empty()) readScalarVolume(options.preopImage);
  if (!options.preopLabels.empty()) readLabelVolume(options.preopLabels);
  if (!options.intraopImage.empty()) readScalarVolume(options.intraopImage);
  for (const std::string& overlay : options.overlays) readScalarVolume(parseOverlayArgument(overlay).file);
}

/// Before any work: the output folder is writable and this run's alone, and no input is a file the run writes.
void claimFolderOf(const RunOptions& options)
{
  std::vector<fs::path> inputs{options.preopImage, options.preopLabels, options.intraopImage, options.config};
  for (const std::string& overlay : options.overlays) inputs.push_back(parseOverlayArgument(overlay).file);
  refuseInputsAmongOutputs(options.outputDir, inputs);
  claimOutputFolder(options.outputDir);
}

struct StageFlags {
  unsigned required, offered;
  bool solver, mesh;
};

StageFlags flagsOf(const std::string& stage)
{
  if (stage == "rigid") return {PreopImage | IntraopImage, PreopImage | IntraopImage | PreopLabels, false, false};
  if (stage == "classify") return {PreopLabels | IntraopImage, PreopImage | PreopLabels | IntraopImage, false, false};
  if (stage == "mesh") return {PreopLabels, PreopLabels, false, true};
  if (stage == "surface") return {PreopLabels | IntraopImage, PreopLabels | IntraopImage, false, false};
  if (stage == "simulate") return {0, PreopImage | PreopLabels | IntraopImage, true, false}; // the images for block matching
  if (stage == "refine") return {PreopLabels | IntraopImage, PreopImage | PreopLabels | IntraopImage, true, false};
  return {PreopImage | PreopLabels | IntraopImage, PreopImage | PreopLabels | IntraopImage | Overlays, false, false};
}
} // namespace

void addRegisterCommand(CLI::App& app)
{
  auto options = std::make_shared<RunOptions>();
  CLI::App* command = app.add_subcommand("register", "The whole intraoperative update: every stage, in order");
  addRunOptions(command, *options, PreopImage | PreopLabels | IntraopImage, PreopImage | PreopLabels | IntraopImage | Overlays,
                true, true, true);
  command->add_option("--previous", options->previous,
                      "the output folder of an earlier scan of the same case: its rigid transform starts the registration, "
                      "its classification prototypes, mesh and preoperative surface fit are reused");
  command->add_flag("--overwrite", options->overwrite, "replace another case's results in --output-dir");
  auto exportDicom = std::make_shared<fs::path>();
  command->add_option("--export-dicom", *exportDicom,
                      "after the update, its series as `export-dicom --to DIR` writes them (the scan's study and Frame "
                      "of Reference when it was a DICOM series)");
  command->callback([options, exportDicom] {
    const Configuration configuration = configurationFor(*options);
    std::error_code ec;
    if (!exportDicom->empty() && fs::exists(*exportDicom, ec) && !fs::is_directory(*exportDicom, ec)) {
      throw InputError(exportDicom->string() + ": --export-dicom is not a folder");
    }
    claimFolderOf(*options);
    RunReport report(options->outputDir / "report.json");
    RunContext context(*options, configuration, report);
    runRegistration(context);
    if (exportDicom->empty()) return;
    const DicomExportResult result = exportUpdateToDicom(inspectUpdateFolder(options->outputDir), *exportDicom, std::nullopt);
    std::printf("== DICOM: %zu series, %d files in %s\n", result.seriesFolders.size(), result.files,
                exportDicom->string().c_str());
  });
}

void addStageCommands(CLI::App& app)
{
  for (const PipelineStage& stage : pipelineStages()) {
    auto options = std::make_shared<RunOptions>();
    CLI::App* command = app.add_subcommand(stage.name, "Stage alone: " + stage.summary);
    const StageFlags flags = flagsOf(stage.name);
    addRunOptions(command, *options, flags.required, flags.offered, flags.solver, flags.mesh,
                  stage.name == "classify" || stage.name == "refine");
    command->add_flag("--overwrite", options->overwrite, "replace another case's results in --output-dir");
    command->callback([options, stage] {
      const Configuration configuration = configurationFor(*options);
      claimFolderOf(*options);
      checkGivenInputs(*options);
      if (!stage.run) {
        throw NotAvailableError("stage '" + stage.name + "' is not available yet in this build");
      }
      RunReport report(options->outputDir / "report.json");
      RunContext context(*options, configuration, report);
      claimCaseForStage(context, stage.name);
      stage.run(context);
      report.save();
    });
  }
}


} // namespace brainshift::cli
