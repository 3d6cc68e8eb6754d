#pragma once
// The flags `register`, `watch`, `demo` and the stage subcommands share, declared on CLI11; what
// they fill (RunOptions) and what runs them (the update pipeline) are the logic's
// (Logic/Update/UpdatePipeline.h).
#include "Commands.h"
#include "UpdatePipeline.h"

namespace brainshift::cli {

enum class InputFlag { PreopImage = 1, PreopLabels = 2, IntraopImage = 4, Overlays = 8 };

/// Declares the flags of RunOptions on `command`; `required` inputs are marked required.
void addRunOptions(CLI::App* command, RunOptions& options, unsigned requiredInputs, unsigned offeredInputs,
                   bool solverFlags, bool meshFlags, bool classificationFlags = false);

} // namespace brainshift::cli
