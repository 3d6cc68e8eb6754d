#pragma once
// What `register`, its stages and `demo` share: the flags, the configuration with the flags over
// it, and the pipeline of stages in order.
#include "Commands.h"
#include "Configuration.h"
#include "RegistrationInputs.h"
#include "RunReport.h"

#include <functional>

namespace brainshift::cli {

enum class InputFlag { PreopImage = 1, PreopLabels = 2, IntraopImage = 4, Overlays = 8 };

/// Declares the flags of RunOptions on `command`; `required` inputs are marked required.
void addRunOptions(CLI::App* command, RunOptions& options, unsigned requiredInputs, unsigned offeredInputs,
                   bool solverFlags, bool meshFlags);

/// The configuration file (or the defaults) with the command-line flags over it, validated.
Configuration configurationFor(const RunOptions& options);

/// A stage of the intraoperative update, as the command line runs it.
struct PipelineStage {
  std::string name;    ///< the subcommand
  std::string summary; ///< one line for --help
  /// Runs the stage on the case in `options.outputDir`; empty while the stage is not built.
  std::function<void(const RunOptions&, const Configuration&, RunReport&)> run;
};

/// The stages in the order `register` runs them.
const std::vector<PipelineStage>& pipelineStages();

/// Runs the stages in order, saving the report after each. Stops at the first stage that is not
/// built with NotAvailableError; a failing stage stops the pipeline with its reason.
void runPipeline(const RunOptions& options, const Configuration& configuration, RunReport& report);

} // namespace brainshift::cli
