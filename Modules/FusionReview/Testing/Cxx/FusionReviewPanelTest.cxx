// The fusion and review panel on the small built-in case's data, bound to real views (as the host
// binds it): the inputs chosen by their roles, the overlay shown thresholded on |t| with its
// colour scale and opacity written into its node, the readout giving the overlay's value at its
// peak, an angiogram's red scale and threshold, the comparison mode and the label outlines.
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftTestingSupport.h"
#include "FusionReviewPanel.h"
#include "ViewLayout.h"

#include <QApplication>
#include <QSignalSpy>
#include <QSurfaceFormat>
#include <QTest>

#include <cmath>
#include <iostream>

int FusionReviewPanelTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("FusionReviewPanelTest", [] {
    using namespace brainshift;
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    const SimulatedCase c = simulateCase(parameters);
    Scene scene;
    auto intraop = scene.add(ScalarVolumeNode::create("intraop image", c.intraopImage));
    intraop->setRole("intraop");
    auto warpedImage = scene.add(ScalarVolumeNode::create("warped preop image", c.preopImage));
    warpedImage->setRole("warped");
    auto warpedLabels = scene.add(LabelMapVolumeNode::create("warped preop labels", c.intraopLabels));
    warpedLabels->setRole("warped");
    auto fmri = scene.add(ScalarVolumeNode::create("warped fmri", c.preopFmri));
    fmri->setRole("overlay");

    ViewLayout views;
    views.resize(600, 600);
    views.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&views));
    ModuleContext context; // as the host does it, straight onto the views
    int shown = 0;
    context.showLayers = [&](const ViewLayers& layers) {
      ++shown;
      views.setBackground(std::dynamic_pointer_cast<ScalarVolumeNode>(scene.node(layers.backgroundId)));
      views.setLabelMap(std::dynamic_pointer_cast<LabelMapVolumeNode>(scene.node(layers.labelMapId)));
      views.setOverlay(std::dynamic_pointer_cast<ScalarVolumeNode>(scene.node(layers.overlayId)));
      views.setComparison(std::dynamic_pointer_cast<ScalarVolumeNode>(scene.node(layers.comparisonId)));
      views.setComparisonMode(ComparisonMode(layers.comparisonMode));
      views.setLabelOutline(layers.labelOutline);
      views.updateLayers();
    };
    FusionReviewPanel panel(scene, context);
    BS_CHECK(shown > 0);
    BS_CHECK(panel.intraopSelector()->currentNode() == intraop);
    BS_CHECK(panel.overlaySelector()->currentNode() == fmri);
    BS_CHECK(panel.labelsSelector()->currentNode() == warpedLabels);
    BS_CHECK(panel.comparisonSelector()->currentNode() == warpedImage);
    SliceView* axial = views.sliceView(SliceOrientation::Axial);
    BS_CHECK(axial->background() == intraop && axial->overlay() == fmri && axial->labelMap() == warpedLabels);
    BS_CHECK(axial->labelOutline());
    BS_CHECK(fmri->display().colorTable == "ColdToHotRainbow" && fmri->display().lowerThreshold == 3.0);
    BS_CHECK_NEAR(fmri->display().opacity, 0.7, 1e-9);
    std::cout << panel.statusText().toStdString() << '\n';

    // At the statistic's peak the readout gives the overlay's value there.
    const float* t = c.preopFmri->GetBufferPointer();
    std::size_t peak = 0;
    for (std::size_t i = 0, n = c.preopFmri->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
      if (std::abs(t[i]) > std::abs(t[peak])) peak = i;
    }
    ScalarImage::IndexType index;
    const auto size = c.preopFmri->GetLargestPossibleRegion().GetSize();
    index[0] = long(peak % size[0]);
    index[1] = long((peak / size[0]) % size[1]);
    index[2] = long(peak / (size[0] * size[1]));
    PhysicalPoint point;
    c.preopFmri->TransformIndexToPhysicalPoint(index, point);
    views.setCursorPosition(point);
    bool found = false;
    for (const LayerValue& value : views.valuesAtCursor()) {
      if (value.layer != "warped fmri") continue;
      found = true;
      BS_CHECK_MSG(value.value && std::abs(*value.value - t[peak]) < 1e-3 * std::abs(t[peak]) + 1e-6,
                   (value.value ? *value.value : -1.0) << " against " << t[peak]);
    }
    BS_CHECK_MSG(found, views.readoutText().toStdString());
    std::cout << views.readoutText().toStdString() << '\n';
    BS_CHECK(std::abs(t[peak]) > 3.0);

    // An angiogram: the red scale, a threshold from its range, and the window over what is shown.
    panel.setOverlayKind(FusionReviewPanel::OverlayKind::Angiography);
    BS_CHECK(fmri->display().colorTable == "Red");
    BS_CHECK(*fmri->display().lowerThreshold > 0.0 && fmri->display().window && *fmri->display().window > 0.0);
    panel.setOverlayKind(FusionReviewPanel::OverlayKind::Statistics);
    panel.setOverlayThreshold(4.5);
    panel.setOverlayOpacity(0.4);
    BS_CHECK(fmri->display().lowerThreshold == 4.5);
    BS_CHECK_NEAR(fmri->display().opacity, 0.4, 1e-9);

    // The comparison of the intraoperative with the warped preoperative image; labels filled.
    panel.setComparison(FusionReviewPanel::Comparison::Checkerboard);
    BS_CHECK(axial->comparison() == warpedImage && axial->comparisonMode() == ComparisonMode::Checkerboard);
    panel.setComparison(FusionReviewPanel::Comparison::Difference);
    BS_CHECK(views.sliceView(SliceOrientation::Coronal)->comparisonMode() == ComparisonMode::Difference);
    panel.setLabelOutline(false);
    BS_CHECK(!axial->labelOutline());
    BS_CHECK(panel.statusText().contains("compared with warped preop image"));

    // A scene loaded after the panel is made (as the host does): the roles still choose.
    {
      Scene later;
      FusionReviewPanel waiting(later, ModuleContext{});
      auto laterIntraop = later.add(ScalarVolumeNode::create("intraop image", c.intraopImage));
      laterIntraop->setRole("intraop"); // after adding
      auto warpedNode = ScalarVolumeNode::create("warped preop image", c.preopImage);
      warpedNode->setRole("warped"); // before adding, as the scene reader does
      auto laterWarped = later.add(warpedNode);
      QCoreApplication::processEvents(); // the panel chooses once the scene's events are over
      BS_CHECK_MSG(waiting.comparisonSelector()->currentNode() == laterWarped,
                   waiting.comparisonSelector()->currentNodeId().toStdString());
      BS_CHECK(waiting.intraopSelector()->currentNode() == laterIntraop);
    }

    // Without views (no context), the panel still keeps the overlay's display.
    FusionReviewPanel alone(scene, ModuleContext{});
    alone.setOverlayThreshold(2.0);
    BS_CHECK(fmri->display().lowerThreshold == 2.0);
  });
}
