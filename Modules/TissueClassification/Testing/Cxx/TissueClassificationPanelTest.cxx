// The tissue classification panel on the small built-in case (given the preoperative MRI, as the
// command line is, which a 15 mm sink shows in the labels): automatic prototypes give the
// intraoperative labels in the scene (checked against the truth); a point picked in the views
// while Pick is on becomes a prototype of the chosen tissue and the next run uses the list; a
// prototype outside the image is the logic's error in the panel, the scene's labels untouched.
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftTestingSupport.h"
#include "TissueClassificationPanel.h"

#include <itkImageRegionConstIteratorWithIndex.h>

#include <QApplication>
#include <QComboBox>
#include <QPushButton>
#include <QSignalSpy>
#include <QSpinBox>

#include <iostream>

namespace {
using namespace brainshift;

double dice(const LabelImage& a, const LabelImage& b, LabelPixel label)
{
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(&a, a.GetLargestPossibleRegion());
  std::size_t inA = 0, inB = 0, both = 0;
  for (; !it.IsAtEnd(); ++it) {
    const bool x = it.Get() == label, y = b.GetPixel(it.GetIndex()) == label;
    inA += x;
    inB += y;
    both += x && y;
  }
  return 2.0 * double(both) / double(inA + inB);
}

/// The LPS point of the first voxel of `label` whose four in-plane neighbours have it too.
PhysicalPoint innerPointOf(const LabelImage& labels, LabelPixel label)
{
  const auto size = labels.GetLargestPossibleRegion().GetSize();
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(&labels, labels.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    const auto i = it.GetIndex();
    if (it.Get() != label || i[0] == 0 || i[1] == 0 || i[0] + 1 == long(size[0]) || i[1] + 1 == long(size[1])) continue;
    if (labels.GetPixel({{i[0] - 1, i[1], i[2]}}) == label && labels.GetPixel({{i[0] + 1, i[1], i[2]}}) == label &&
        labels.GetPixel({{i[0], i[1] - 1, i[2]}}) == label && labels.GetPixel({{i[0], i[1] + 1, i[2]}}) == label) {
      PhysicalPoint p;
      labels.TransformIndexToPhysicalPoint(i, p);
      return p;
    }
  }
  throw std::runtime_error("no inner voxel of label " + std::to_string(label));
}

std::size_t differingVoxels(const LabelImage& a, const LabelImage& b)
{
  std::size_t n = 0;
  const LabelPixel* x = a.GetBufferPointer();
  const LabelPixel* y = b.GetBufferPointer();
  for (std::size_t i = 0, count = a.GetLargestPossibleRegion().GetNumberOfPixels(); i < count; ++i) n += x[i] != y[i];
  return n;
}

/// A 15 mm sink (small rf15-cavityrim), where the preoperative image changes the labels (the gap
/// takes the fluid pooled over the sunken brain): the panel's run gives the labels of the logic
/// given the image, as the command line does, not those without it.
void panelClassifiesWithThePreoperativeImage()
{
  CaseParameters parameters = caseScenario("rf15-cavityrim").parameters;
  parameters.size = CaseSize::Small;
  const SimulatedCase c = simulateCase(parameters);
  Scene scene;
  scene.add(ScalarVolumeNode::create("intraop image", c.intraopImage))->setRole("intraop");
  scene.add(ScalarVolumeNode::create("preop image", c.preopImage))->setRole("preop");
  scene.add(LabelMapVolumeNode::create("preop labels", c.preopLabels));
  scene.add(TransformNode::create("rigid intraop_to_preop", c.rigidIntraopToPreop));
  TissueClassificationPanel panel(scene, ModuleContext{});
  QSignalSpy finished(&panel, &TissueClassificationPanel::runFinished);
  panel.run();
  BS_CHECK(finished.wait(120000) && finished.last().at(0).toBool());
  auto labels = scene.findByName<LabelMapVolumeNode>("intraop labels");
  BS_CHECK(labels && labels->image());
  TissueClassificationParameters withImage;
  takePreoperativeImage(withImage, *c.preopImage, *c.preopLabels, *c.rigidIntraopToPreop);
  const TissueClassificationResult expected = classifyTissues(*c.intraopImage, *c.preopLabels, *c.rigidIntraopToPreop, std::nullopt, withImage);
  const TissueClassificationResult without = classifyTissues(*c.intraopImage, *c.preopLabels, *c.rigidIntraopToPreop, std::nullopt, {});
  const std::size_t fromExpected = differingVoxels(*labels->image(), *expected.labels);
  const std::size_t fromWithout = differingVoxels(*labels->image(), *without.labels);
  std::cout << "15 mm sink: " << expected.fluidJoinedToGapsMl << " ml joined; the panel's labels differ from the logic's given the image in "
            << fromExpected << " voxels, from those without it in " << fromWithout << "\n";
  BS_CHECK_MSG(fromWithout > 0, "the image changes nothing here: the check no longer tells");
  BS_CHECK_MSG(fromExpected == 0, fromExpected << " voxels differ from the logic given the image");
}
} // namespace

namespace {
/// k is the command line's, from the one configuration; the host's --config reaches the panel.
void checkNeighboursFromConfiguration(brainshift::Scene& scene, const brainshift::TissueClassificationPanel& panel)
{
  using namespace brainshift;
  BS_CHECK(panel.neighboursBox()->value() == int(Configuration{}.classificationK));
  const std::filesystem::path file = std::filesystem::temp_directory_path() / "brainshift-panel-k9.json";
  std::ofstream(file) << R"({"classification": {"k": 9}})";
  ModuleContext configured;
  configured.configurationFile = file.string();
  const TissueClassificationPanel nine(scene, configured);
  BS_CHECK_MSG(nine.neighboursBox()->value() == 9, nine.neighboursBox()->value());
  std::filesystem::remove(file);
}
} // namespace

int TissueClassificationPanelTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("TissueClassificationPanelTest", [] {
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    const SimulatedCase c = simulateCase(parameters);
    Scene scene;
    auto intraop = scene.add(ScalarVolumeNode::create("intraop image", c.intraopImage));
    intraop->setRole("intraop");
    auto preop = scene.add(ScalarVolumeNode::create("preop image", c.preopImage));
    preop->setRole("preop");
    scene.add(LabelMapVolumeNode::create("preop labels", c.preopLabels));
    scene.add(TransformNode::create("rigid intraop_to_preop", c.rigidIntraopToPreop));

    ModuleContext context;
    std::function<void(const std::array<double, 3>&)> pick;
    context.subscribeToPicks = [&pick](QObject*, std::function<void(const std::array<double, 3>&)> onPick) { pick = onPick; };
    TissueClassificationPanel panel(scene, context);
    BS_CHECK(pick && panel.pickButton()->isEnabled());
    checkNeighboursFromConfiguration(scene, panel);
    BS_CHECK(panel.intraopSelector()->currentNode() == intraop);
    // The preoperative MRI, as the command line passes it (offered: the "preop" volumes only).
    BS_CHECK(panel.preopImageSelector()->currentNode() == preop && panel.preopImageSelector()->count() == 1);
    QSignalSpy finished(&panel, &TissueClassificationPanel::runFinished);

    // Automatic prototypes.
    panel.runButton()->click();
    BS_CHECK(panel.isRunning() && panel.cancelButton()->isEnabled());
    BS_CHECK(finished.wait(120000));
    BS_CHECK_MSG(finished.last().at(0).toBool(), panel.statusText().toStdString());
    std::cout << panel.statusText().toStdString() << '\n';
    auto labels = scene.findByName<LabelMapVolumeNode>("intraop labels");
    BS_CHECK(labels && labels->role() == "intraop");
    BS_CHECK(ImageGeometry::of(labels->image()).sameGridAs(ImageGeometry::of(c.intraopImage.GetPointer())));
    const double parenchyma = dice(*labels->image(), *c.intraopLabels, 2);
    std::cout << "parenchyma Dice " << parenchyma << '\n';
    BS_CHECK_MSG(parenchyma > 0.85, parenchyma);
    const std::size_t automatic = panel.prototypes().size();
    BS_CHECK(automatic > 0);

    // A pick while Pick is off adds nothing; with Pick on, a prototype of the chosen tissue.
    const PhysicalPoint ventricle = innerPointOf(*c.intraopLabels, 3);
    pick({ventricle[0], ventricle[1], ventricle[2]});
    BS_CHECK(panel.prototypes().size() == automatic);
    panel.pickButton()->setChecked(true);
    panel.pickTissueBox()->setCurrentIndex(3);
    pick({ventricle[0], ventricle[1], ventricle[2]});
    BS_CHECK(panel.prototypes().size() == automatic + 1);
    BS_CHECK(panel.prototypes().back().label == 3 && panel.prototypes().back().name == "ventricles-picked-1");

    // The next run uses exactly the list, the picked prototype included.
    LabelImage* before = labels->image();
    panel.run();
    BS_CHECK(finished.wait(120000));
    BS_CHECK_MSG(finished.last().at(0).toBool(), panel.statusText().toStdString());
    BS_CHECK(labels->image() != before); // the node's labels replaced by the new run's
    BS_CHECK(panel.prototypes().size() == automatic + 1 && panel.prototypes().back().name == "ventricles-picked-1");

    // A prototype outside the image: the run fails with the logic's message; the labels stay.
    pick({1000.0, 0.0, 0.0});
    before = labels->image();
    panel.run();
    BS_CHECK(finished.wait(120000));
    BS_CHECK(!finished.last().at(0).toBool());
    std::cout << panel.statusText().toStdString() << '\n';
    BS_CHECK(panel.statusText().contains("outside the intraoperative image"));
    BS_CHECK(labels->image() == before && scene.nodesOfType<LabelMapVolumeNode>().size() == 2);
    BS_CHECK(panel.prototypes().size() == automatic + 2); // the list is kept to be corrected

    panel.clearPrototypes();
    BS_CHECK(panel.prototypes().empty());

    panelClassifiesWithThePreoperativeImage();
  });
}
