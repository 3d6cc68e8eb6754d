#pragma once
// The subcommands of `brainshift` (../shared/CONTRACT.md). Each `add...Command` declares its flags
// on the CLI11 app and sets the callback that runs it. A callback reports bad input by throwing
// InputError (exit 2) and a failure of the method by MethodError (exit 1).
#include <CLI/CLI.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace brainshift::cli {

/// The flags `register` and its stages share.
struct RunOptions {
  std::filesystem::path preopImage, preopLabels, intraopImage, outputDir, config;
  std::vector<std::string> overlays;
  std::optional<int> ranks;
  std::optional<double> meshResolutionMm;
  std::optional<std::string> meshBackend;
  std::optional<double> meshGrading;
  std::vector<double> meshRegionOfInterest; ///< x, y, z (LPS mm), radius mm; empty: the configuration's
  std::optional<std::string> solverOptions;
  std::filesystem::path prototypes; ///< classification prototypes (recorded or picked); empty: automatic
  std::optional<std::string> tumourResected; ///< "yes", "no" or "auto" (the configuration's otherwise)
  /// An earlier scan's output folder of the same case (register --previous): its rigid transform
  /// starts the registration, its prototypes classify, its mesh and preoperative surface fit are reused.
  std::filesystem::path previous;
  bool overwrite = false; ///< register into a folder holding another case's results
};

void addEvaluateCommand(CLI::App& app);
void addDemoCommand(CLI::App& app);
void addRegisterCommand(CLI::App& app);
void addWatchCommand(CLI::App& app); ///< `watch`, WatchCommand.cxx
void addStageCommands(CLI::App& app);
void addBenchCommand(CLI::App& app);
void addSendCommand(CLI::App& app);        ///< `send`, SendCommand.cxx
void addExportDicomCommand(CLI::App& app); ///< `export-dicom`, ExportDicomCommand.cxx
void addMeshBenchCommand(CLI::App& bench); ///< `bench mesh`, MeshBenchCommand.cxx
void addSurfaceBenchCommand(CLI::App& bench); ///< `bench surface`, SurfaceBenchCommand.cxx
void addUpdateBenchCommand(CLI::App& bench);  ///< `bench update`, UpdateBenchCommand.cxx
void addSimulateBenchCommand(CLI::App& bench); ///< `bench simulate`, SimulateBenchCommand.cxx
void addFuzzBenchCommand(CLI::App& bench);     ///< `bench read-scene`, FuzzBenchCommand.cxx

} // namespace brainshift::cli
