#pragma once
// The small built-in case in a scene, as the host holds it, and a quick rigid schedule.
#include "BrainShiftCaseSimulator.h"
#include "RigidRegistrationLogic.h"
#include "Scene.h"

namespace brainshift::testing {

struct CaseInScene {
  SimulatedCase simulated;
  std::shared_ptr<ScalarVolumeNode> intraop, preop;
  std::shared_ptr<LabelMapVolumeNode> preopLabels;
};

inline CaseInScene addSmallCase(Scene& scene)
{
  CaseParameters parameters;
  parameters.size = CaseSize::Small;
  CaseInScene c{simulateCase(parameters), {}, {}, {}};
  c.preop = scene.add(ScalarVolumeNode::create("preop image", c.simulated.preopImage));
  c.preop->setRole("preop");
  c.preopLabels = scene.add(LabelMapVolumeNode::create("preop labels", c.simulated.preopLabels));
  c.preopLabels->setRole("preop");
  c.intraop = scene.add(ScalarVolumeNode::create("intraop image", c.simulated.intraopImage));
  c.intraop->setRole("intraop");
  return c;
}

/// Two levels, one start: a second or two on the small case, still within a millimetre there.
inline RigidRegistrationParameters quickRigidParameters()
{
  RigidRegistrationParameters p;
  p.levelSpacingMm = {4.0, 2.5};
  p.samplesPerLevel = {6000, 12000};
  p.iterationsPerLevel = {100, 60};
  p.stepMmPerLevel = {3.0, 1.0};
  p.minimumStepMmPerLevel = {0.05, 0.02};
  p.startAnglesDegrees = {0.0};
  p.startsOptimized = 1;
  return p;
}

} // namespace brainshift::testing
