#pragma once
#include "BrainShiftCaseSimulator.h"
#include "LandmarkEvaluation.h"
#include "RigidRegistrationLogic.h"

namespace brainshift::testing {

/// The small built-in case with the given head motion in the scanner.
inline SimulatedCase smallCaseWithMotion(std::array<double, 3> rotationDegrees, std::array<double, 3> translationMm)
{
  CaseParameters parameters;
  parameters.size = CaseSize::Small;
  parameters.rotationDegrees = rotationDegrees;
  parameters.translationMillimetres = translationMm;
  return simulateCase(parameters);
}

/// The error of a rigid result on the head landmarks, where only the rigid motion applies.
inline ErrorStatistics headError(const SpatialTransform& estimate, const SimulatedCase& c)
{
  return evaluateTransform(estimate, c.landmarks).groups.at("head");
}

} // namespace brainshift::testing
