// The rigid panel on the small built-in case: it picks the volumes by role, runs off the GUI
// thread (the GUI stays live: the busy bar and the disabled Run), and the recovered transform
// lands in the scene. A failing worker (an intraoperative image without foreground) leaves a
// message and the scene as it was.
#include "BrainShiftTestingSupport.h"
#include "LandmarkEvaluation.h"
#include "RigidRegistrationPanel.h"
#include "RigidRegistrationPanelTestSupport.h"

#include <QApplication>
#include <QCheckBox>
#include <QProgressBar>
#include <QPushButton>
#include <QSignalSpy>

#include <iostream>

int RigidRegistrationPanelTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("RigidRegistrationPanelTest", [] {
    using namespace brainshift;
    Scene scene;
    // The panel exists before the data (as in the host): the roles choose the inputs as they arrive.
    RigidRegistrationPanel panel(scene);
    const testing::CaseInScene c = testing::addSmallCase(scene);
    panel.setParameters(testing::quickRigidParameters());
    BS_CHECK(panel.intraopSelector()->currentNode() == c.intraop);
    BS_CHECK(panel.preopSelector()->currentNode() == c.preop);
    BS_CHECK(panel.preopLabelsSelector()->currentNode() == c.preopLabels && panel.useLabelsCheckBox()->isChecked());
    BS_CHECK(!panel.isRunning() && panel.runButton()->isEnabled() && !panel.cancelButton()->isEnabled());

    QSignalSpy finished(&panel, &RigidRegistrationPanel::runFinished);
    panel.runButton()->click();
    BS_CHECK(panel.isRunning());
    BS_CHECK(!panel.runButton()->isEnabled() && panel.cancelButton()->isEnabled());
    BS_CHECK(panel.progressBar()->maximum() == 0); // busy
    BS_CHECK(scene.nodesOfType<TransformNode>().empty()); // nothing before the run ends
    BS_CHECK(finished.wait(120000));
    BS_CHECK_MSG(finished.first().at(0).toBool(), panel.statusText().toStdString());
    BS_CHECK(!panel.isRunning() && panel.runButton()->isEnabled());

    auto transform = scene.findByName<TransformNode>(RigidRegistrationPanel::resultNodeName().toStdString());
    BS_CHECK(transform && transform->transformFromParent());
    BS_CHECK(scene.nodesOfType<TransformNode>().size() == 1);
    const ErrorStatistics head = evaluateTransform(*transform->transformFromParent(), c.simulated.landmarks).groups.at("head");
    std::cout << "head TRE mean " << head.meanMm << " max " << head.maxMm << " mm; " << panel.statusText().toStdString() << '\n';
    BS_CHECK_MSG(head.maxMm < 1.5, head.maxMm);

    // A worker that fails: an intraoperative image without foreground.
    auto empty = ScalarImage::New();
    empty->CopyInformation(c.simulated.intraopImage);
    empty->SetRegions(c.simulated.intraopImage->GetLargestPossibleRegion());
    empty->Allocate();
    empty->FillBuffer(0.0f);
    auto blank = scene.add(ScalarVolumeNode::create("blank", empty));
    const std::size_t nodesBefore = scene.nodes().size();
    const SpatialTransform* transformBefore = transform->transformFromParent();
    BS_CHECK(panel.intraopSelector()->setCurrentNodeId(QString::fromStdString(blank->id())));
    panel.run();
    BS_CHECK(finished.wait(60000));
    BS_CHECK(!finished.last().at(0).toBool());
    BS_CHECK_MSG(panel.statusText().contains("no foreground"), panel.statusText().toStdString());
    BS_CHECK(!panel.isRunning() && panel.runButton()->isEnabled());
    BS_CHECK(scene.nodes().size() == nodesBefore && transform->transformFromParent() == transformBefore);

    // The same volume as both inputs is refused before any work starts.
    BS_CHECK(panel.intraopSelector()->setCurrentNodeId(QString::fromStdString(c.preop->id())));
    panel.run();
    BS_CHECK(!panel.isRunning() && panel.statusText().contains("same node"));
  });
}
