// The meshing panel on a small two-tissue phantom: the mesh lands in the scene under the rigid
// transform with its Label cell array; bad tissues give a message and no mesh; Cancel leaves the
// panel idle at once and the cancelled mesh never reaches the scene. Then the small built-in case:
// its three tissues meshed, every one in the model.
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftTestingSupport.h"
#include "MeshingPanel.h"
#include "SyntheticData.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <vtkCellData.h>

#include <QApplication>
#include <QDoubleSpinBox>
#include <QLineEdit>
#include <QPushButton>
#include <QSignalSpy>

#include <iostream>
#include <set>

int MeshingPanelTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("MeshingPanelTest", [] {
    using namespace brainshift;
    using testing::point;
    // A ball of parenchyma (radius 15 mm) around ventricles (radius 6 mm), 1 mm voxels.
    const ImageGeometry grid = testing::grid({40, 40, 40}, {1, 1, 1}, point(-20, -20, -20));
    auto labels = grid.allocate<LabelImage>();
    itk::ImageRegionIteratorWithIndex<LabelImage> it(labels, labels->GetLargestPossibleRegion());
    for (; !it.IsAtEnd(); ++it) {
      PhysicalPoint p;
      labels->TransformIndexToPhysicalPoint(it.GetIndex(), p);
      const double r = p.EuclideanDistanceTo(point(0, 0, 0));
      it.Set(r < 6 ? 3 : r < 15 ? 2 : 0);
    }
    Scene scene;
    MeshingPanel panel(scene);
    // The defaults are the command line's, from the one configuration (4 mm; the panel used to
    // mesh at 3); another configuration's reach the panel.
    BS_CHECK_MSG(panel.resolutionBox()->value() == Configuration{}.meshResolutionMm, panel.resolutionBox()->value());
    BS_CHECK(panel.tissuesEdit()->text() == "2, 3, 4");
    Configuration coarse;
    coarse.meshResolutionMm = 6.0;
    coarse.meshLabels = {2, 3};
    const MeshingPanel configured(scene, coarse);
    BS_CHECK(configured.resolutionBox()->value() == 6.0 && configured.tissuesEdit()->text() == "2, 3");
    auto rigid = scene.add(TransformNode::create("rigid intraop_to_preop", testing::makeRigidTransform().GetPointer()));
    auto labelNode = scene.add(LabelMapVolumeNode::create("preop labels", labels));
    BS_CHECK(panel.labelsSelector()->currentNode() == labelNode);
    QSignalSpy finished(&panel, &MeshingPanel::runFinished);
    QSignalSpy discarded(&panel, &MeshingPanel::discardedRunFinished);

    // Tissues that are not labels are refused before any work.
    panel.tissuesEdit()->setText("2, brain");
    panel.run();
    BS_CHECK(!panel.isRunning() && panel.statusText().contains("'brain'"));

    // A tissue absent from the label map: the logic's error reaches the panel.
    panel.tissuesEdit()->setText("2 7");
    panel.runButton()->click();
    BS_CHECK(finished.wait(60000));
    BS_CHECK(!finished.last().at(0).toBool());
    std::cout << panel.statusText().toStdString() << '\n';
    BS_CHECK(panel.statusText().startsWith("Meshing failed") && panel.statusText().contains("7"));
    BS_CHECK(scene.nodesOfType<ModelNode>().empty());

    // Cancelled: idle at once, and the result is dropped when the worker ends.
    panel.tissuesEdit()->setText("2, 3");
    panel.run();
    BS_CHECK(panel.isRunning());
    panel.cancelButton()->click();
    BS_CHECK(!panel.isRunning() && panel.runButton()->isEnabled());
    BS_CHECK(discarded.wait(60000));
    BS_CHECK(scene.nodesOfType<ModelNode>().empty());

    // A run: the mesh in the scene, under the rigid transform.
    panel.run();
    BS_CHECK(finished.wait(60000));
    BS_CHECK_MSG(finished.last().at(0).toBool(), panel.statusText().toStdString());
    std::cout << panel.statusText().toStdString() << '\n';
    auto mesh = scene.findByName<ModelNode>("mesh");
    BS_CHECK(mesh && mesh->isVolumetric() && mesh->mesh()->GetNumberOfCells() > 100);
    BS_CHECK(mesh->mesh()->GetCellData()->GetArray("Label"));
    BS_CHECK(mesh->parentTransformId() == rigid->id());
    double range[2];
    mesh->mesh()->GetCellData()->GetArray("Label")->GetRange(range);
    BS_CHECK(range[0] == 2 && range[1] == 3);

    // The small built-in case's preoperative labels, as a scene after loading it holds them.
    CaseParameters small;
    small.size = CaseSize::Small;
    const SimulatedCase c = simulateCase(small);
    Scene caseScene;
    auto preopLabels = caseScene.add(LabelMapVolumeNode::create("preop labels", c.preopLabels));
    preopLabels->setRole("preop");
    MeshingPanel casePanel(caseScene);
    BS_CHECK(casePanel.labelsSelector()->currentNode() == preopLabels);
    casePanel.resolutionBox()->setValue(4.0);
    QSignalSpy caseFinished(&casePanel, &MeshingPanel::runFinished);
    casePanel.runButton()->click();
    BS_CHECK(caseFinished.wait(60000));
    BS_CHECK_MSG(caseFinished.last().at(0).toBool(), casePanel.statusText().toStdString());
    std::cout << "small case: " << casePanel.statusText().toStdString() << '\n';
    auto caseMesh = caseScene.findByName<ModelNode>("mesh");
    BS_CHECK(caseMesh && caseMesh->isVolumetric());
    std::set<int> tissues;
    vtkDataArray* label = caseMesh->mesh()->GetCellData()->GetArray("Label");
    for (vtkIdType cell = 0; cell < label->GetNumberOfTuples(); ++cell) tissues.insert(int(label->GetComponent(cell, 0)));
    BS_CHECK_MSG((tissues == std::set<int>{2, 3, 4}), tissues.size() << " tissues in the mesh");
    BS_CHECK(casePanel.statusText().contains(" 0 inverted"));
  });
}
