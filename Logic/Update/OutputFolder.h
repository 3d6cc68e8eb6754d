#pragma once
// One folder, one writer: what every subcommand that writes into --output-dir does before any work
// (../shared/CONTRACT.md: a second run into a folder is refused, exit 2).
#include <filesystem>
#include <vector>

namespace brainshift {

/// Creates `folder` if needed and claims it for this process: InputError (exit 2) naming the folder
/// when it cannot be created, is not writable, or another brainshift run holds it (an advisory
/// flock on the folder itself, released when the process ends, however it ends). Removes
/// the stale temporary files of runs that died there. Claiming a folder twice in one process is
/// allowed (a pipeline inside a subcommand).
void claimOutputFolder(const std::filesystem::path& folder);

/// InputError when the file `output` (given by `outputFlag`) is one of `inputs`: an output never
/// replaces an input.
void refuseOutputOverInputs(const std::filesystem::path& output, const std::vector<std::filesystem::path>& inputs,
                            const char* outputFlag);

/// InputError when one of `inputs` lies in the output folder under a name a stage writes
/// (warped_*.nii.gz, mesh.vtu, report.json, ...): the run would replace its own input.
void refuseInputsAmongOutputs(const std::filesystem::path& outputFolder, const std::vector<std::filesystem::path>& inputs);

} // namespace brainshift
