// The warped labels as a DICOM Segmentation, read back with DCMTK's reader: one segment per label
// value present with its SNOMED CT type and algorithm BrainShift (AUTOMATIC), frames from the
// segment's first to its last slice at the slices' exact positions, each derived from the source
// series' slice there, the voxels of every segment those of its label, the study and Frame of
// Reference of the source MR series, and a value BrainShift does not know refused.
#include "BrainShiftTestingSupport.h"
#include "DicomSegmentationExport.h"
#include "DicomSegmentationReadBack.h"
#include "DicomSeriesExport.h"
#include "SyntheticData.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

namespace {
/// Labels on `g` (at least 5 columns, 4 rows, 5 slices): head everywhere but the first voxel of each
/// slice, parenchyma in a 3x3 block, ventricles at its centre in slices 2-3, tumour at two voxels
/// of slice 4. `counts[v]` is the number of voxels of value v.
brainshift::ScalarImage::Pointer brainLabels(const brainshift::ImageGeometry& g, std::size_t counts[5])
{
  auto labels = g.allocate<brainshift::ScalarImage>();
  const std::size_t nx = g.size[0], ny = g.size[1];
  for (std::size_t k = 0; k < g.size[2]; ++k)
    for (std::size_t j = 0; j < ny; ++j)
      for (std::size_t i = 0; i < nx; ++i) {
        int value = (i == 0 && j == 0) ? 0 : 1;
        if (i >= 2 && i <= 4 && j >= 1 && j <= 3) value = 2;
        if ((k == 2 || k == 3) && i == 3 && j == 2) value = 3;
        if (k == 4 && i == 2 && j >= 1 && j <= 2) value = 4;
        labels->GetBufferPointer()[(k * ny + j) * nx + i] = static_cast<float>(value);
        ++counts[value];
      }
  return labels;
}

/// The set pixels of each frame, decoded from the file's Pixel Data by PS3.5 8.1.1 (frames back to
/// back, first pixel in the lowest bit), independently of DCMTK's Segmentation reader.
std::vector<std::size_t> setPixelsPerFrame(const std::filesystem::path& file, std::size_t pixelsPerFrame, std::size_t frames)
{
  DcmFileFormat seg;
  const Uint8* bytes = nullptr;
  unsigned long length = 0;
  if (seg.loadFile(file.c_str()).bad() || seg.getDataset()->findAndGetUint8Array(DCM_PixelData, bytes, &length).bad()) return {};
  std::vector<std::size_t> counts(frames, 0);
  for (std::size_t bit = 0; bit < pixelsPerFrame * frames && bit / 8 < length; ++bit)
    counts[bit / pixelsPerFrame] += (bytes[bit / 8] >> (bit % 8)) & 1u;
  return counts;
}
} // namespace

int DicomSegmentationExportTest(int, char*[])
{
  return brainshift::testing::runTest("DicomSegmentationExportTest", [] {
    using namespace brainshift;
    using namespace brainshift::testing;
    BS_CHECK(dicomSegmentationAvailable());
    const std::filesystem::path folder = temporaryFolder("DicomSegmentationExportTest");
    // 8 columns, 5 rows (frames end on a byte: DCMTK 3.6.7's reader unpacks other frames wrongly,
    // see below), 6 slices, oblique.
    const ImageGeometry g = grid({8, 5, 6}, {0.9, 1.2, 2.5}, point(-30.25, 41.5, -12.125), rotationAbout(1, -2, 3, 20));
    std::size_t counts[5] = {};
    auto labels = brainLabels(g, counts);
    DicomStudyContext study = newDicomStudy();
    study.patientName = "Doe^Jane";
    study.patientId = "P-0001";
    auto image = imageOn<ScalarImage>(g, [](const PhysicalPoint& p) { return static_cast<float>(p[0] * 3 + p[2]); });
    writeDicomSeries(*image, study, {"BrainShift warped_preop_image", 9001, "test"}, folder / "image");
    const std::filesystem::path file = folder / "seg.dcm";
    const std::vector<DicomSegmentInfo> written = writeDicomSegmentation(*labels, folder / "image", {"BrainShift labels", 9005, ""}, file);
    BS_CHECK(written.size() == 4 && written[2].label == "ventricles" && written[2].frames == 2 && written[3].frames == 1);

    const ReadBackSegmentation seg = readBackSegmentation(file.string());
    BS_CHECK(seg.modality == "SEG");
    BS_CHECK(seg.studyUid == study.studyInstanceUid && seg.frameOfReferenceUid == study.frameOfReferenceUid);
    BS_CHECK_MSG(seg.segments.size() == 4, seg.segments.size());
    const std::size_t expectedFrames[4] = {6, 6, 2, 1};
    const char* expectedTypes[4] = {"69536005", "12738006", "35764002", "108369006"};
    for (std::size_t s = 0; s < 4; ++s) {
      const ReadBackSegment& segment = seg.segments[s];
      BS_CHECK_MSG(segment.frames == expectedFrames[s], segment.label << ": " << segment.frames << " frames");
      BS_CHECK_MSG(segment.voxels == counts[s + 1], segment.label << ": " << segment.voxels << " voxels, the labels " << counts[s + 1]);
      BS_CHECK(segment.algorithmType == "AUTOMATIC" && segment.algorithmName == "BrainShift");
      BS_CHECK_MSG(segment.typeCode == expectedTypes[s], segment.label << " type " << segment.typeCode);
    }
    BS_CHECK(seg.segments[3].label == "tumour" && seg.segments[3].categoryCode == "49755003");
    // Geometry: the orientation, spacing and each frame's position as the MR slices have them.
    DcmFileFormat slice;
    BS_CHECK(slice.loadFile((folder / "image" / "IM0005.dcm").c_str()).good());
    OFString orientation, spacing, position, instance;
    slice.getDataset()->findAndGetOFStringArray(DCM_ImageOrientationPatient, orientation);
    slice.getDataset()->findAndGetOFStringArray(DCM_PixelSpacing, spacing);
    slice.getDataset()->findAndGetOFStringArray(DCM_ImagePositionPatient, position);
    slice.getDataset()->findAndGetOFString(DCM_SOPInstanceUID, instance);
    BS_CHECK_MSG(seg.orientation == orientation.c_str(), seg.orientation << " vs " << orientation);
    BS_CHECK_MSG(seg.pixelSpacing == spacing.c_str(), seg.pixelSpacing << " vs " << spacing);
    BS_CHECK_MSG(seg.segments[3].positions.at(0) == position.c_str(), seg.segments[3].positions.at(0) << " vs " << position);
    BS_CHECK(seg.segments[3].sourceInstances.at(0) == instance.c_str());
    BS_CHECK(seg.segments[0].positions.at(4) == position.c_str());

    // 7 columns: frames of 35 pixels share bytes. The Pixel Data decoded by the standard's rule
    // holds every frame's pixels (DCMTK 3.6.7 would corrupt them when it packs, BrainShift packs).
    const ImageGeometry odd = grid({7, 5, 6}, {0.9, 1.2, 2.5}, point(-30.25, 41.5, -12.125), rotationAbout(1, -2, 3, 20));
    std::size_t oddCounts[5] = {};
    auto oddLabels = brainLabels(odd, oddCounts);
    auto oddImage = imageOn<ScalarImage>(odd, [](const PhysicalPoint& p) { return static_cast<float>(p[1]); });
    writeDicomSeries(*oddImage, study, {"odd", 9001, "test"}, folder / "odd");
    writeDicomSegmentation(*oddLabels, folder / "odd", {}, folder / "odd.dcm");
    const std::vector<std::size_t> perFrame = setPixelsPerFrame(folder / "odd.dcm", 35, 15);
    const std::vector<std::size_t> expected{25, 25, 25, 25, 25, 25, 9, 9, 8, 8, 7, 9, 1, 1, 2};
    BS_CHECK_MSG(perFrame == expected, "frame 2 has " << (perFrame.size() > 2 ? perFrame[2] : 0) << " set pixels");

    // The whole export: the Segmentation beside the MR series, derived from the warped image's.
    writeScalarVolume(image, folder / "warped_preop_image.nii.gz");
    writeScalarVolume(labels, folder / "warped_preop_labels.nii.gz");
    UpdateFolderContents contents;
    contents.folder = folder;
    contents.intraopImage = folder / "warped_preop_image.nii.gz";
    contents.warpedVolumes = {{"warped_preop_image", folder / "warped_preop_image.nii.gz", false},
                              {"warped_preop_labels", folder / "warped_preop_labels.nii.gz", true}};
    const DicomExportResult exported = exportUpdateToDicom(contents, folder / "export", std::nullopt);
    BS_CHECK(exported.seriesFolders.size() == 3 && exported.seriesFolders[2] == "warped_preop_labels_seg");
    const ReadBackSegmentation again = readBackSegmentation((folder / "export/warped_preop_labels_seg/SEG0001.dcm").string());
    BS_CHECK(again.segments.size() == 4 && again.frameOfReferenceUid == exported.study.frameOfReferenceUid);
    DcmFileFormat first;
    BS_CHECK(first.loadFile((folder / "export/warped_preop_image/IM0001.dcm").c_str()).good());
    first.getDataset()->findAndGetOFString(DCM_SOPInstanceUID, instance);
    BS_CHECK(again.segments[0].sourceInstances.at(0) == instance.c_str());

    // A value that is no BrainShift label: refused naming the labels' file, nothing exported.
    labels->GetBufferPointer()[3] = 7;
    BS_CHECK_THROWS(writeDicomSegmentation(*labels, folder / "image", {}, folder / "bad.dcm"), InputError, "label value 7");
    BS_CHECK(!std::filesystem::exists(folder / "bad.dcm"));
    writeScalarVolume(labels, folder / "warped_preop_labels.nii.gz");
    BS_CHECK_THROWS(exportUpdateToDicom(contents, folder / "refused", std::nullopt), InputError,
                    (folder / "warped_preop_labels.nii.gz").string() + ": label value 7");
    BS_CHECK(std::filesystem::is_empty(folder / "refused"));
  });
}
