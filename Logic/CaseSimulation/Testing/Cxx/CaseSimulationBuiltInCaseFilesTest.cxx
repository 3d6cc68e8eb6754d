// The demo's case logic: a scenario's parameters with overrides over them, the case written with
// its scene, and an update folder evaluated against the case's truth (here one holding the truth
// itself: its errors must be the truth's, its classification perfect).
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "BuiltInCaseFiles.h"
#include "CaseSimulationTestSupport.h"
#include "SceneIO.h"
#include "UpdateEvaluationAgainstTruth.h"

#include <iostream>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;

void checkParameters()
{
  CaseParameterOverrides overrides;
  overrides.seed = 7;
  overrides.shiftMillimetres = 5.0;
  const CaseParameters scenario = caseScenario("rf10-t2").parameters;
  const CaseParameters p = builtInCaseParameters("rf10-t2", CaseSize::Small, overrides);
  BS_CHECK(p.size == CaseSize::Small && p.seed == 7 && p.shiftMillimetres == 5.0);
  BS_CHECK(p.contrast == scenario.contrast && p.contrast == IntraopContrast::T2); // the scenario's, not overridden
  BS_CHECK(p.craniotomy == scenario.craniotomy && p.rotationDegrees == scenario.rotationDegrees);
  BS_CHECK_THROWS(builtInCaseParameters("no-such-scenario", CaseSize::Small, {}), InputError, "rf10-t2"); // the names listed
  overrides.noiseFraction = -1.0;
  BS_CHECK_THROWS(builtInCaseParameters("default", CaseSize::Small, overrides), InputError, "--noise"); // validated
}

void checkScene(const CaseFiles& files)
{
  Scene scene;
  readScene(scene, files.folder / "scene.mrml");
  BS_CHECK(scene.nodes().size() == 7);
  const auto truth = scene.findByName<TransformNode>("truth intraop_to_preop");
  const auto preop = scene.findByName<ScalarVolumeNode>("preop image");
  const auto intraop = scene.findByName<ScalarVolumeNode>("intraop image");
  const auto truthLabels = scene.findByName<LabelMapVolumeNode>("truth intraop labels");
  BS_CHECK(truth && preop && intraop && truthLabels);
  if (!truth || !preop || !intraop || !truthLabels) return;
  BS_CHECK(preop->parentTransformId() == truth->id() && intraop->parentTransformId().empty());
  BS_CHECK(scene.sliceViewLayers().backgroundVolumeId == intraop->id() && scene.sliceViewLayers().labelVolumeId == truthLabels->id());
  const auto landmarks = scene.findByName<LandmarksNode>("landmarks");
  BS_CHECK(landmarks && landmarks->parentTransformId() == truth->id());
}

/// The boundary under the craniotomy of an update folder holding the truth: the whole transform shows
/// it exactly; the rigid part alone shows it where it was before the shift: out by the sinking's
/// normal component, at most the 10 mm peak on the axis, less at the rim (sigma 25 mm, 30 mm radius).
void checkBoundaryUnderCraniotomy(const nlohmann::json& b)
{
  BS_CHECK(b["radius_mm"] == 30.0 && b["true_boundary_points"].get<std::size_t>() > 2000); // 2821 lines 1 mm apart, nearly all hit
  const nlohmann::json& shown = b["shown"];
  BS_CHECK(shown["brainshift"]["points"] == b["true_boundary_points"]);
  BS_CHECK(shown["brainshift"]["max_abs_mm"].get<double>() < 1e-3);
  const nlohmann::json& rigid = shown["brainshift_rigid"];
  std::cout << "rigid under the craniotomy: mean " << rigid["mean_abs_mm"] << ", p95 " << rigid["p95_abs_mm"] << ", max " << rigid["max_abs_mm"] << '\n';
  BS_CHECK_NEAR(rigid["mean_abs_mm"].get<double>(), shown["truth_rigid"]["mean_abs_mm"].get<double>(), 1e-6);
  BS_CHECK(rigid["mean_abs_mm"].get<double>() > 4.0 && rigid["mean_abs_mm"].get<double>() < 7.2);
  BS_CHECK(rigid["signed_mean_mm"].get<double>() > 0.98 * rigid["mean_abs_mm"].get<double>()); // outside: the brain sank
  BS_CHECK(rigid["max_abs_mm"].get<double>() > 8.5 && rigid["max_abs_mm"].get<double>() < 10.05);
  BS_CHECK(!b.contains("imposed_nodes")); // no brain_surface.vtp in the folder
}

/// An update folder holding the case's own truth as the update: the true transforms and labels.
void checkEvaluationOfTheTruth(const SimulatedCase& c, const CaseFiles& files, const fs::path& update)
{
  fs::create_directories(update);
  fs::copy_file(files.truthTransform, update / "intraop_to_preop.h5");
  fs::copy_file(files.truthRigidTransform, update / "rigid_intraop_to_preop.tfm");
  fs::copy_file(files.truthIntraopLabels, update / "intraop_labels.nii.gz");
  const nlohmann::json e = evaluateUpdateAgainstTruth(c, update, "case/landmarks.csv", false);
  BS_CHECK(e["landmarks"] == "case/landmarks.csv" && e["pairs"] == c.landmarks.size() && e["pipeline_complete"] == false);
  const nlohmann::json& t = e["transforms"];
  for (const char* key : {"identity", "truth_rigid", "truth", "brainshift_rigid", "brainshift"}) BS_CHECK_MSG(t.contains(key), key);
  BS_CHECK(!t.contains("brainshift_rejected_update"));
  BS_CHECK_NEAR(t["brainshift"]["mean_mm"].get<double>(), t["truth"]["mean_mm"].get<double>(), 0.02);
  BS_CHECK_NEAR(t["brainshift_rigid"]["max_mm"].get<double>(), t["truth_rigid"]["max_mm"].get<double>(), 0.02);
  BS_CHECK(t["identity"]["mean_mm"].get<double>() > 5.0); // the case moved: the identity is far off
  BS_CHECK_NEAR(e["classification"]["brain_dice"].get<double>(), 1.0, 1e-12);
  // Maurer's distance to the boundary between voxel centres: within half the smallest spacing (2.5 mm) of 0.
  BS_CHECK(e["classification"]["brain_surface_distance_mm"].get<double>() < 1.25);
  BS_CHECK(!e.contains("surface") && !e.contains("uncertainty")); // their files are not in the folder
  checkBoundaryUnderCraniotomy(e["boundary_under_craniotomy"]);
  BS_CHECK(!fs::exists(update / "true_error_mm.nii.gz"));
}
} // namespace

int CaseSimulationBuiltInCaseFilesTest(int, char*[])
{
  return brainshift::testing::runTest("CaseSimulationBuiltInCaseFilesTest", [] {
    checkParameters();
    const SimulatedCase& c = testing::smallCase();
    const fs::path root = testing::temporaryFolder("CaseSimulationBuiltInCaseFilesTest");
    const CaseFiles files(root / "case");
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    writeCase(c, parameters, files.folder);
    writeCaseScene(c, files);
    checkScene(files);
    checkEvaluationOfTheTruth(c, files, root / "update");
  });
}
