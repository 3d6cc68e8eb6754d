// DICOM out, read back by ITK's GDCM reader: an oblique float volume keeps its grid and its values
// within half the rescale slope, labels are exact, the series carries the study, patient and
// Frame of Reference it was given, and a reference series of another patient, or of another grid
// than a NIfTI scan's, is refused.
#include "BrainShiftTestingSupport.h"
#include "DicomSeriesExport.h"
#include "SyntheticData.h"
#include "VolumeIO.h"

#include <itkImageRegionConstIterator.h>

namespace {
double worstDifference(const brainshift::ScalarImage& a, const brainshift::ScalarImage& b)
{
  double worst = 0;
  itk::ImageRegionConstIterator<brainshift::ScalarImage> i(&a, a.GetLargestPossibleRegion());
  itk::ImageRegionConstIterator<brainshift::ScalarImage> j(&b, b.GetLargestPossibleRegion());
  for (; !i.IsAtEnd(); ++i, ++j) worst = std::max(worst, std::abs(static_cast<double>(i.Get()) - j.Get()));
  return worst;
}
} // namespace

int DicomSeriesExportTest(int, char*[])
{
  return brainshift::testing::runTest("DicomSeriesExportTest", [] {
    using namespace brainshift;
    using namespace brainshift::testing;
    const std::filesystem::path folder = temporaryFolder("DicomSeriesExportTest");
    const ImageGeometry g = grid({6, 5, 4}, {0.9, 1.2, 2.5}, point(-30.25, 41.5, -12.125), rotationAbout(1, -2, 3, 20));
    auto image = imageOn<ScalarImage>(g, [](const PhysicalPoint& p) { return static_cast<float>(std::sin(p[0] / 7) * 300 + p[2]); });
    auto labels = imageOn<ScalarImage>(g, [](const PhysicalPoint& p) { return p[1] > 41 ? 4.f : 2.f; });

    DicomStudyContext study = newDicomStudy();
    study.patientName = "Doe^Jane";
    study.patientId = "P-0001";
    const DicomRescale rescale = writeDicomSeries(*image, study, {"BrainShift warped_preop_image", 9001, "test"}, folder / "image");
    BS_CHECK(rescale.slope > 0 && rescale.slope < 1);
    ScalarImage::Pointer back = readDicomSeries(folder / "image");
    BS_CHECK_MSG(ImageGeometry::of(back.GetPointer()).sameGridAs(g, 1e-5), ImageGeometry::of(back.GetPointer()).describe());
    BS_CHECK_MSG(worstDifference(*image, *back) <= rescale.slope / 2 + 1e-4, worstDifference(*image, *back));

    const DicomRescale exact = writeDicomSeries(*labels, study, {"BrainShift warped_preop_labels", 9002, "test"}, folder / "labels");
    BS_CHECK(exact.slope == 1 && exact.intercept == 0);
    BS_CHECK(worstDifference(*labels, *readDicomSeries(folder / "labels")) == 0);

    const DicomStudyContext read = readDicomStudyOf(folder / "image");
    BS_CHECK(read.patientId == "P-0001" && read.patientName == "Doe^Jane");
    BS_CHECK(read.studyInstanceUid == study.studyInstanceUid && read.frameOfReferenceUid == study.frameOfReferenceUid);
    BS_CHECK(newDicomStudy().studyInstanceUid != study.studyInstanceUid);

    // The intraoperative scan as a DICOM series of P-0001: a series of P-0002 is refused, the
    // scan's own series and another of its patient and Frame of Reference are accepted.
    DicomStudyContext other = newDicomStudy();
    other.patientId = "P-0002";
    writeDicomSeries(*labels, other, {"another patient", 1, ""}, folder / "other");
    BS_CHECK_THROWS(checkReferenceFitsUpdate(folder / "other", readDicomStudyOf(folder / "other"), folder / "image"),
                    InputError, "another patient");
    checkReferenceFitsUpdate(folder / "labels", readDicomStudyOf(folder / "labels"), folder / "image");
    // The scan as a NIfTI file: the reference must lie on its grid.
    writeScalarVolume(image, folder / "scan.nii.gz");
    checkReferenceFitsUpdate(folder / "image", read, folder / "scan.nii.gz");
    auto shifted = imageOn<ScalarImage>(grid({6, 5, 4}, {0.9, 1.2, 2.5}, point(0, 0, 0)), [](const PhysicalPoint&) { return 1.f; });
    writeDicomSeries(*shifted, study, {"elsewhere", 2, ""}, folder / "elsewhere");
    BS_CHECK_THROWS(checkReferenceFitsUpdate(folder / "elsewhere", read, folder / "scan.nii.gz"), InputError,
                    "not on the intraoperative scan's grid");
    BS_CHECK_THROWS(readDicomStudyOf(folder), InputError, "no DICOM image file");
  });
}
