// Loads into the host: a volume, then bad input that must leave the scene and the views as they
// were (a file that is not an image, a label map on another grid, a scene with a missing file);
// a label map, an overlay, the linked cursor and its readout; a scene saved and read back.
#include "BrainShiftTestingSupport.h"
#include "HostMainWindow.h"
#include "OrientationPhantom.h"
#include "SyntheticData.h"
#include "VolumeIO.h"

#include <itkImageRegionIteratorWithIndex.h>

#include <QApplication>
#include <QComboBox>
#include <QSurfaceFormat>
#include <QTest>

#include <fstream>
#include <iostream>

namespace {
using namespace brainshift;

QString q(const std::filesystem::path& p)
{
  return QString::fromStdString(p.string());
}
} // namespace

int HostLoadTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("HostLoadTest", [] {
    using testing::point;
    registerIOFactories();
    const auto folder = testing::temporaryFolder("HostLoadTest");
    const ImageGeometry grid = testing::grid({24, 20, 16}, {1.0, 1.0, 2.0}, point(-10, -8, -12));
    writeScalarVolume(testing::imageOn<ScalarImage>(grid, [](const PhysicalPoint& p) { return float(50 + p[0]); }), folder / "t1.nii.gz");
    writeLabelVolume(testing::imageOn<LabelImage>(grid, [](const PhysicalPoint& p) { return LabelPixel(p[1] < 0 ? 2 : 0); }), folder / "labels.nii.gz");
    const ImageGeometry otherGrid = testing::grid({12, 10, 8}, {2.0, 2.0, 4.0}, point(-10, -8, -12));
    writeLabelVolume(testing::imageOn<LabelImage>(otherGrid, [](const PhysicalPoint&) { return LabelPixel(2); }), folder / "coarse_labels.nii.gz");
    writeScalarVolume(testing::imageOn<ScalarImage>(grid, [](const PhysicalPoint& p) { return float(p[2] > 0 ? 6 : -6); }), folder / "tmap.nrrd");
    std::ofstream(folder / "notes.nii.gz") << "surgical notes, not an image\n";

    HostMainWindow host(QString::fromStdString((folder / "no-modules").string()));
    host.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&host));
    ViewLayout& views = *host.views();
    SliceView& axial = *views.sliceView(SliceOrientation::Axial);

    BS_CHECK_MSG(host.loadVolume(q(folder / "t1.nii.gz")).isEmpty(), host.lastMessage().toStdString());
    BS_CHECK(host.scene().nodes().size() == 1);
    const auto t1 = host.scene().findByName<ScalarVolumeNode>("t1");
    BS_CHECK(t1 && axial.background() == t1);
    BS_CHECK(views.sliceView(SliceOrientation::Coronal)->background() == t1);

    // Not an image: a message naming the file; the scene and the views unchanged.
    const QString notAnImage = host.loadVolume(q(folder / "notes.nii.gz"));
    std::cout << "not an image: " << notAnImage.toStdString() << '\n';
    BS_CHECK(notAnImage.contains("notes.nii.gz"));
    BS_CHECK(host.lastMessage() == notAnImage);
    BS_CHECK(host.scene().nodes().size() == 1 && axial.background() == t1 && t1->image());
    BS_CHECK(!host.loadVolume(q(folder / "missing.nii.gz")).isEmpty());
    BS_CHECK(host.scene().nodes().size() == 1);

    // A label map on another grid is refused; on the volume's grid it is shown.
    const QString otherGridError = host.loadLabelMap(q(folder / "coarse_labels.nii.gz"));
    std::cout << "another grid: " << otherGridError.toStdString() << '\n';
    BS_CHECK(otherGridError.contains("coarse_labels.nii.gz") && otherGridError.contains("grid"));
    BS_CHECK(host.scene().nodes().size() == 1 && !axial.labelMap());
    BS_CHECK_MSG(host.loadLabelMap(q(folder / "labels.nii.gz")).isEmpty(), host.lastMessage().toStdString());
    BS_CHECK(axial.labelMap() && axial.labelMap()->name() == "labels");

    // An overlay with negative values is a statistical map.
    BS_CHECK_MSG(host.loadOverlay(q(folder / "tmap.nrrd")).isEmpty(), host.lastMessage().toStdString());
    BS_CHECK(axial.overlay() && axial.overlay()->role() == "overlay");
    BS_CHECK(axial.overlay()->display().lowerThreshold == 3.0);
    BS_CHECK(axial.background() == t1);

    // The linked cursor: a point picked in one view moves the others; the readout names every layer.
    const PhysicalPoint p = point(2, -3, 4);
    emit views.sliceView(SliceOrientation::Sagittal)->cursorPicked(p);
    for (auto orientation : {SliceOrientation::Axial, SliceOrientation::Sagittal, SliceOrientation::Coronal}) {
      BS_CHECK(views.sliceView(orientation)->cursorPosition() == p);
    }
    const auto values = views.valuesAtCursor();
    BS_CHECK(values.size() == 3);
    BS_CHECK_NEAR(*values[0].value, 52.0, 1e-3); // 50 + x
    BS_CHECK(*values[1].value == 2.0);          // y < 0
    BS_CHECK(*values[2].value == 6.0);          // z > 0
    std::cout << "readout: " << views.readoutText().toStdString() << '\n';
    BS_CHECK(views.readoutText().startsWith("LPS (2.0, -3.0, 4.0) mm") && views.readoutText().contains("labels 2"));
    // The comparison volume is read out while a comparison is shown.
    BS_CHECK(host.dataPanel()->comparisonSelector()->setCurrentNodeId(QString::fromStdString(t1->id())));
    host.dataPanel()->comparisonModeBox()->setCurrentIndex(int(ComparisonMode::Difference));
    BS_CHECK(axial.comparisonMode() == ComparisonMode::Difference && axial.comparison() == t1);
    BS_CHECK(views.valuesAtCursor().size() == 4);
    host.dataPanel()->comparisonModeBox()->setCurrentIndex(int(ComparisonMode::Off));
    BS_CHECK(views.valuesAtCursor().size() == 3);
    views.setCursorPosition(point(100, 0, 0));
    BS_CHECK(views.readoutText().contains("t1 outside"));

    // A DICOM series (a folder) loads as a volume with its geometry; one with a missing slice is refused.
    auto t1Image = readScalarVolume(folder / "t1.nii.gz");
    testing::writeDicomSeries(t1Image, folder / "dicom");
    testing::writeDicomSeries(t1Image, folder / "dicom-gap", 5);
    const std::size_t before = host.scene().nodes().size();
    BS_CHECK_MSG(host.loadVolume(q(folder / "dicom")).isEmpty(), host.lastMessage().toStdString());
    const auto dicom = std::dynamic_pointer_cast<ScalarVolumeNode>(host.scene().nodes().back());
    BS_CHECK(dicom && host.scene().nodes().size() == before + 1);
    BS_CHECK(ImageGeometry::of(dicom->image()).sameGridAs(grid));
    const QString gap = host.loadVolume(q(folder / "dicom-gap"));
    std::cout << "DICOM with a gap: " << gap.toStdString() << '\n';
    BS_CHECK(gap.contains("dicom-gap") && host.scene().nodes().size() == before + 1);
    host.scene().remove(dicom->id());
    BS_CHECK(host.dataPanel()->backgroundSelector()->setCurrentNodeId(QString::fromStdString(t1->id())));

    // Layouts: one-up shows one view.
    views.setArrangement(ViewArrangement::OneUp3D);
    BS_CHECK(views.threeDView()->isVisible() && !axial.isVisible());
    views.setArrangement(ViewArrangement::FourUp);
    BS_CHECK(axial.isVisible());

    // Save, and read back into another host.
    BS_CHECK_MSG(host.saveScene(q(folder / "scene" / "case.mrml")).isEmpty(), host.lastMessage().toStdString());
    HostMainWindow reader(QString::fromStdString((folder / "no-modules").string()));
    BS_CHECK_MSG(reader.loadScene(q(folder / "scene" / "case.mrml")).isEmpty(), reader.lastMessage().toStdString());
    BS_CHECK(reader.scene().nodes().size() == 3);
    BS_CHECK(reader.views()->sliceView(SliceOrientation::Axial)->background());

    // A scene whose data file is missing: refused, naming the file; the reader's scene intact.
    std::filesystem::copy_file(folder / "scene" / "case.mrml", folder / "scene" / "broken.mrml");
    std::string text;
    {
      std::ifstream in(folder / "scene" / "broken.mrml");
      text.assign(std::istreambuf_iterator<char>(in), {});
    }
    const auto at = text.find("t1.nii.gz");
    BS_CHECK(at != std::string::npos);
    text.replace(at, 9, "gone.nii.gz");
    std::ofstream(folder / "scene" / "broken.mrml") << text;
    const QString missing = reader.loadScene(q(folder / "scene" / "broken.mrml"));
    std::cout << "missing file: " << missing.toStdString() << '\n';
    BS_CHECK(missing.contains("gone.nii.gz"));
    BS_CHECK(reader.scene().nodes().size() == 3);
  });
}
