// The scene's bookkeeping: Slicer-style ids, the events observers see (and in which order),
// transform re-parenting on removal, node ownership, and the lookups.
#include "BrainShiftTestingSupport.h"
#include "Scene.h"
#include "SyntheticData.h"

#include <itkTranslationTransform.h>

#include <stdexcept>
#include <vector>

namespace {
using namespace brainshift;

struct RecordedEvent {
  SceneEventType type;
  Node* node;
  bool dataChanged;
};

ScalarImage::Pointer smallImage()
{
  return testing::makeUniformImage({{4, 4, 4}}, 1.0f);
}

SpatialTransform::Pointer translation(double x)
{
  auto t = itk::TranslationTransform<double, 3>::New();
  itk::TranslationTransform<double, 3>::OutputVectorType offset;
  offset.Fill(0.0);
  offset[0] = x;
  t->SetOffset(offset);
  return t.GetPointer();
}

void checkEvent(const RecordedEvent& event, SceneEventType type, const Node* node)
{
  BS_CHECK(event.type == type);
  BS_CHECK(event.node == node);
}
} // namespace

int SceneObserversTest(int, char*[])
{
  return brainshift::testing::runTest("SceneObserversTest", [&] {
    Scene scene;
    std::vector<RecordedEvent> events;
    const Scene::ObserverId observer =
      scene.addObserver([&](const SceneEvent& e) { events.push_back({e.type, e.node, e.dataChanged}); });

    // Ids: the Slicer class name and a per-class counter.
    auto preop = scene.add(ScalarVolumeNode::create("preop", smallImage()));
    auto intraop = scene.add(ScalarVolumeNode::create("intraop", smallImage()));
    auto labels = scene.add(LabelMapVolumeNode::create("labels"));
    auto surface = scene.add(ModelNode::create("surface"));
    auto rigid = scene.add(TransformNode::create("rigid", translation(1)));
    auto local = scene.add(TransformNode::create("local", translation(2)));
    BS_CHECK_MSG(preop->id() == "vtkMRMLScalarVolumeNode1", preop->id());
    BS_CHECK_MSG(intraop->id() == "vtkMRMLScalarVolumeNode2", intraop->id());
    BS_CHECK_MSG(labels->id() == "vtkMRMLLabelMapVolumeNode1", labels->id());
    BS_CHECK_MSG(surface->id() == "vtkMRMLModelNode1", surface->id());
    BS_CHECK_MSG(rigid->id() == "vtkMRMLLinearTransformNode1", rigid->id());
    BS_CHECK_MSG(local->id() == "vtkMRMLLinearTransformNode2", local->id());
    BS_CHECK(scene.nodes().size() == 6);
    BS_CHECK(scene.node(intraop->id()) == intraop);
    BS_CHECK(preop->scene() == &scene);

    BS_CHECK(events.size() == 6);
    checkEvent(events[0], SceneEventType::NodeAdded, preop.get());
    checkEvent(events[5], SceneEventType::NodeAdded, local.get());

    // Modified: dataChanged for new data, not for a new name; an unchanged name is no event.
    events.clear();
    intraop->setImage(smallImage());
    intraop->setName("intraop T1");
    intraop->setName("intraop T1");
    BS_CHECK(events.size() == 2);
    checkEvent(events[0], SceneEventType::NodeModified, intraop.get());
    BS_CHECK(events[0].dataChanged);
    checkEvent(events[1], SceneEventType::NodeModified, intraop.get());
    BS_CHECK(!events[1].dataChanged);
    BS_CHECK(intraop->dataModifiedSinceStorage());

    // Removal: AboutToBeRemoved, then Removed; the removed node leaves the scene.
    events.clear();
    scene.remove(intraop->id());
    BS_CHECK(events.size() == 2);
    checkEvent(events[0], SceneEventType::NodeAboutToBeRemoved, intraop.get());
    checkEvent(events[1], SceneEventType::NodeRemoved, intraop.get());
    BS_CHECK(scene.nodes().size() == 5);
    BS_CHECK(scene.node("vtkMRMLScalarVolumeNode2") == nullptr);
    BS_CHECK(intraop->scene() == nullptr);
    BS_CHECK(intraop->id().empty());
    // Ids are never reused within a scene.
    auto warped = scene.add(ScalarVolumeNode::create("warped"));
    BS_CHECK_MSG(warped->id() == "vtkMRMLScalarVolumeNode3", warped->id());

    // Removing a transform moves its children to the transform's own parent.
    local->setParentTransformId(rigid->id());
    surface->setParentTransformId(local->id());
    labels->setParentTransformId(local->id());
    events.clear();
    scene.remove(local->id());
    BS_CHECK(surface->parentTransformId() == rigid->id());
    BS_CHECK(labels->parentTransformId() == rigid->id());
    BS_CHECK(events.size() == 4);
    checkEvent(events.front(), SceneEventType::NodeAboutToBeRemoved, local.get());
    checkEvent(events[1], SceneEventType::NodeModified, labels.get());
    checkEvent(events[2], SceneEventType::NodeModified, surface.get());
    checkEvent(events.back(), SceneEventType::NodeRemoved, local.get());
    // ... and to the world when the removed transform had no parent.
    scene.remove(rigid->id());
    BS_CHECK(surface->parentTransformId().empty());
    BS_CHECK(labels->parentTransformId().empty());

    // A node belongs to one scene.
    BS_CHECK_THROWS(scene.add(preop), std::invalid_argument, "preop");
    Scene other;
    BS_CHECK_THROWS(other.add(preop), std::invalid_argument, "already belongs");
    BS_CHECK(other.nodes().empty());
    BS_CHECK(preop->id() == "vtkMRMLScalarVolumeNode1");
    // A removed node may join another scene.
    other.add(intraop);
    BS_CHECK(intraop->scene() == &other);
    BS_CHECK(intraop->id() == "vtkMRMLScalarVolumeNode1");

    // Lookups.
    BS_CHECK(scene.findByName<ScalarVolumeNode>("warped") == warped);
    BS_CHECK(scene.findByName<ScalarVolumeNode>("surface") == nullptr); // right name, wrong type
    BS_CHECK(scene.findByName<ModelNode>("surface") == surface);
    BS_CHECK(scene.findByName<Node>("labels") == labels);
    const auto volumes = scene.nodesOfType<ScalarVolumeNode>();
    BS_CHECK(volumes.size() == 2);
    BS_CHECK(volumes[0] == preop && volumes[1] == warped);
    BS_CHECK(scene.nodesOfType<TransformNode>().empty());
    BS_CHECK(scene.nodesOfType<LabelMapVolumeNode>().size() == 1);

    // A removed observer hears nothing more; the others still do.
    int secondObserverCalls = 0;
    scene.addObserver([&](const SceneEvent&) { ++secondObserverCalls; });
    scene.removeObserver(observer);
    events.clear();
    preop->setName("preop T1");
    scene.add(ScalarVolumeNode::create("overlay"));
    scene.remove(warped->id());
    BS_CHECK(events.empty());
    BS_CHECK(secondObserverCalls == 4);
  });
}
