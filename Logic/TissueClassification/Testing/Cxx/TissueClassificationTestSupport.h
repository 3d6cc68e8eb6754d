#pragma once
#include "BrainShiftCaseSimulator.h"
#include "LabelOverlap.h"
#include "RigidRegistrationLogic.h"
#include "TissueClassificationLogic.h"

#include <iostream>

namespace brainshift::testing {

struct ClassifiedCase {
  SimulatedCase simulated;
  SpatialTransform::Pointer rigid;
};

/// The small built-in case, registered rigidly.
inline ClassifiedCase registeredSmallCase(bool resection = true, double noise = 0.03, std::uint64_t seed = 2000)
{
  CaseParameters parameters;
  parameters.size = CaseSize::Small;
  parameters.resection = resection;
  parameters.noiseFraction = noise;
  parameters.seed = seed;
  ClassifiedCase c{simulateCase(parameters), nullptr};
  c.rigid = registerRigidly(*c.simulated.intraopImage, *c.simulated.preopImage, c.simulated.preopLabels, {}).intraopToPreop;
  return c;
}

struct Scores {
  double brain, ventricles, tumour, surfaceMm;
};

inline Scores scoresOf(const LabelImage& labels, const SimulatedCase& c, const char* what)
{
  Scores s{diceCoefficient(labels, *c.intraopLabels, {2, 3, 4}), diceCoefficient(labels, *c.intraopLabels, {3}),
           diceCoefficient(labels, *c.intraopLabels, {4}), meanSurfaceDistanceMm(labels, *c.intraopLabels, {2, 3, 4})};
  std::cout << what << ": brain Dice " << s.brain << ", ventricles " << s.ventricles << ", tumour " << s.tumour
            << ", brain surface distance " << s.surfaceMm << " mm\n";
  return s;
}

} // namespace brainshift::testing
