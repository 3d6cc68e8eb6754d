// A fused slice view (an anatomy, its labels filled at half opacity, a thresholded statistical
// map over them) against a committed baseline (300x300), with VTK's image comparison
// (RenderingComparison.h). Without the overlay the comparison must fail.
#include "RenderingComparison.h"
#include "SliceView.h"
#include "SyntheticData.h"

#include <itkImageRegionIteratorWithIndex.h>

#include <QApplication>
#include <QSurfaceFormat>
#include <QTest>

#include <cmath>

using namespace brainshift;

int SliceViewRenderingTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("SliceViewRenderingTest", [] {
    using testing::point;
    // A "head" of 60 mm radius with a "brain" inside and "ventricles" at its centre; a t-map with
    // a hot blob on the left and a cold one on the right, |t| < 3 elsewhere.
    const ImageGeometry grid = testing::grid({64, 64, 16}, {2.0, 2.0, 4.0}, point(-63, -63, -30));
    auto radius = [](const PhysicalPoint& p) { return std::hypot(p[0], 1.2 * p[1]); };
    auto anatomy = ScalarVolumeNode::create("T1", testing::imageOn<ScalarImage>(grid, [&](const PhysicalPoint& p) {
      const double r = radius(p);
      return float(r > 60 ? 0 : r > 50 ? 300 : r < 12 ? 80 : 200 + 40 * std::sin(p[0] / 6.0) * std::cos(p[1] / 7.0));
    }));
    auto labels = LabelMapVolumeNode::create("labels", testing::imageOn<LabelImage>(grid, [&](const PhysicalPoint& p) {
      const double r = radius(p);
      return LabelPixel(r > 60 ? 0 : r > 50 ? 1 : r < 12 ? 3 : 2);
    }));
    auto statistics = ScalarVolumeNode::create("fMRI", testing::imageOn<ScalarImage>(grid, [](const PhysicalPoint& p) {
      const double hot = 8 * std::exp(-(std::pow(p[0] - 25, 2) + std::pow(p[1] + 10, 2)) / 200.0);
      const double cold = -6 * std::exp(-(std::pow(p[0] + 28, 2) + std::pow(p[1] - 15, 2)) / 150.0);
      return float(hot + cold + 0.5);
    }));
    statistics->setDisplay(VolumeDisplay::statisticalMap());

    SliceView view(SliceOrientation::Axial);
    view.resize(300, 300);
    view.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&view));
    view.setBackground(anatomy);
    view.setLabelMap(labels);
    view.setOverlay(statistics);
    view.setWindowLevel(400, 200);
    view.setCursorPosition(point(10, -20, 0));

    const auto rendered = testing::capture(view);
    const int* size = rendered->GetDimensions();
    BS_CHECK_MSG(size[0] == 300 && size[1] == 300, size[0] << "x" << size[1]);
    const auto expected = testing::baseline("SliceViewRenderingTest", "SliceViewFused.png", rendered);
    const double error = testing::differencePerPixel(rendered, expected);
    std::cout << "difference from the baseline: " << error << " per pixel\n";
    BS_CHECK_MSG(error < testing::renderingTolerance, error);

    view.setOverlay(nullptr);
    const double withoutOverlay = testing::differencePerPixel(testing::capture(view), expected);
    std::cout << "without the overlay: " << withoutOverlay << " per pixel\n";
    BS_CHECK_MSG(withoutOverlay > 2 * testing::renderingTolerance, withoutOverlay); // clearly outside the tolerance
  });
}
