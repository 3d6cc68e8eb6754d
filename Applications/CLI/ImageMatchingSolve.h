#pragma once
// The simulate stage's image-driven second solve (ImageMatchingSolve.cxx).
#include "DisplacementUncertainty.h"
#include "RunCommands.h"

#include <nlohmann/json.hpp>
#include <vtkUnstructuredGrid.h>

#include <functional>
#include <optional>
#include <string>

namespace brainshift::cli {

/// Why block matching cannot run on this context (inputs not given, earlier stages' files absent),
/// or nullopt when it can.
std::optional<std::string> imageMatchingUnavailable(RunContext& context);

/// Solves a job (with soft constraints) as the stage solves: one-shot or in the session's worker.
using ConstrainedSolve = std::function<FiniteElementResult(const FiniteElementJob&)>;

/// Blocks matched from the surface-driven solution `surfaceOnly`, then `job` solved again with the
/// matches as soft constraints. Returns the final solution (the surface-driven one when no block
/// matched); `entry` becomes report.json's simulate.block_matching. Writes block_matches.vtp. Adds
/// the kept matches to `evidence` (points) and every match with its misfit (misfit points).
FiniteElementResult solveWithImageMatches(RunContext& context, vtkUnstructuredGrid* mesh, const FiniteElementJob& job,
                                          const FiniteElementResult& surfaceOnly, const ConstrainedSolve& solve, nlohmann::json& entry,
                                          DisplacementEvidence& evidence);

} // namespace brainshift::cli
