// Scene::moveNodesFrom: a scene read aside handed to the scene the views follow. Every node moves in
// its order with an id of the receiving scene (which already has nodes: ids never collide), the
// transforms the nodes live under and the slice view layers follow them, the receiving scene's
// observers hear each node added, and the source is left empty. A source without layers leaves the
// receiving scene's layers alone.
#include "BrainShiftTestingSupport.h"
#include "Scene.h"
#include "SyntheticData.h"

#include <itkTranslationTransform.h>

int SceneMoveNodesTest(int, char*[])
{
  return brainshift::testing::runTest("SceneMoveNodesTest", [] {
    using namespace brainshift;
    const auto image = [] { return testing::makeUniformImage({{4, 4, 4}}, 1.0f); };
    Scene views; // the scene the views follow, already holding a volume
    auto old = views.add(ScalarVolumeNode::create("old scan", image()));
    SliceViewLayers oldLayers;
    oldLayers.backgroundVolumeId = old->id();
    views.setSliceViewLayers(oldLayers);

    Scene aside; // a scan's scene read aside
    auto transform = aside.add(TransformNode::create("rigid", itk::TranslationTransform<double, 3>::New().GetPointer()));
    auto scan = aside.add(ScalarVolumeNode::create("intraop image", image()));
    auto warped = aside.add(ScalarVolumeNode::create("warped preop image", image()));
    warped->setParentTransformId(transform->id());
    auto labelImage = LabelImage::New();
    labelImage->SetRegions(image()->GetLargestPossibleRegion());
    labelImage->Allocate();
    labelImage->FillBuffer(2);
    auto labels = aside.add(LabelMapVolumeNode::create("warped preop labels", labelImage));
    SliceViewLayers layers;
    layers.backgroundVolumeId = scan->id();
    layers.foregroundVolumeId = warped->id();
    layers.labelVolumeId = labels->id();
    aside.setSliceViewLayers(layers);

    std::vector<std::string> added;
    views.addObserver([&](const SceneEvent& e) {
      if (e.type == SceneEventType::NodeAdded) added.push_back(e.node->name());
    });
    views.remove(old->id());
    views.moveNodesFrom(aside);

    BS_CHECK(aside.nodes().empty() && aside.sliceViewLayers().empty());
    BS_CHECK(views.nodes().size() == 4);
    BS_CHECK((added == std::vector<std::string>{"rigid", "intraop image", "warped preop image", "warped preop labels"}));
    BS_CHECK(views.node(scan->id()) == scan && views.node(labels->id()) == labels);
    BS_CHECK(warped->parentTransformId() == transform->id() && views.node(transform->id()) == transform);
    const SliceViewLayers& moved = views.sliceViewLayers();
    BS_CHECK(moved.backgroundVolumeId == scan->id() && moved.foregroundVolumeId == warped->id() && moved.labelVolumeId == labels->id());

    // A source without layers moves its nodes and leaves the layers as they were.
    Scene more;
    auto extra = more.add(ScalarVolumeNode::create("extra", image()));
    views.moveNodesFrom(more);
    BS_CHECK(views.nodes().size() == 5 && views.node(extra->id()) == extra);
    BS_CHECK(views.sliceViewLayers().backgroundVolumeId == scan->id());
    views.moveNodesFrom(views); // onto itself: nothing happens
    BS_CHECK(views.nodes().size() == 5);
  });
}
