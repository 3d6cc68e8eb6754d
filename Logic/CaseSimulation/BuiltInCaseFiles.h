#pragma once
// The built-in case as `brainshift demo` makes it: a named scenario's parameters with the caller's
// values over them, the case simulated and written into its folder (every file of CaseFiles and
// case.json) with a 3D Slicer scene that shows it (scene.mrml). The command line parses the options
// and prints; this builds and writes.
#include "BrainShiftCaseSimulator.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string>

namespace brainshift {

/// Values that replace a scenario's (the options given on the command line); those not set keep
/// the scenario's.
struct CaseParameterOverrides {
  std::optional<std::uint64_t> seed;
  std::optional<double> shiftMillimetres;
  std::optional<CraniotomySite> craniotomy;
  std::optional<bool> resection;
  std::optional<std::array<double, 3>> rotationDegrees, translationMillimetres;
  std::optional<double> noiseFraction, biasStrength;
  std::optional<IntraopContrast> contrast;
  std::optional<TumourAppearance> tumourAppearance;
  std::optional<double> tumourDepthMm;
  std::optional<GapContent> gap;
  std::optional<bool> cavityRim;
  std::optional<TruthModel> truth;
  std::optional<FieldOfView> fieldOfView;
};

/// The scenario's parameters (InputError listing the names for an unknown one) at `size`, with the
/// overrides over them, validated (InputError naming the option).
CaseParameters builtInCaseParameters(const std::string& scenario, CaseSize size, const CaseParameterOverrides& overrides);

/// A built-in case in memory (its truth for the evaluation) and the seconds it took to build and write.
struct BuiltInCase {
  SimulatedCase simulated;
  double seconds = 0;
};

/// Simulates the case and writes it into files.folder: every file of CaseFiles, case.json and
/// scene.mrml (writeCaseScene).
BuiltInCase buildBuiltInCaseFiles(const CaseParameters& parameters, const CaseFiles& files);

/// The case as a 3D Slicer scene (files.folder/scene.mrml) over the files writeCase wrote: the
/// intraoperative scan in the world, the preoperative data under the true intraop_to_preop transform
/// (so they overlay it), the truth labels, the landmarks; the slice views open on the scan with the
/// true intraoperative labels over it.
void writeCaseScene(const SimulatedCase& simulated, const CaseFiles& files);

} // namespace brainshift
