// The configuration file: defaults, overrides per key, and errors that name the file and the key.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "Configuration.h"

int ConfigurationTest(int, char*[])
{
  return brainshift::testing::runTest("ConfigurationTest", [] {
    using namespace brainshift;
    namespace fs = std::filesystem;
    const fs::path folder = testing::temporaryFolder("ConfigurationTest");
    const Configuration defaults;
    BS_CHECK_NEAR(defaults.materials.at(2).youngsModulusPa, 3000.0, 0);
    BS_CHECK_NEAR(defaults.materials.at(2).poissonRatio, 0.45, 0);
    BS_CHECK_NEAR(defaults.meshResolutionMm, 4.0, 0);

    // The default configuration shipped in Resources/ is the built-in one, and valid.
    const Configuration shipped = Configuration::load(BRAINSHIFT_DEFAULT_CONFIGURATION);
    for (const auto& [label, material] : defaults.materials) {
      BS_CHECK_NEAR(shipped.materials.at(label).youngsModulusPa, material.youngsModulusPa, 0);
      BS_CHECK_NEAR(shipped.materials.at(label).poissonRatio, material.poissonRatio, 0);
    }
    BS_CHECK(shipped.meshLabels == defaults.meshLabels);
    BS_CHECK_NEAR(shipped.meshResolutionMm, defaults.meshResolutionMm, 0);
    BS_CHECK_NEAR(shipped.rigidSamplingFraction, defaults.rigidSamplingFraction, 0);
    BS_CHECK(shipped.rigidLevels == defaults.rigidLevels && defaults.rigidLevels == 3);
    BS_CHECK_NEAR(shipped.meshGrading, defaults.meshGrading, 0);
    BS_CHECK(shipped.meshCoarseningLevels == defaults.meshCoarseningLevels);
    BS_CHECK(shipped.classificationFluidThicknessInAlignedBrain && defaults.classificationFluidThicknessInAlignedBrain);
    BS_CHECK(shipped.classificationTumourFluidByLook && defaults.classificationTumourFluidByLook);
    BS_CHECK(shipped.classificationPrototypesPerTissue == defaults.classificationPrototypesPerTissue &&
             defaults.classificationPrototypesPerTissue == 150);
    BS_CHECK(shipped.classificationSeed == defaults.classificationSeed && defaults.classificationSeed == 2000);
    // Refinement passes "auto" (empty: chosen from the scan's contrast) in both.
    BS_CHECK(!shipped.classificationRefinementPasses && !defaults.classificationRefinementPasses);
    BS_CHECK(shipped.surfaceResidualCorrection && defaults.surfaceResidualCorrection);
    BS_CHECK(!shipped.surfaceSnapToBoundary && !defaults.surfaceSnapToBoundary);
    BS_CHECK_NEAR(shipped.surfaceRestBandMm, defaults.surfaceRestBandMm, 0);
    BS_CHECK(shipped.surfaceRestBandSmoothingPasses == defaults.surfaceRestBandSmoothingPasses);
    BS_CHECK_NEAR(shipped.blockMatching.selectionCellMm, defaults.blockMatching.selectionCellMm, 0);
    BS_CHECK_NEAR(defaults.blockMatching.selectionCellMm, 8.0, 0);
    BS_CHECK_NEAR(shipped.blockMatching.maximumBlocks, defaults.blockMatching.maximumBlocks, 0);
    BS_CHECK(shipped.blockMatching.deformedWindows == defaults.blockMatching.deformedWindows);
    BS_CHECK_NEAR(shipped.blockMatching.smoothingMm, defaults.blockMatching.smoothingMm, 0);
    BS_CHECK_NEAR(defaults.blockMatching.smoothingMm, 0.7, 0);
    BS_CHECK_NEAR(shipped.blockMatching.stiffnessNPerMm, defaults.blockMatching.stiffnessNPerMm, 0);
    BS_CHECK_NEAR(defaults.blockMatching.stiffnessNPerMm, 1.0, 0);
    BS_CHECK_NEAR(shipped.uncertainty.floorMm, defaults.uncertainty.floorMm, 0);
    BS_CHECK_NEAR(shipped.uncertainty.growthPerMm, defaults.uncertainty.growthPerMm, 0);
    BS_CHECK_NEAR(shipped.uncertainty.misfitReachMm, defaults.uncertainty.misfitReachMm, 0);
    BS_CHECK_NEAR(shipped.uncertainty.displacementShare, defaults.uncertainty.displacementShare, 0);

    const fs::path file = folder / "config.json";
    writeTextFileAtomically(file, R"({"materials": {"4": {"youngs_modulus_pa": 20000}},
                                      "mesh": {"resolution_mm": 2.5, "labels": [2, 3], "grading": 1.5, "coarsening_levels": 3,
                                               "region_of_interest": {"center_lps": [10, -20, 30.5], "radius_mm": 12}},
                                      "solver": {"options": "-ksp_type gmres -pc_type bjacobi"},
                                      "rigid": {"sampling": 0.5, "levels": 2},
                                      "classification": {"fluid_thickness_in_aligned_brain": false, "tumour_fluid_by_look": false,
                                                         "refinement_passes": 2, "prototypes_per_tissue": 600, "seed": 7},
                                      "surface": {"residual_correction": false, "rest_band_mm": 1.5, "rest_band_smoothing_passes": 0},
                                      "uncertainty": {"growth_per_mm": 0, "displacement_share": 0.25}})");
    const Configuration c = Configuration::load(file);
    BS_CHECK_NEAR(c.materials.at(4).youngsModulusPa, 20000.0, 0);
    BS_CHECK_NEAR(c.materials.at(4).poissonRatio, 0.45, 0); // the rest of label 4 keeps its default
    BS_CHECK_NEAR(c.materials.at(2).youngsModulusPa, 3000.0, 0);
    BS_CHECK_NEAR(c.meshResolutionMm, 2.5, 0);
    BS_CHECK((c.meshLabels == std::vector<int>{2, 3}));
    BS_CHECK_NEAR(c.meshGrading, 1.5, 0);
    BS_CHECK(c.meshCoarseningLevels == 3);
    BS_CHECK_NEAR(c.meshRegionOfInterestCenterLps[2], 30.5, 0);
    BS_CHECK_NEAR(c.meshRegionOfInterestRadiusMm, 12.0, 0);
    BS_CHECK(c.solverOptions == "-ksp_type gmres -pc_type bjacobi");
    BS_CHECK_NEAR(c.rigidSamplingFraction, 0.5, 0);
    BS_CHECK(c.rigidLevels == 2);
    BS_CHECK(!c.classificationFluidThicknessInAlignedBrain && !c.classificationTumourFluidByLook);
    BS_CHECK(c.classificationRefinementPasses && *c.classificationRefinementPasses == 2);
    BS_CHECK(c.classificationPrototypesPerTissue == 600 && c.classificationSeed == 7);
    BS_CHECK(!c.surfaceResidualCorrection && c.surfaceMatchAlongSinkingDirection); // the rest of "surface" keeps its defaults
    BS_CHECK_NEAR(c.surfaceRestBandMm, 1.5, 0);
    BS_CHECK(c.surfaceRestBandSmoothingPasses == 0);
    BS_CHECK_NEAR(c.uncertainty.growthPerMm, 0.0, 0);
    BS_CHECK_NEAR(c.uncertainty.displacementShare, 0.25, 0);
    BS_CHECK_NEAR(c.uncertainty.floorMm, defaults.uncertainty.floorMm, 0); // not in the file: the default

    // The blocks chosen by structure alone, as before they were spread over the brain.
    writeTextFileAtomically(file, R"({"block_matching": {"selection_cell_mm": 0}})");
    BS_CHECK_NEAR(Configuration::load(file).blockMatching.selectionCellMm, 0.0, 0);
    // The blocks matched in translated windows alone, as before the deformed ones.
    BS_CHECK(defaults.blockMatching.deformedWindows);
    writeTextFileAtomically(file, R"({"block_matching": {"deformed_windows": false}})");
    BS_CHECK(!Configuration::load(file).blockMatching.deformedWindows);
    // The images matched unsmoothed (0), as before the smoothing.
    writeTextFileAtomically(file, R"({"block_matching": {"smoothing_mm": 0}})");
    BS_CHECK_NEAR(Configuration::load(file).blockMatching.smoothingMm, 0.0, 0);

    auto refused = [&](const std::string& text, const std::string& fragment) {
      writeTextFileAtomically(file, text);
      BS_CHECK_THROWS(Configuration::load(file), InputError, fragment);
      BS_CHECK_THROWS(Configuration::load(file), InputError, file.string());
    };
    refused(R"({"materials": {"2": {"poisson_ratio": 0.5}}})", "materials.2.poisson_ratio");
    refused(R"({"materials": {"3": {"youngs_modulus_pa": -1}}})", "materials.3.youngs_modulus_pa");
    refused(R"({"materials": {"brain": {"youngs_modulus_pa": 1}}})", "label number");
    refused(R"({"materials": {"2": {"youngs_modulus_pa": "soft"}}})", "a number is expected");
    refused(R"({"mesh": {"resolution_mm": 0.01}})", "mesh resolution 0.01 mm is outside 0.5 to 50 mm"); // as given, not 0.010000
    refused(R"({"mesh": {"labels": []}})", "empty");
    refused(R"({"meshes": {}})", "unknown key \"meshes\"");
    refused(R"({"mesh": {"grading": -1}})", "mesh grading");
    refused(R"({"mesh": {"coarsening_levels": 9}})", "coarsening levels");
    refused(R"({"mesh": {"region_of_interest": {"center_lps": [1, 2], "radius_mm": 5}}})", "center_lps");
    refused(R"({"mesh": {"region_of_interest": {"center_lps": [1, 2, 3]}}})", "radius_mm");
    refused(R"({"rigid": {"levels": 4}})", "rigid levels");
    refused(R"({"rigid": {"sampling": 0}})", "rigid sampling 0 is outside 0.05 to 4");
    refused(R"({"rigid": {"pyramid": 2}})", "unknown key \"pyramid\"");
    refused(R"({"classification": {"tumour_fluid_by_look": 1}})", "classification.tumour_fluid_by_look");
    refused(R"({"classification": {"refinement_passes": "always"}})", "classification.refinement_passes must be \"auto\"");
    refused(R"({"classification": {"refinement_passes": -1}})", "classification.refinement_passes");
    refused(R"({"classification": {"refinement_passes": 11}})", "refinement passes 11 is outside 0 to 10");
    refused(R"({"classification": {"refinement_passes": 4294967296}})", "classification.refinement_passes must be");
    refused(R"({"classification": {"k": 0}})", "classification.k must be a whole number >= 1");
    refused(R"({"classification": {"seed": -1}})", "classification.seed must be a whole number >= 0");
    refused(R"({"classification": {"prototypes_per_tissue": 50000}})", "prototypes_per_tissue 50000 is outside 1 to 20000");
    refused(R"({"rigid": {"levels": 2.5}})", "rigid.levels must be a whole number >= 1");
    refused(R"({"surface": {"max_iterations": -3}})", "surface.max_iterations must be a whole number >= 1");
    refused(R"({"surface": {"residual_correction": "yes"}})", "surface.residual_correction must be true or false");
    refused(R"({"surface": {"rest_band_mm": 6}})", "surface rest_band_mm 6 mm is outside 0 (off) to 5 mm");
    refused(R"({"surface": {"rest_band_mm": "wide"}})", "surface.rest_band_mm: a number is expected");
    refused(R"({"surface": {"rest_band_smoothing_passes": 101}})", "surface rest_band_smoothing_passes 101 is outside 0 to 100");
    refused(R"({"uncertainty": {"floor_mm": -0.1}})", "uncertainty.floor_mm -0.1 is outside 0 to 100");
    refused(R"({"uncertainty": {"misfit_reach_mm": 0}})", "uncertainty.misfit_reach_mm must be above 0");
    refused(R"({"uncertainty": {"share": 0.2}})", "unknown key \"share\"");
    refused(R"({"block_matching": {"selection_cell_mm": -4}})", "block_matching.selection_cell_mm -4 is outside 1 to 200");
    refused(R"({"block_matching": {"selection_cell_mm": 1e-7}})", "block_matching.selection_cell_mm 1e-07 is outside 1 to 200");
    refused(R"({"block_matching": {"selection_cell_mm": 250}})", "block_matching.selection_cell_mm 250 is outside 1 to 200");
    refused(R"({"block_matching": {"deformed_windows": 1}})", "deformed_windows");
    refused(R"({"block_matching": {"smoothing_mm": -0.5}})", "smoothing_mm");
    refused(R"({"block_matching": {"smoothing_mm": 1e-200}})", "block_matching.smoothing_mm 1e-200 is outside 0.1 to 5");
    refused(R"({"block_matching": {"smoothing_mm": 12}})", "smoothing_mm");
    refused(R"({"materials": )", "not valid JSON");
    BS_CHECK_THROWS(Configuration::load(folder / "missing.json"), InputError, "no such file");
  });
}
