// On the small built-in case: the rigid part of the truth is recovered (head landmarks, rotation),
// the same inputs give the same transform, and a known start (a later scan) converges to it.
#include "BrainShiftTestingSupport.h"
#include "RigidRegistrationTestSupport.h"

#include <iostream>

int RigidRegistrationAccuracyTest(int, char*[])
{
  return brainshift::testing::runTest("RigidRegistrationAccuracyTest", [] {
    using namespace brainshift;
    const SimulatedCase c = testing::smallCaseWithMotion({4.0, -3.0, 6.0}, {6.0, -8.0, 5.0});
    const RigidRegistrationParameters parameters;
    const RigidRegistrationResult result = registerRigidly(*c.intraopImage, *c.preopImage, c.preopLabels, parameters);
    const ErrorStatistics head = testing::headError(*result.intraopToPreop, c);
    const double rotationError = rotationDifferenceDegrees(*result.intraopToPreop, *c.rigidIntraopToPreop);
    std::cout << "head TRE mean " << head.meanMm << " max " << head.maxMm << " mm, rotation error " << rotationError
              << " degrees, NMI " << result.normalizedMutualInformation << '\n';
    BS_CHECK_MSG(result.trustworthy, result.failureReason);
    BS_CHECK_MSG(result.warnings.empty(), result.warnings.front());
    BS_CHECK_MSG(head.maxMm < 0.6, head.maxMm);
    BS_CHECK_MSG(rotationError < 0.25, rotationError);
    BS_CHECK_NEAR(result.rotationDegrees, 7.7, 0.5); // the motion: 4, -3, 6 degrees about L, P, S
    BS_CHECK(result.startsScored == 125);
    BS_CHECK(result.iterationsPerLevel.size() == 3);
    BS_CHECK_MSG(result.overlap > 0.95, result.overlap);

    // Deterministic: seeded sampling, the metric's four work units summed in a fixed order (their
    // threads finish in any order), the same transform to the last bit, run after run.
    BS_CHECK_MSG(result.metricWorkUnits == 4, result.metricWorkUnits);
    for (int run = 0; run < 3; ++run) {
      const RigidRegistrationResult again = registerRigidly(*c.intraopImage, *c.preopImage, c.preopLabels, parameters);
      BS_CHECK(again.intraopToPreop->GetParameters() == result.intraopToPreop->GetParameters());
    }

    // A later scan starts from the previous result: no multi-start, the same answer.
    RigidRegistrationParameters serial = parameters;
    serial.initialIntraopToPreop = result.intraopToPreop;
    const RigidRegistrationResult later = registerRigidly(*c.intraopImage, *c.preopImage, c.preopLabels, serial);
    BS_CHECK(later.startsScored == 0);
    BS_CHECK_MSG(later.trustworthy, later.failureReason);
    BS_CHECK_MSG(testing::headError(*later.intraopToPreop, c).maxMm < 0.6, testing::headError(*later.intraopToPreop, c).maxMm);

    // Without the label mask the result is still close (the mask is an option, not a crutch).
    const RigidRegistrationResult unmasked = registerRigidly(*c.intraopImage, *c.preopImage, nullptr, parameters);
    BS_CHECK_MSG(testing::headError(*unmasked.intraopToPreop, c).maxMm < 1.0, testing::headError(*unmasked.intraopToPreop, c).maxMm);
  });
}
