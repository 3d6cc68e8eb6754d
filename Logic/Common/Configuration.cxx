#include "Configuration.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "NumberText.h"

#include <nlohmann/json.hpp>

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <initializer_list>
#include <limits>
#include <set>
#include <tuple>
#include <sstream>
#include <utility>
#include <vector>

namespace brainshift {
namespace fs = std::filesystem;

/// Poisson ratios from here on lock linear tetrahedra (0.4999: 1527 iterations, nodes moved
/// 10 mm for 8.5 mm imposed): refused.
constexpr double kLockingPoissonRatio = 0.49;
using nlohmann::json;

namespace {
void requireKnownKeys(const json& object, const std::set<std::string>& known, const std::string& where)
{
  for (auto it = object.begin(); it != object.end(); ++it) {
    if (!known.count(it.key())) {
      std::string list;
      for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
      throw InputError(where + ": unknown key \"" + it.key() + "\" (known: " + list + ")");
    }
  }
}

double number(const json& value, const std::string& where)
{
  if (!value.is_number()) throw InputError(where + ": a number is expected, not " + value.dump());
  return value.get<double>();
}

bool isWholeNumberFrom(const json& value, long long minimum)
{
  return value.is_number_integer() && value.get<long long>() >= minimum &&
         value.get<long long>() <= static_cast<long long>(std::numeric_limits<unsigned>::max());
}

/// A whole number of at least `minimum` (InputError "`where` must be a whole number >= minimum").
unsigned wholeNumber(const json& value, long long minimum, const std::string& where)
{
  if (!isWholeNumberFrom(value, minimum)) throw InputError(where + " must be a whole number >= " + std::to_string(minimum));
  return static_cast<unsigned>(value.get<long long>());
}
/// The label number a "materials" key names, or -1.
int labelOfKey(const std::string& key)
{
  int label = -1;
  try {
    std::size_t used = 0;
    label = std::stoi(key, &used);
    if (used != key.size()) label = -1;
  } catch (const std::exception&) {
  }
  return label;
}

void readMaterials(const json& materials, const std::string& file, Configuration& configuration)
{
  if (!materials.is_object()) throw InputError(file + ": \"materials\" must be an object keyed by label");
  for (auto it = materials.begin(); it != materials.end(); ++it) {
    const std::string where = file + ": materials." + it.key();
    const int label = labelOfKey(it.key());
    if (label < 0 || label > 65535) throw InputError(where + ": the key must be a label number");
    if (!it.value().is_object()) throw InputError(where + ": an object with youngs_modulus_pa and poisson_ratio is expected");
    requireKnownKeys(it.value(), {"youngs_modulus_pa", "poisson_ratio"}, where);
    Material material = configuration.materials.count(label) ? configuration.materials[label] : Material{};
    if (it.value().contains("youngs_modulus_pa")) material.youngsModulusPa = number(it.value()["youngs_modulus_pa"], where + ".youngs_modulus_pa");
    if (it.value().contains("poisson_ratio")) material.poissonRatio = number(it.value()["poisson_ratio"], where + ".poisson_ratio");
    configuration.materials[label] = material;
  }
}

void readRegionOfInterest(const json& roi, const std::string& file, Configuration& configuration)
{
  const std::string where = file + ": mesh.region_of_interest";
  if (!roi.is_object()) throw InputError(where + " must be an object {\"center_lps\": [x, y, z], \"radius_mm\": r}");
  requireKnownKeys(roi, {"center_lps", "radius_mm"}, where);
  if (!roi.contains("center_lps") || !roi["center_lps"].is_array() || roi["center_lps"].size() != 3) {
    throw InputError(where + ".center_lps must be a list of three numbers (LPS mm)");
  }
  for (int d = 0; d < 3; ++d) {
    configuration.meshRegionOfInterestCenterLps[std::size_t(d)] = number(roi["center_lps"][std::size_t(d)], where + ".center_lps");
  }
  if (!roi.contains("radius_mm")) throw InputError(where + ".radius_mm is missing");
  configuration.meshRegionOfInterestRadiusMm = number(roi["radius_mm"], where + ".radius_mm");
}

void readMesh(const json& mesh, const std::string& file, Configuration& configuration)
{
  if (!mesh.is_object()) throw InputError(file + ": \"mesh\" must be an object");
  requireKnownKeys(mesh, {"resolution_mm", "labels", "backend", "grading", "coarsening_levels", "region_of_interest"}, file + ": mesh");
  if (mesh.contains("grading")) configuration.meshGrading = number(mesh["grading"], file + ": mesh.grading");
  if (mesh.contains("coarsening_levels")) {
    if (!mesh["coarsening_levels"].is_number_integer()) throw InputError(file + ": mesh.coarsening_levels must be a whole number");
    configuration.meshCoarseningLevels = mesh["coarsening_levels"].get<int>();
  }
  if (mesh.contains("region_of_interest")) readRegionOfInterest(mesh["region_of_interest"], file, configuration);
  if (mesh.contains("backend")) {
    if (!mesh["backend"].is_string()) throw InputError(file + ": mesh.backend must be \"lattice\" or \"cgal\"");
    configuration.meshBackend = mesh["backend"].get<std::string>();
  }
  if (mesh.contains("resolution_mm")) configuration.meshResolutionMm = number(mesh["resolution_mm"], file + ": mesh.resolution_mm");
  if (mesh.contains("labels")) {
    if (!mesh["labels"].is_array()) throw InputError(file + ": mesh.labels must be a list of labels");
    configuration.meshLabels.clear();
    for (const json& l : mesh["labels"]) {
      if (!l.is_number_integer()) throw InputError(file + ": mesh.labels holds " + l.dump() + ", not a label");
      configuration.meshLabels.push_back(l.get<int>());
    }
  }
}

void readSolver(const json& solver, const std::string& file, Configuration& configuration)
{
  if (!solver.is_object()) throw InputError(file + ": \"solver\" must be an object");
  requireKnownKeys(solver, {"options"}, file + ": solver");
  if (solver.contains("options")) {
    if (!solver["options"].is_string()) throw InputError(file + ": solver.options must be a string of PETSc options");
    configuration.solverOptions = solver["options"].get<std::string>();
  }
}

/// Each key of `flags` that `section` (named `where`) holds must be true or false; read into its target.
void readFlags(const json& section, std::initializer_list<std::pair<const char*, bool*>> flags, const std::string& where)
{
  for (const auto& [key, target] : flags) {
    if (!section.contains(key)) continue;
    if (!section[key].is_boolean()) throw InputError(where + "." + key + " must be true or false");
    *target = section[key].get<bool>();
  }
}

void readClassification(const json& c, const std::string& file, Configuration& configuration)
{
  if (!c.is_object()) throw InputError(file + ": \"classification\" must be an object");
  requireKnownKeys(c, {"k", "saturation_mm", "bias_correction", "tumour_resected", "refinement_passes", "refinement_tolerance_mm",
                      "refinement_reach_mm", "fluid_thickness_in_aligned_brain", "tumour_fluid_by_look", "tumour_second_look",
                      "prototypes_per_tissue", "seed"},
                   file + ": classification");
  if (c.contains("tumour_resected")) {
    if (!c["tumour_resected"].is_string()) throw InputError(file + ": classification.tumour_resected must be \"auto\", \"yes\" or \"no\"");
    configuration.classificationTumourResected = c["tumour_resected"].get<std::string>();
  }
  if (c.contains("refinement_passes")) {
    const json& passes = c["refinement_passes"];
    if (passes.is_string() && passes.get<std::string>() == "auto") {
      configuration.classificationRefinementPasses.reset();
    } else if (isWholeNumberFrom(passes, 0)) {
      configuration.classificationRefinementPasses = passes.get<unsigned>();
    } else {
      throw InputError(file + ": classification.refinement_passes must be \"auto\" or a whole number >= 0");
    }
  }
  if (c.contains("refinement_reach_mm")) {
    configuration.classificationRefinementReachMm = number(c["refinement_reach_mm"], file + ": classification.refinement_reach_mm");
  }
  if (c.contains("refinement_tolerance_mm")) {
    configuration.classificationRefinementToleranceMm = number(c["refinement_tolerance_mm"], file + ": classification.refinement_tolerance_mm");
  }
  if (c.contains("k")) configuration.classificationK = wholeNumber(c["k"], 1, file + ": classification.k");
  if (c.contains("prototypes_per_tissue")) {
    configuration.classificationPrototypesPerTissue = wholeNumber(c["prototypes_per_tissue"], 1, file + ": classification.prototypes_per_tissue");
  }
  if (c.contains("seed")) configuration.classificationSeed = wholeNumber(c["seed"], 0, file + ": classification.seed");
  if (c.contains("saturation_mm")) configuration.classificationSaturationMm = number(c["saturation_mm"], file + ": classification.saturation_mm");
  readFlags(c, {{"bias_correction", &configuration.classificationBiasCorrection},
                {"fluid_thickness_in_aligned_brain", &configuration.classificationFluidThicknessInAlignedBrain},
                {"tumour_fluid_by_look", &configuration.classificationTumourFluidByLook},
                {"tumour_second_look", &configuration.classificationTumourSecondLook}},
            file + ": classification");
}

void readRigid(const json& c, const std::string& file, Configuration& configuration)
{
  if (!c.is_object()) throw InputError(file + ": \"rigid\" must be an object");
  requireKnownKeys(c, {"sampling", "levels"}, file + ": rigid");
  if (c.contains("sampling")) configuration.rigidSamplingFraction = number(c["sampling"], file + ": rigid.sampling");
  if (c.contains("levels")) configuration.rigidLevels = wholeNumber(c["levels"], 1, file + ": rigid.levels");
}

void readSurface(const json& c, const std::string& file, Configuration& configuration)
{
  if (!c.is_object()) throw InputError(file + ": \"surface\" must be an object");
  requireKnownKeys(c, {"membrane_weight", "bending_weight", "image_weight", "max_iterations", "match_along_sinking_direction",
                       "snap_to_boundary", "residual_correction", "hold_outside_field_of_view", "rest_band_mm",
                       "rest_band_smoothing_passes"},
                   file + ": surface");
  readFlags(c, {{"match_along_sinking_direction", &configuration.surfaceMatchAlongSinkingDirection},
                {"snap_to_boundary", &configuration.surfaceSnapToBoundary},
                {"residual_correction", &configuration.surfaceResidualCorrection},
                {"hold_outside_field_of_view", &configuration.surfaceHoldOutsideFieldOfView}},
            file + ": surface");
  if (c.contains("membrane_weight")) configuration.surfaceMembraneWeight = number(c["membrane_weight"], file + ": surface.membrane_weight");
  if (c.contains("bending_weight")) configuration.surfaceBendingWeight = number(c["bending_weight"], file + ": surface.bending_weight");
  if (c.contains("image_weight")) configuration.surfaceImageWeight = number(c["image_weight"], file + ": surface.image_weight");
  if (c.contains("rest_band_mm")) configuration.surfaceRestBandMm = number(c["rest_band_mm"], file + ": surface.rest_band_mm");
  if (c.contains("rest_band_smoothing_passes")) {
    configuration.surfaceRestBandSmoothingPasses = wholeNumber(c["rest_band_smoothing_passes"], 0, file + ": surface.rest_band_smoothing_passes");
  }
  if (c.contains("max_iterations")) {
    configuration.surfaceMaximumIterations = wholeNumber(c["max_iterations"], 1, file + ": surface.max_iterations");
  }
}

void readBlockMatching(const json& c, const std::string& file, Configuration& configuration)
{
  if (!c.is_object()) throw InputError(file + ": \"block_matching\" must be an object");
  Configuration::BlockMatching& b = configuration.blockMatching;
  const std::vector<std::pair<const char*, double*>> numbers{
    {"block_half_size_mm", &b.blockHalfSizeMm}, {"block_spacing_mm", &b.blockSpacingMm}, {"selected_share", &b.selectedShare},
    {"search_radius_mm", &b.searchRadiusMm}, {"minimum_similarity", &b.minimumSimilarity}, {"maximum_blocks", &b.maximumBlocks}, {"selection_cell_mm", &b.selectionCellMm},
    {"smoothing_mm", &b.smoothingMm},
    {"stiffness_n_per_mm", &b.stiffnessNPerMm}, {"rejection_rounds", &b.rejectionRounds}, {"rejection_fraction", &b.rejectionFraction},
    {"outlier_factor", &b.outlierFactor}, {"rejection_floor_mm", &b.rejectionFloorMm}};
  std::set<std::string> keys{"enabled", "deformed_windows"};
  for (const auto& [key, target] : numbers) keys.insert(key);
  requireKnownKeys(c, keys, file + ": block_matching");
  readFlags(c, {{"enabled", &b.enabled}, {"deformed_windows", &b.deformedWindows}}, file + ": block_matching");
  for (const auto& [key, target] : numbers) {
    if (c.contains(key)) *target = number(c[key], file + ": block_matching." + key);
  }
}

void readUncertainty(const json& c, const std::string& file, Configuration& configuration)
{
  if (!c.is_object()) throw InputError(file + ": \"uncertainty\" must be an object");
  Configuration::Uncertainty& u = configuration.uncertainty;
  const std::vector<std::pair<const char*, double*>> numbers{{"floor_mm", &u.floorMm},
                                                             {"growth_per_mm", &u.growthPerMm},
                                                             {"misfit_reach_mm", &u.misfitReachMm},
                                                             {"displacement_share", &u.displacementShare}};
  std::set<std::string> keys;
  for (const auto& [key, target] : numbers) keys.insert(key);
  requireKnownKeys(c, keys, file + ": uncertainty");
  for (const auto& [key, target] : numbers) {
    if (c.contains(key)) *target = number(c[key], file + ": uncertainty." + key);
  }
}

/// Each section of the configuration file: its reader (the sections are read in this order).
using SectionReader = void (*)(const json&, const std::string&, Configuration&);
const std::vector<std::pair<const char*, SectionReader>>& sectionReaders()
{
  static const std::vector<std::pair<const char*, SectionReader>> readers{
    {"materials", readMaterials}, {"mesh", readMesh},       {"solver", readSolver},
    {"classification", readClassification}, {"rigid", readRigid}, {"surface", readSurface},
    {"block_matching", readBlockMatching}, {"uncertainty", readUncertainty}};
  return readers;
}
} // namespace

Configuration Configuration::load(const fs::path& path)
{
  Configuration configuration;
  json document;
  try {
    document = json::parse(readTextFile(path));
  } catch (const json::exception& e) {
    throw InputError(path.string() + ": not valid JSON: " + e.what());
  }
  const std::string file = path.string();
  if (!document.is_object()) throw InputError(file + ": the configuration must be a JSON object");
  requireKnownKeys(document, {"materials", "mesh", "solver", "ranks", "rigid", "classification", "surface", "block_matching",
                                "uncertainty"}, file);
  for (const auto& [section, read] : sectionReaders()) {
    if (document.contains(section)) read(document[section], file, configuration);
  }
  if (document.contains("ranks")) {
    if (!document["ranks"].is_number_integer()) throw InputError(file + ": ranks must be a whole number");
    configuration.ranks = document["ranks"].get<int>();
  }
  configuration.validate(file);
  return configuration;
}

namespace {
bool isOptionName(const std::string& token)
{
  return token.size() > 1 && token[0] == '-' && std::isalpha(static_cast<unsigned char>(token[1]));
}

/// PETSc ignores in silence a word that is not an option ("garbage") and takes a negative
/// tolerance or iteration count for "the default": both are refused here, naming the word.
/// (Options PETSc does not know are refused by the worker, which asks PETSc which were unused.)
std::string solverOptionsProblem(const std::string& options)
{
  std::istringstream words(options);
  std::string word, option;
  bool valueTaken = true;
  while (words >> word) {
    if (isOptionName(word)) {
      option = word;
      valueTaken = false;
      continue;
    }
    if (valueTaken) return "'" + word + "' is neither an option (-name) nor the value of one";
    valueTaken = true;
    const bool countOrTolerance = option.find("tol") != std::string::npos || option.find("max_it") != std::string::npos;
    char* end = nullptr;
    const double value = std::strtod(word.c_str(), &end);
    if (countOrTolerance && (end == word.c_str() || *end != '\0' || !std::isfinite(value) || value < 0)) {
      return option + " " + word + ": a non-negative number is expected";
    }
  }
  return "";
}

void validateMaterial(const Material& material, const std::string& where)
{
  if (!std::isfinite(material.youngsModulusPa) || material.youngsModulusPa <= 0) {
    throw InputError(where + ".youngs_modulus_pa: " + numberText(material.youngsModulusPa) +
                     " Pa; a positive, finite modulus is expected");
  }
  // Soft tissue lies within 1e2-1e5 Pa, bone near 1e10: outside 1 Pa to 1 GPa the stiffness
  // matrix spans more orders of magnitude than the solver can resolve (1e300 gave NaN).
  if (material.youngsModulusPa < 1.0 || material.youngsModulusPa > 1e9) {
    throw InputError(where + ".youngs_modulus_pa: " + numberText(material.youngsModulusPa) +
                     " Pa is outside the physical range 1 Pa to 1e9 Pa (brain tissue: about 1e3 to 1e4 Pa)");
  }
  if (!std::isfinite(material.poissonRatio) || material.poissonRatio < 0 || material.poissonRatio >= 0.5) {
    throw InputError(where + ".poisson_ratio: " + numberText(material.poissonRatio) +
                     "; it must be at least 0 and below 0.5 (0.5 is incompressible: no linear elastic solution)");
  }
  if (material.poissonRatio >= kLockingPoissonRatio) {
    std::ostringstream value;
    value << material.poissonRatio;
    throw InputError(where + ".poisson_ratio: " + value.str() +
                     " is 0.49 or more: linear tetrahedra lock volumetrically near incompressibility (far too "
                     "stiff, wrong displacements); use a ratio below 0.49 (0.45 is the usual value for brain)");
  }
}

void validateMeshSettings(const Configuration& c, const std::string& source)
{
  if (!std::isfinite(c.meshResolutionMm) || c.meshResolutionMm < 0.5 || c.meshResolutionMm > 50) {
    throw InputError(source + ": mesh resolution " + numberText(c.meshResolutionMm) + " mm is outside 0.5 to 50 mm");
  }
  if (c.meshLabels.empty()) throw InputError(source + ": mesh.labels is empty; nothing to mesh");
  if (!std::isfinite(c.meshGrading) || c.meshGrading < 0 || c.meshGrading > 10) {
    throw InputError(source + ": mesh grading " + numberText(c.meshGrading) + " is outside 0 (uniform) to 10");
  }
  if (c.meshCoarseningLevels < 0 || c.meshCoarseningLevels > 4) {
    throw InputError(source + ": mesh coarsening levels " + std::to_string(c.meshCoarseningLevels) + " is outside 0 to 4");
  }
  if (!std::isfinite(c.meshRegionOfInterestRadiusMm) || c.meshRegionOfInterestRadiusMm < 0 || c.meshRegionOfInterestRadiusMm > 500 ||
      !std::isfinite(c.meshRegionOfInterestCenterLps[0]) || !std::isfinite(c.meshRegionOfInterestCenterLps[1]) ||
      !std::isfinite(c.meshRegionOfInterestCenterLps[2])) {
    throw InputError(source + ": mesh region of interest radius " + numberText(c.meshRegionOfInterestRadiusMm) +
                     " mm (or its centre) is not a finite size within 0 to 500 mm");
  }
  if (c.meshBackend != "lattice" && c.meshBackend != "cgal") {
    throw InputError(source + ": mesh backend \"" + c.meshBackend + "\" is neither \"lattice\" nor \"cgal\"");
  }
  for (int label : c.meshLabels) {
    if (label <= 0 || label > 65535) throw InputError(source + ": mesh label " + std::to_string(label) + " is not a tissue label");
  }
}

void validateRigidSettings(const Configuration& c, const std::string& source)
{
  if (!std::isfinite(c.rigidSamplingFraction) || c.rigidSamplingFraction < 0.05 || c.rigidSamplingFraction > 4) {
    throw InputError(source + ": rigid sampling " + numberText(c.rigidSamplingFraction) + " is outside 0.05 to 4");
  }
  if (c.rigidLevels < 1 || c.rigidLevels > 3) {
    throw InputError(source + ": rigid levels " + std::to_string(c.rigidLevels) + " is outside 1 to 3");
  }
}

void validateClassificationSettings(const Configuration& c, const std::string& source)
{
  if (c.classificationK < 1 || c.classificationK > 101) {
    throw InputError(source + ": classification k " + std::to_string(c.classificationK) + " is outside 1 to 101");
  }
  if (c.classificationPrototypesPerTissue < 1 || c.classificationPrototypesPerTissue > 20000) {
    throw InputError(source + ": classification prototypes_per_tissue " + std::to_string(c.classificationPrototypesPerTissue) +
                     " is outside 1 to 20000");
  }
  if (c.classificationTumourResected != "auto" && c.classificationTumourResected != "yes" && c.classificationTumourResected != "no") {
    throw InputError(source + ": classification tumour_resected '" + c.classificationTumourResected + "' is not one of auto, yes, no");
  }
  if (c.classificationRefinementPasses && *c.classificationRefinementPasses > 10) {
    throw InputError(source + ": classification refinement passes " + std::to_string(*c.classificationRefinementPasses) +
                     " is outside 0 to 10");
  }
  if (!std::isfinite(c.classificationRefinementToleranceMm) || c.classificationRefinementToleranceMm <= 0 ||
      c.classificationRefinementToleranceMm > 10) {
    throw InputError(source + ": classification refinement tolerance " + numberText(c.classificationRefinementToleranceMm) +
                     " mm is outside 0 to 10 mm");
  }
  if (!std::isfinite(c.classificationRefinementReachMm) || c.classificationRefinementReachMm < 0 || c.classificationRefinementReachMm > 200) {
    throw InputError(source + ": classification refinement reach " + numberText(c.classificationRefinementReachMm) +
                     " mm is outside 0 to 200 mm");
  }
  if (!std::isfinite(c.classificationSaturationMm) || c.classificationSaturationMm <= 0 || c.classificationSaturationMm > 100) {
    throw InputError(source + ": classification saturation " + numberText(c.classificationSaturationMm) + " mm is outside 0 to 100 mm");
  }
}

void validateSurfaceSettings(const Configuration& c, const std::string& source)
{
  if (!std::isfinite(c.surfaceRestBandMm) || c.surfaceRestBandMm < 0 || c.surfaceRestBandMm > 5) {
    throw InputError(source + ": surface rest_band_mm " + numberText(c.surfaceRestBandMm) + " mm is outside 0 (off) to 5 mm");
  }
  if (c.surfaceRestBandSmoothingPasses > 100) {
    throw InputError(source + ": surface rest_band_smoothing_passes " + std::to_string(c.surfaceRestBandSmoothingPasses) +
                     " is outside 0 to 100");
  }
  if (!std::isfinite(c.surfaceMembraneWeight) || c.surfaceMembraneWeight < 0 || c.surfaceMembraneWeight > 1000 ||
      !std::isfinite(c.surfaceBendingWeight) || c.surfaceBendingWeight < 0 || c.surfaceBendingWeight > 1000) {
    throw InputError(source + ": surface membrane and bending weights must be within 0 to 1000");
  }
  if (!std::isfinite(c.surfaceImageWeight) || c.surfaceImageWeight < 0 || c.surfaceImageWeight > 1) {
    throw InputError(source + ": surface image weight " + numberText(c.surfaceImageWeight) + " is outside 0 to 1");
  }
  if (c.surfaceMaximumIterations < 1 || c.surfaceMaximumIterations > 100000) {
    throw InputError(source + ": surface max_iterations " + std::to_string(c.surfaceMaximumIterations) + " is outside 1 to 100000");
  }
}
} // namespace

void Configuration::validate(const std::string& source) const
{
  if (const std::string problem = solverOptionsProblem(solverOptions); !problem.empty()) {
    throw InputError(source + ": solver options \"" + solverOptions + "\": " + problem);
  }
  for (const auto& [label, material] : materials) validateMaterial(material, source + ": materials." + std::to_string(label));
  validateMeshSettings(*this, source);
  validateRigidSettings(*this, source);
  validateClassificationSettings(*this, source);
  validateSurfaceSettings(*this, source);
  if (ranks < 1 || ranks > 1024) throw InputError(source + ": ranks " + std::to_string(ranks) + " is outside 1 to 1024");
  validateBlockMatching(source);
  validateUncertainty(source);
}

void Configuration::validateBlockMatching(const std::string& source) const
{
  const BlockMatching& b = blockMatching;
  auto within = [&source](const char* key, double value, double low, double high, bool whole = false) {
    if (!std::isfinite(value) || value < low || value > high || (whole && value != std::floor(value))) {
      std::ostringstream message;
      message << source << ": block_matching." << key << " " << value << " is outside " << low << " to " << high
              << (whole ? " (a whole number)" : "");
      throw InputError(message.str());
    }
  };
  within("block_half_size_mm", b.blockHalfSizeMm, 1, 20);
  within("block_spacing_mm", b.blockSpacingMm, 1, 50);
  within("selected_share", b.selectedShare, 0.01, 1);
  if (b.selectionCellMm != 0) within("selection_cell_mm", b.selectionCellMm, 1, 200); // 0: by structure alone
  within("search_radius_mm", b.searchRadiusMm, 1, 30);
  within("minimum_similarity", b.minimumSimilarity, -1, 1);
  within("maximum_blocks", b.maximumBlocks, 1, 1e6, true);
  if (b.smoothingMm != 0) within("smoothing_mm", b.smoothingMm, 0.1, 5); // 0: not smoothed
  within("stiffness_n_per_mm", b.stiffnessNPerMm, 0, 100);
  within("rejection_rounds", b.rejectionRounds, 0, 100, true);
  within("rejection_fraction", b.rejectionFraction, 0, 1);
  within("outlier_factor", b.outlierFactor, 0, 100);
  within("rejection_floor_mm", b.rejectionFloorMm, 0, 100);
}

void Configuration::validateUncertainty(const std::string& source) const
{
  for (const auto& [key, value, high] : {std::tuple<const char*, double, double>{"floor_mm", uncertainty.floorMm, 100},
                                         {"growth_per_mm", uncertainty.growthPerMm, 10},
                                         {"misfit_reach_mm", uncertainty.misfitReachMm, 100},
                                         {"displacement_share", uncertainty.displacementShare, 10}}) {
    if (!std::isfinite(value) || value < 0 || value > high) {
      std::ostringstream message;
      message << source << ": uncertainty." << key << " " << value << " is outside 0 to " << high;
      throw InputError(message.str());
    }
  }
  if (!(uncertainty.misfitReachMm > 0)) throw InputError(source + ": uncertainty.misfit_reach_mm must be above 0");
}

} // namespace brainshift
