// The stages as the command line runs them: inputs from the run context, the stage's logic, its
// files in the output folder, its entry in report.json.
#include "BrainShiftErrors.h"
#include "RigidRegistrationLogic.h"
#include "RunCommands.h"
#include "TransformIO.h"

#include <cstdio>
#include <numeric>

namespace brainshift::cli {

void runRigidStage(RunContext& context)
{
  Stopwatch clock;
  RigidRegistrationParameters parameters;
  const RigidRegistrationResult result = registerRigidly(context.intraopImage("rigid"), context.preopImage("rigid"),
                                                         context.preopLabelsIfGiven(), parameters);
  const double seconds = clock.seconds();
  nlohmann::json entry = {{"wall_seconds", seconds},
                          {"metric_value", result.metricValue},
                          {"iterations", std::accumulate(result.iterationsPerLevel.begin(), result.iterationsPerLevel.end(), 0u)},
                          {"iterations_per_level", result.iterationsPerLevel},
                          {"normalized_mutual_information", result.normalizedMutualInformation},
                          {"overlap", result.overlap},
                          {"rotation_degrees", result.rotationDegrees},
                          {"translation_mm", result.translationMm},
                          {"starts_scored", result.startsScored},
                          {"winning_start_degrees", result.winningStartDegrees},
                          {"trustworthy", result.trustworthy}};
  if (!result.trustworthy) entry["failure"] = result.failureReason;
  context.report().setStage("rigid", entry);
  context.report().addWarnings(result.warnings);
  if (!result.trustworthy) {
    context.report().save();
    throw MethodError("rigid registration cannot be trusted: " + result.failureReason +
                      "; rigid_intraop_to_preop.tfm not written");
  }
  writeTransform(result.intraopToPreop, context.output("rigid_intraop_to_preop.tfm"));
  std::printf("  rigid: rotation %.2f degrees, translation %.2f mm, NMI %.3f, overlap %.2f, %.2f s\n",
              result.rotationDegrees, result.translationMm, result.normalizedMutualInformation, result.overlap, seconds);
}

} // namespace brainshift::cli
