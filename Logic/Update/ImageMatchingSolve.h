#pragma once
// The simulate stage's image-driven second solve (ImageMatchingSolve.cxx).
#include "ImageMatchConstraints.h"
#include "UpdatePipeline.h"

#include <nlohmann/json.hpp>
#include <vtkUnstructuredGrid.h>

#include <functional>
#include <optional>
#include <string>

namespace brainshift {

/// Why block matching cannot run on this context (inputs not given, earlier stages' files absent),
/// or nullopt when it can.
std::optional<std::string> imageMatchingUnavailable(RunContext& context);

/// The stage's side of solveWithImageMatches (Logic/BiomechanicalSimulation/ImageMatchConstraints.h): reads
/// the rigid transform and the classification from the output folder, calls it, reports. Returns the final solution (the
/// surface-driven one when no block
/// matched); `entry` becomes report.json's simulate.block_matching. Writes block_matches.vtp. Adds
/// the kept matches to `evidence` (points) and every match with its misfit (misfit points).
FiniteElementResult runImageDrivenSolve(RunContext& context, vtkUnstructuredGrid* mesh, const FiniteElementJob& job,
                                        const FiniteElementResult& surfaceOnly, const ConstrainedSolve& solve, nlohmann::json& entry,
                                        DisplacementEvidence& evidence);

} // namespace brainshift
