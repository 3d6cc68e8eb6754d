#pragma once
#include "BrainShiftCaseSimulator.h"

#include <map>
#include <memory>

namespace brainshift::testing {

/// The small case with default options, simulated once per test process.
inline const SimulatedCase& smallCase(bool resection = true)
{
  static std::map<bool, std::unique_ptr<SimulatedCase>> cases;
  auto& slot = cases[resection];
  if (!slot) {
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    parameters.resection = resection;
    slot = std::make_unique<SimulatedCase>(simulateCase(parameters));
  }
  return *slot;
}

} // namespace brainshift::testing
