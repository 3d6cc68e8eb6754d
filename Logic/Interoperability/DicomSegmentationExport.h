#pragma once
// DICOM out (DCMTK dcmseg): the warped labels as a binary DICOM Segmentation (SEG) object, for a
// navigation workstation or 3D Slicer that reads segments rather than an MR series of label values.
// One segment per label value present (1 head, 2 parenchyma, 3 ventricles, 4 tumour) with SNOMED CT
// property category and type (DICOM PS3.16 CID 7150/7151), algorithm type AUTOMATIC named
// BrainShift; one frame per slice from the segment's first to its last slice. The patient, study
// and Frame of Reference are the source series' (the warped image's MR series, written beside it);
// each frame is derived from that series' slice at the same position. Geometry exact: the plane
// orientation and pixel measures in the shared functional groups, the plane position per frame.
#include "ImageTypes.h"

#include <filesystem>
#include <string>
#include <vector>

namespace brainshift {

/// True when BrainShift was built with DCMTK's dcmseg (Debian's libdcmtk-dev has it).
bool dicomSegmentationAvailable();

/// What the Segmentation series is.
struct DicomSegmentationDescription {
  std::string description = "BrainShift warped_preop_labels"; ///< SeriesDescription
  int seriesNumber = 1;
  std::string labelsSource; ///< where the labels came from, named by a label value error (default: the file)
};

/// The segments written: the label value and the number of frames of each.
struct DicomSegmentInfo {
  int labelValue = 0;
  std::string label; ///< SegmentLabel, e.g. "tumour"
  int frames = 0;
};

/// Writes `labels` (values 0..4, on the grid of the MR series in `sourceSeriesFolder`, whose files
/// IM0001.dcm... are its slices in order) as a binary Segmentation into `file`. InputError naming
/// the labels' source when a value is not a label BrainShift knows, or the file when the labels hold
/// none or the source series does not fit the grid;
/// std::runtime_error naming the file when DCMTK refuses the object.
std::vector<DicomSegmentInfo> writeDicomSegmentation(const ScalarImage& labels,
                                                     const std::filesystem::path& sourceSeriesFolder,
                                                     const DicomSegmentationDescription& description,
                                                     const std::filesystem::path& file);

} // namespace brainshift
