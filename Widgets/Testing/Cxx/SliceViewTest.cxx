// Slice views: reslicing is exact in LPS on an oblique volume; the layers compose as shown
// (window/level, labels filled with opacity, the overlay's |t| threshold and colour map); the
// cursor moves the slice; a click picks the point under the mouse.
#include "BrainShiftTestingSupport.h"
#include "SliceView.h"
#include "SyntheticData.h"

#include <itkImageRegionIteratorWithIndex.h>

#include <QApplication>
#include <QSignalSpy>
#include <QSurfaceFormat>
#include <QTimer>
#include <QTest>

#include <iostream>

namespace {
using namespace brainshift;

double linearField(const PhysicalPoint& p)
{
  return 2.0 * p[0] - p[1] + 0.5 * p[2] + 100.0;
}

template <class TImage, class Value>
void fill(TImage* image, Value value)
{
  itk::ImageRegionIteratorWithIndex<TImage> it(image, image->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint p;
    image->TransformIndexToPhysicalPoint(it.GetIndex(), p);
    it.Set(value(p));
  }
}

PhysicalPoint centreOf(const ImageGeometry& g)
{
  itk::ContinuousIndex<double, 3> middle;
  for (int a = 0; a < 3; ++a) middle[a] = 0.5 * double(g.size[a] - 1);
  auto image = g.allocate<LabelImage>();
  PhysicalPoint p;
  image->TransformContinuousIndexToPhysicalPoint(middle, p);
  return p;
}
} // namespace

int SliceViewTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("SliceViewTest", [] {
    using brainshift::testing::point;
    // An oblique, anisotropic volume whose voxels hold a linear function of their LPS position:
    // every resliced pixel must hold the function at the pixel's LPS point.
    const ImageGeometry oblique = testing::grid({40, 30, 20}, {1.0, 1.5, 2.0}, point(-20, 10, -15), testing::rotationAbout(1, 2, 3, 25));
    auto linear = oblique.allocate<ScalarImage>();
    fill(linear.GetPointer(), [](const PhysicalPoint& p) { return float(linearField(p)); });
    const ResliceableVolume volume(*linear);
    const PhysicalPoint centre = centreOf(oblique);
    for (const SliceOrientation orientation : {SliceOrientation::Axial, SliceOrientation::Sagittal, SliceOrientation::Coronal}) {
      SliceView probe(orientation);
      SlicePlane plane = probe.plane();
      const Vector3 c = plane.planeCoordinates(centre);
      plane.offset = c[2];
      plane.originU = c[0] - 5;
      plane.originV = c[1] - 5;
      plane.spacing = 1.0;
      plane.sizeU = plane.sizeV = 11;
      const auto slice = volume.slice(plane);
      for (int j = 0; j < 11; ++j) {
        for (int i = 0; i < 11; ++i) {
          const PhysicalPoint p = plane.pointAt(plane.originU + i, plane.originV + j);
          const double value = slice->GetScalarComponentAsDouble(i, j, 0, 0);
          BS_CHECK_MSG(std::abs(value - linearField(p)) < 1e-3,
                       toString(orientation).toStdString() << " pixel (" << i << ", " << j << "): " << value << " vs " << linearField(p));
        }
      }
    }

    // Three layers on a 1 mm grid: background 100; labels 2 where x < 10; overlay t = 5 where
    // y < 5, -5 where y > 15, 1 elsewhere (shown as a statistical map: |t| >= 3).
    const ImageGeometry grid = testing::grid({20, 20, 20}, {1, 1, 1}, point(0, 0, 0));
    auto background = ScalarVolumeNode::create("background", testing::makeUniformImage({20, 20, 20}, 100.0f));
    auto labelImage = grid.allocate<LabelImage>();
    fill(labelImage.GetPointer(), [](const PhysicalPoint& p) { return LabelPixel(p[0] < 10 ? 2 : 0); });
    auto labels = LabelMapVolumeNode::create("labels", labelImage);
    auto overlayImage = grid.allocate<ScalarImage>();
    fill(overlayImage.GetPointer(), [](const PhysicalPoint& p) { return p[1] < 5 ? 5.0f : p[1] > 15 ? -5.0f : 1.0f; });
    auto overlay = ScalarVolumeNode::create("fMRI", overlayImage);
    overlay->setDisplay(VolumeDisplay::statisticalMap());

    SliceView view(SliceOrientation::Axial);
    view.resize(300, 300);
    view.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&view));
    view.setBackground(background);
    view.setWindowLevel(200, 100);
    view.setCursorPosition(point(10, 10, 10));
    BS_CHECK(view.cursorPosition() == point(10, 10, 10));
    BS_CHECK_NEAR(view.plane().planeCoordinates(point(3, 4, 10))[2], view.plane().offset, 1e-9);
    auto grey = view.colorAt(point(15, 10, 10));
    BS_CHECK(grey && (*grey)[0] == 128 && (*grey)[1] == 128 && (*grey)[3] == 255);
    BS_CHECK(!view.colorAt(point(15, 10, 12))); // off the slice

    view.setLabelMap(labels);
    view.setLabelOpacity(0.5);
    const auto labelled = view.colorAt(point(5, 10, 10));
    BS_CHECK(labelled);
    BS_CHECK_NEAR((*labelled)[0], 0.5 * 128 + 0.5 * 255 * 0.95, 1.0); // parenchyma's colour, half opaque
    BS_CHECK_NEAR((*labelled)[2], 0.5 * 128 + 0.5 * 255 * 0.60, 1.0);
    BS_CHECK(*view.colorAt(point(15, 10, 10)) == *grey); // label 0 is transparent

    view.setOverlay(overlay);
    BS_CHECK(*view.colorAt(point(15, 10, 10)) == *grey); // |t| = 1: below the threshold
    const auto hot = *view.colorAt(point(15, 2, 10)), cold = *view.colorAt(point(15, 18, 10));
    BS_CHECK_MSG(hot[0] > hot[2] + 40, int(hot[0]) << " " << int(hot[2]));   // t = 5: red side
    BS_CHECK_MSG(cold[2] > cold[0] + 40, int(cold[0]) << " " << int(cold[2])); // t = -5: blue side
    VolumeDisplay hidden = overlay->display();
    hidden.opacity = 0.0;
    overlay->setDisplay(hidden);
    view.updateLayers();
    BS_CHECK(*view.colorAt(point(15, 2, 10)) == *grey);

    // Labels as outlines: the region's edge (x = 9) is coloured, its inside (x = 5) is not.
    view.setLabelOutline(true);
    BS_CHECK(*view.colorAt(point(5, 10, 10)) == *grey);
    BS_CHECK(*view.colorAt(point(9, 10, 10)) == *labelled);
    view.setLabelOutline(false);
    view.setLabelMap(nullptr);

    // Comparison with a volume of 200 on the background's window (level 100, window 200).
    view.setComparison(ScalarVolumeNode::create("warped", testing::makeUniformImage({20, 20, 20}, 200.0f)));
    view.setCheckerSize(10.0);
    view.setComparisonMode(ComparisonMode::Checkerboard);
    // Squares in plane coordinates (u = x, v = -y on the axial slice): (0, -1) and (1, -2) show
    // the comparison, (1, -1) the background.
    BS_CHECK((*view.colorAt(point(5, 5, 10)))[0] == 255);
    BS_CHECK((*view.colorAt(point(15, 5, 10)))[0] == 128);
    BS_CHECK((*view.colorAt(point(15, 15, 10)))[0] == 255);
    view.setComparisonMode(ComparisonMode::Difference);
    BS_CHECK((*view.colorAt(point(5, 5, 10)))[0] == 0); // 100 - 200 = -window/2: black; equal: mid grey
    view.setComparisonMode(ComparisonMode::Flicker);
    view.setFlickerShowsComparison(true);
    BS_CHECK((*view.colorAt(point(5, 5, 10)))[0] == 255);
    QSignalSpy frames(view.findChild<QTimer*>(), &QTimer::timeout);
    BS_CHECK(frames.wait(2000)); // the flicker timer turns it back
    BS_CHECK(!view.flickerShowsComparison() && (*view.colorAt(point(5, 5, 10)))[0] == 128);
    view.setComparisonMode(ComparisonMode::Off);
    BS_CHECK((*view.colorAt(point(5, 5, 10)))[0] == 128);

    // The cursor moves the slice; a click picks the point under the mouse, on the slice.
    view.setCursorPosition(point(10, 10, 4));
    BS_CHECK_NEAR(view.plane().offset, -4.0, 1e-9); // the axial normal is inferior (-S)
    QSignalSpy picked(&view, &SliceView::cursorPicked);
    const PhysicalPoint atCentre = view.pointAtPixel(QPoint(150, 150));
    BS_CHECK_NEAR(atCentre[2], 4.0, 1e-6);
    BS_CHECK_NEAR(atCentre[0], 9.5, 1.0); // the slice's centre (voxel centres 0..19)
    BS_CHECK_NEAR(atCentre[1], 9.5, 1.0);
    // Right of the centre is the patient's left (+L), above it anterior (-P).
    const PhysicalPoint rightUp = view.pointAtPixel(QPoint(250, 50));
    BS_CHECK(rightUp[0] > atCentre[0] + 3 && rightUp[1] < atCentre[1] - 3);
    QTest::mouseClick(&view, Qt::LeftButton, {}, QPoint(250, 50));
    BS_CHECK(picked.count() == 1);
    const auto pickedPoint = picked.first().at(0).value<PhysicalPoint>();
    BS_CHECK(pickedPoint.EuclideanDistanceTo(rightUp) < 1e-6);
    BS_CHECK(view.cursorPosition().EuclideanDistanceTo(rightUp) < 1e-6);
    std::cout << "picked " << pickedPoint << '\n';
  });
}
