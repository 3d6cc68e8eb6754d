#pragma once
// DICOM out (DCMTK): the update's volumes as derived MR image series that a navigation workstation
// (Brainlab, StealthStation) imports and fuses with the intraoperative scan. One file per slice,
// MR Image Storage, explicit VR little endian. Geometry exact (ImagePositionPatient per slice,
// ImageOrientationPatient, PixelSpacing, SliceThickness); real values through RescaleSlope and
// RescaleIntercept over unsigned 16-bit stored values (integer volumes such as labels are stored
// as they are). The series share one study and one Frame of Reference: the intraoperative scan's
// when it came from DICOM or a reference series is given, otherwise new ones.
#include "ImageTypes.h"

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace brainshift {

struct UpdateFolderContents;

/// A DICOM decimal string (VR DS, at most 16 characters) that parses back as close to `value` as
/// 16 characters allow.
std::string dicomDecimalString(double value);

/// The patient, study and Frame of Reference a series goes into.
struct DicomStudyContext {
  std::string specificCharacterSet; ///< copied from a reference; empty: ASCII
  std::string patientName, patientId, patientBirthDate, patientSex;
  std::string studyInstanceUid, studyDate, studyTime, studyId, accessionNumber, referringPhysicianName,
    studyDescription;
  std::string frameOfReferenceUid;
  std::string sourceSeriesInstanceUid; ///< the reference series, when there is one
};

/// New study and Frame of Reference UIDs (DCMTK's generator), today's date, no patient.
DicomStudyContext newDicomStudy();

/// The patient, study and Frame of Reference of the DICOM files in `seriesFolder`. InputError naming
/// the folder when it holds no DICOM file, or files of several patients, studies or Frames of Reference.
DicomStudyContext readDicomStudyOf(const std::filesystem::path& seriesFolder);

/// What a series is.
struct DicomSeriesDescription {
  std::string description;  ///< SeriesDescription, e.g. "BrainShift warped_preop_image"
  int seriesNumber = 1;
  std::string derivation;   ///< DerivationDescription: how the values were made
};

/// How the values were stored: real value = slope * stored + intercept.
struct DicomRescale {
  double slope = 1, intercept = 0;
};

/// Writes `image` as one series into `folder` (created; files IM0001.dcm, ...). Returns the
/// rescale used; a value differs from the stored real value by at most slope / 2.
DicomRescale writeDicomSeries(const ScalarImage& image, const DicomStudyContext& study,
                              const DicomSeriesDescription& series, const std::filesystem::path& folder);

/// Checks that `reference` may lend its patient, study and Frame of Reference to an update
/// computed on `intraopImage` (a NIfTI file or a DICOM series folder): a series of the same
/// patient and Frame of Reference as a DICOM intraoperative scan, or, for a scan given as a file,
/// a series on the scan's very grid (the series it was converted from). InputError otherwise.
void checkReferenceFitsUpdate(const std::filesystem::path& reference, const DicomStudyContext& referenceStudy,
                              const std::filesystem::path& intraopImage);

struct DicomExportResult {
  DicomStudyContext study;
  bool fromReference = false;              ///< study and Frame of Reference came from a reference series
  std::filesystem::path referenceSeries;   ///< the series they came from
  std::vector<std::string> seriesFolders;  ///< below the target folder, one per series
  int files = 0;
};

/// Exports the update in `contents` into `target`: a folder per series (warped volumes,
/// displacement_magnitude_mm where the displacement field is present, displacement_uncertainty_mm
/// where present; warped_preop_labels also as a DICOM Segmentation, warped_preop_labels_seg/SEG0001.dcm,
/// when DCMTK's dcmseg is available, derived from the warped_preop_image series). The reference is
/// `referenceSeries`, else the intraoperative scan when it is a DICOM series folder, else none (new UIDs).
/// Everything is written into a hidden staging folder inside `target` and renamed into place at the
/// end: a failure leaves nothing in `target`.
/// InputError (nothing written) when a series folder exists already in `target`, or the reference
/// does not fit the update.
DicomExportResult exportUpdateToDicom(const UpdateFolderContents& contents, const std::filesystem::path& target,
                                      const std::optional<std::filesystem::path>& referenceSeries);

} // namespace brainshift
