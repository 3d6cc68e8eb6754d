#pragma once
// An estimate of the error of the solved displacement, per mesh node (mm): the confidence map of
// the update. A model is wrong by a share of how far it moves the tissue; where the evidence
// disagrees with the solution (the misfit of the matches around a node, kept or rejected) it is
// known worse by that disagreement; and it may be known less well the farther a node lies from any
// evidence (the imposed surface nodes, the kept matches), a term off by default:
//
//   sigma(n)^2 = floor^2 + (growth * distance to the nearest evidence)^2
//                + (local root mean square misfit of the matches within reach)^2
//                + (share * |u(n)|)^2
//
// The weights are a model, not a measurement: chosen on, and validated against the true error of,
// the built-in scenarios (Logic/Evaluation/UncertaintyEvaluation, demo's evaluation.json; README,
// "The confidence map"). The distance term ranked the deep brain, which hardly moves, as uncertain.
#include <array>
#include <cstdint>
#include <vector>

namespace brainshift {

struct DisplacementUncertaintyModel {
  double floorMm = 0.3;            ///< the error where the evidence is exact
  /// Added per mm of distance from the nearest evidence. Off: it ranked the deep brain, which hardly
  /// moves, as uncertain (README, "The confidence map": 0.06 before).
  double growthPerMm = 0.0;
  double misfitReachMm = 8.0;      ///< matches within this distance count in a node's misfit (Gaussian, sigma reach / 2)
  double displacementShare = 0.25; ///< of the node's own displacement (0.15 before)
};

struct DisplacementEvidence {
  std::vector<std::array<double, 3>> points;  ///< preoperative frame: imposed nodes and kept matches
  std::vector<std::array<double, 3>> misfitPoints; ///< the matches, kept and rejected
  std::vector<double> misfitsMm;              ///< their misfit under the solution
};

/// One value per node (`nodes`, `displacements`: x, y, z per node, preoperative frame, mm).
std::vector<double> nodalDisplacementUncertainty(const std::vector<double>& nodes, const std::vector<double>& displacements,
                                                 const DisplacementEvidence& evidence, const DisplacementUncertaintyModel& model = {});

struct Configuration;
/// The model of the configuration's "uncertainty" section (its defaults are those above).
DisplacementUncertaintyModel displacementUncertaintyModelFrom(const Configuration& configuration);

} // namespace brainshift
