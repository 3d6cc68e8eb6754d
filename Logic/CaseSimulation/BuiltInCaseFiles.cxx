#include "BuiltInCaseFiles.h"

#include "RunReport.h"
#include "SceneIO.h"

namespace brainshift {
namespace fs = std::filesystem;

CaseParameters builtInCaseParameters(const std::string& scenario, CaseSize size, const CaseParameterOverrides& overrides)
{
  CaseParameters p = caseScenario(scenario).parameters;
  const CaseParameterOverrides& o = overrides;
  p.size = size;
  p.seed = o.seed.value_or(p.seed);
  p.shiftMillimetres = o.shiftMillimetres.value_or(p.shiftMillimetres);
  p.craniotomy = o.craniotomy.value_or(p.craniotomy);
  p.resection = o.resection.value_or(p.resection);
  p.rotationDegrees = o.rotationDegrees.value_or(p.rotationDegrees);
  p.translationMillimetres = o.translationMillimetres.value_or(p.translationMillimetres);
  p.noiseFraction = o.noiseFraction.value_or(p.noiseFraction);
  p.biasStrength = o.biasStrength.value_or(p.biasStrength);
  p.contrast = o.contrast.value_or(p.contrast);
  p.tumourAppearance = o.tumourAppearance.value_or(p.tumourAppearance);
  p.tumourDepthMm = o.tumourDepthMm.value_or(p.tumourDepthMm);
  p.gap = o.gap.value_or(p.gap);
  p.cavityRim = o.cavityRim.value_or(p.cavityRim);
  p.truth = o.truth.value_or(p.truth);
  p.fieldOfView = o.fieldOfView.value_or(p.fieldOfView);
  p.validate();
  return p;
}

BuiltInCase buildBuiltInCaseFiles(const CaseParameters& parameters, const CaseFiles& files)
{
  Stopwatch clock;
  BuiltInCase built{simulateCase(parameters), 0.0};
  writeCase(built.simulated, parameters, files.folder);
  writeCaseScene(built.simulated, files);
  built.seconds = clock.seconds();
  return built;
}

void writeCaseScene(const SimulatedCase& simulated, const CaseFiles& files)
{
  Scene scene;
  auto stored = [](auto node, const fs::path& file) {
    node->setStorageFile(fs::absolute(file));
    node->markStored();
    return node;
  };
  auto truth = scene.add(stored(TransformNode::create("truth intraop_to_preop", simulated.intraopToPreop), files.truthTransform));
  truth->setRole("truth");
  auto intraop = scene.add(stored(ScalarVolumeNode::create("intraop image", simulated.intraopImage), files.intraopImage));
  intraop->setRole("intraop");
  auto preop = scene.add(stored(ScalarVolumeNode::create("preop image", simulated.preopImage), files.preopImage));
  preop->setRole("preop");
  preop->setParentTransformId(truth->id());
  auto labels = scene.add(stored(LabelMapVolumeNode::create("preop labels", simulated.preopLabels), files.preopLabels));
  labels->setRole("preop");
  labels->setParentTransformId(truth->id());
  auto fmri = scene.add(stored(ScalarVolumeNode::create("preop fmri", simulated.preopFmri), files.preopFmri));
  fmri->setRole("overlay");
  fmri->setDisplay(VolumeDisplay::statisticalMap());
  fmri->setParentTransformId(truth->id());
  auto truthLabels = scene.add(stored(LabelMapVolumeNode::create("truth intraop labels", simulated.intraopLabels), files.truthIntraopLabels));
  truthLabels->setRole("truth");
  auto landmarks = scene.add(LandmarksNode::create("landmarks", simulated.landmarks));
  landmarks->setRole("truth");
  landmarks->setParentTransformId(truth->id());
  // Slicer opens on the intraoperative scan with the true intraoperative labels over it.
  SliceViewLayers layers;
  layers.backgroundVolumeId = intraop->id();
  layers.labelVolumeId = truthLabels->id();
  scene.setSliceViewLayers(layers);
  writeScene(scene, files.folder / "scene.mrml");
}

} // namespace brainshift
