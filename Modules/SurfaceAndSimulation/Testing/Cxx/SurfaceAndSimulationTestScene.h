#pragma once
// The small built-in case as the surface and simulation panel tests give it to the panel: a 5 mm mesh
// of the preoperative labels, the preoperative labels, the true intraoperative labels, the
// intraoperative image and the case's rigid transform, in a scene.
#include "BrainShiftCaseSimulator.h"
#include "LabelMapMesher.h"
#include "Scene.h"

#include <memory>

namespace brainshift::testing {

struct SurfaceAndSimulationTestNodes {
  std::shared_ptr<ModelNode> mesh;
  std::shared_ptr<LabelMapVolumeNode> intraopLabels;
  std::shared_ptr<ScalarVolumeNode> intraopImage;
  std::shared_ptr<TransformNode> rigid;
};

inline SurfaceAndSimulationTestNodes addSmallDeformationCase(Scene& scene, const SimulatedCase& c)
{
  MeshingParameters meshing;
  meshing.resolutionMm = 5.0;
  SurfaceAndSimulationTestNodes nodes;
  nodes.mesh = scene.add(ModelNode::create("mesh", meshLabelMap(*c.preopLabels, meshing).mesh));
  scene.add(LabelMapVolumeNode::create("preop labels", c.preopLabels));
  nodes.intraopLabels = scene.add(LabelMapVolumeNode::create("intraop labels", c.intraopLabels));
  nodes.intraopImage = scene.add(ScalarVolumeNode::create("intraop image", c.intraopImage));
  nodes.rigid = scene.add(TransformNode::create("rigid intraop_to_preop", c.rigidIntraopToPreop));
  return nodes;
}

} // namespace brainshift::testing
