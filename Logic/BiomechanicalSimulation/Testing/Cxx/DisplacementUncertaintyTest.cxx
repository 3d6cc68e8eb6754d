// The confidence of a solved displacement per node: the floor at the evidence, growing with the
// distance from it, raised by the misfit of the matches around a node and by the node's own
// displacement, each by the model's weights.
#include "BrainShiftTestingSupport.h"
#include "Configuration.h"
#include "DisplacementUncertainty.h"

#include <cmath>
#include <iostream>

int DisplacementUncertaintyTest(int, char*[])
{
  return brainshift::testing::runTest("DisplacementUncertaintyTest", [] {
    using namespace brainshift;
    DisplacementUncertaintyModel model; // floor 0.3, reach 8 mm; growth and share set here
    model.growthPerMm = 0.06;
    model.displacementShare = 0.15;
    // Nodes along x at 0, 10, 20, 40 mm; evidence at x = 0.
    const std::vector<double> nodes{0, 0, 0, 10, 0, 0, 20, 0, 0, 40, 0, 0};
    std::vector<double> still(nodes.size(), 0.0);
    DisplacementEvidence evidence;
    evidence.points = {{0, 0, 0}};
    std::vector<double> sigma = nodalDisplacementUncertainty(nodes, still, evidence, model);
    BS_CHECK_NEAR(sigma[0], 0.3, 1e-12);
    BS_CHECK_NEAR(sigma[1], std::hypot(0.3, 0.6), 1e-12);
    BS_CHECK_NEAR(sigma[3], std::hypot(0.3, 2.4), 1e-12);
    // A match with a 2 mm misfit on the node at 20 mm: that node's misfit term is 2 mm; the node
    // at 40 mm is beyond its reach.
    evidence.misfitPoints = {{20, 0, 0}};
    evidence.misfitsMm = {2.0};
    sigma = nodalDisplacementUncertainty(nodes, still, evidence, model);
    BS_CHECK_NEAR(sigma[2], std::sqrt(0.09 + 1.2 * 1.2 + 4.0), 1e-12);
    BS_CHECK_NEAR(sigma[3], std::hypot(0.3, 2.4), 1e-12);
    // A node moved 10 mm: 15 % of it.
    std::vector<double> moved = still;
    moved[0] = 6.0;
    moved[1] = 8.0;
    sigma = nodalDisplacementUncertainty(nodes, moved, evidence, model);
    BS_CHECK_NEAR(sigma[0], std::hypot(0.3, 1.5), 1e-12);
    std::cout << "sigma " << sigma[0] << ' ' << sigma[1] << ' ' << sigma[2] << ' ' << sigma[3] << '\n';
    // The configuration's "uncertainty" section: its defaults are the model's, and it sets each weight.
    const DisplacementUncertaintyModel fromDefaults = displacementUncertaintyModelFrom(Configuration{}), builtIn;
    BS_CHECK(fromDefaults.floorMm == builtIn.floorMm && fromDefaults.growthPerMm == builtIn.growthPerMm &&
             fromDefaults.misfitReachMm == builtIn.misfitReachMm && fromDefaults.displacementShare == builtIn.displacementShare);
    // The defaults: no growth with the distance, a quarter of the displacement.
    sigma = nodalDisplacementUncertainty(nodes, moved, evidence, fromDefaults);
    BS_CHECK_NEAR(sigma[0], std::hypot(0.3, 2.5), 1e-12);
    BS_CHECK_NEAR(sigma[3], 0.3, 1e-12); // 40 mm from the evidence, beyond the match's reach: the floor alone
    Configuration growing;
    growing.uncertainty.growthPerMm = 0.06;
    sigma = nodalDisplacementUncertainty(nodes, still, evidence, displacementUncertaintyModelFrom(growing));
    BS_CHECK_NEAR(sigma[3], std::hypot(0.3, 2.4), 1e-12);
    evidence.misfitsMm.clear();
    BS_CHECK_THROWS(nodalDisplacementUncertainty(nodes, still, evidence, model), std::invalid_argument, "one misfit per match");
    BS_CHECK_THROWS(nodalDisplacementUncertainty(nodes, std::vector<double>(3, 0.0), DisplacementEvidence{}, model),
                    std::invalid_argument, "one displacement per node");
  });
}
