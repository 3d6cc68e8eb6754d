#pragma once
// The subcommands of `brainshift` (../shared/CONTRACT.md). Each `add...Command` declares its flags
// on the CLI11 app and sets the callback that runs it. A callback reports bad input by throwing
// InputError (exit 2) and a failure of the method by MethodError (exit 1).
#include <CLI/CLI.hpp>


namespace brainshift::cli {

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
