// The node selector follows the scene: nodes of its kind and role appear, are renamed, leave;
// its choice survives changes elsewhere and moves on when its node is removed.
#include "BrainShiftTestingSupport.h"
#include "NodeSelector.h"

#include <QApplication>
#include <QSignalSpy>

int NodeSelectorTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("NodeSelectorTest", [] {
    using namespace brainshift;
    Scene scene;
    auto preop = scene.add(ScalarVolumeNode::create("preop T1"));
    preop->setRole("preop");
    auto intraop = scene.add(ScalarVolumeNode::create("intraop T1"));
    intraop->setRole("intraop");
    scene.add(LabelMapVolumeNode::create("labels"));

    NodeSelector volumes({NodeKind::ScalarVolume});
    QSignalSpy changes(&volumes, &NodeSelector::currentNodeChanged);
    volumes.setScene(&scene);
    BS_CHECK(volumes.count() == 2);
    BS_CHECK(volumes.currentNodeId() == QString::fromStdString(preop->id()));
    BS_CHECK(changes.count() == 1);

    NodeSelector intraopOnly({NodeKind::ScalarVolume}, "intraop");
    intraopOnly.setScene(&scene);
    BS_CHECK(intraopOnly.count() == 1 && intraopOnly.currentNode() == intraop);

    // Choose the second volume; adding, renaming and removing other nodes keeps the choice.
    BS_CHECK(volumes.setCurrentNodeId(QString::fromStdString(intraop->id())));
    BS_CHECK(changes.count() == 2 && changes.last().at(0).toString() == QString::fromStdString(intraop->id()));
    auto fmri = scene.add(ScalarVolumeNode::create("fMRI"));
    BS_CHECK(volumes.count() == 3);
    BS_CHECK(volumes.currentNode() == intraop);
    preop->setName("preop T1 (renamed)");
    BS_CHECK(volumes.itemText(0) == "preop T1 (renamed)");
    BS_CHECK(!volumes.setCurrentNodeId("vtkMRMLLabelMapVolumeNode1"));
    BS_CHECK(volumes.currentNode() == intraop);

    // A role change moves a node into or out of the role-filtered selector.
    fmri->setRole("intraop");
    BS_CHECK(intraopOnly.count() == 2);
    intraop->setRole("other");
    BS_CHECK(intraopOnly.count() == 1 && intraopOnly.currentNode() == fmri);

    // Removing the chosen node moves the choice to a node that exists and says so.
    const int before = changes.count();
    scene.remove(intraop->id());
    BS_CHECK(volumes.count() == 2);
    BS_CHECK(volumes.currentNode() != nullptr && volumes.currentNode() != intraop);
    BS_CHECK(changes.count() == before + 1);

    // Detached from the scene, it offers nothing and no longer listens.
    volumes.setScene(nullptr);
    BS_CHECK(volumes.count() == 0 && volumes.currentNodeId().isEmpty());
    scene.add(ScalarVolumeNode::create("late"));
    BS_CHECK(volumes.count() == 0);
  });
}
