#include "DicomSeriesExport.h"

#include "BrainShiftErrors.h"
#include "DicomSegmentationExport.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dctk.h>
#include <dcmtk/dcmdata/dcuid.h>

#include <itkImageRegionConstIterator.h>

#include <algorithm>
#include <functional>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <unistd.h>

namespace brainshift {
namespace fs = std::filesystem;

std::string dicomDecimalString(double value)
{
  if (std::abs(value) < 1e-12) value = 0;
  char text[64];
  for (int digits = 15; digits > 1; --digits) {
    std::snprintf(text, sizeof text, "%.*g", digits, value);
    if (std::strlen(text) <= 16) return text;
  }
  std::snprintf(text, sizeof text, "%.1g", value);
  return text;
}

namespace {

std::string dateTime(const char* format)
{
  const std::time_t now = std::time(nullptr);
  std::tm local{};
  localtime_r(&now, &local);
  char text[32];
  std::strftime(text, sizeof text, format, &local);
  return text;
}

std::string newUid(const char* root)
{
  char uid[100];
  dcmGenerateUniqueIdentifier(uid, root);
  return uid;
}

void put(DcmDataset& data, const DcmTagKey& tag, const std::string& value)
{
  const OFCondition status = data.putAndInsertString(tag, value.c_str());
  if (status.bad()) throw std::runtime_error(std::string("DCMTK cannot set ") + DcmTag(tag).getTagName() + ": " + status.text());
}

std::string get(DcmDataset& data, const DcmTagKey& tag)
{
  OFString value;
  if (data.findAndGetOFStringArray(tag, value).bad()) return {};
  return value.c_str();
}

DicomRescale rescaleFor(const ScalarImage& image)
{
  float low = std::numeric_limits<float>::max(), high = std::numeric_limits<float>::lowest();
  bool integers = true;
  itk::ImageRegionConstIterator<ScalarImage> it(&image, image.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    const float v = it.Get();
    low = std::min(low, v);
    high = std::max(high, v);
    integers = integers && v == std::round(v);
  }
  DicomRescale rescale;
  if (integers && high - low <= 65535) {
    rescale.intercept = low >= 0 && high <= 65535 ? 0.0 : static_cast<double>(low);
    return rescale;
  }
  // Parse the decimal strings back: the file's values are what a reader will apply.
  rescale.slope = std::stod(dicomDecimalString(high > low ? (static_cast<double>(high) - low) / 65535.0 : 1.0));
  rescale.intercept = std::stod(dicomDecimalString(low));
  return rescale;
}

void putStudy(DcmDataset& data, const DicomStudyContext& study)
{
  if (!study.specificCharacterSet.empty()) put(data, DCM_SpecificCharacterSet, study.specificCharacterSet);
  put(data, DCM_PatientName, study.patientName);
  put(data, DCM_PatientID, study.patientId);
  put(data, DCM_PatientBirthDate, study.patientBirthDate);
  put(data, DCM_PatientSex, study.patientSex);
  put(data, DCM_StudyInstanceUID, study.studyInstanceUid);
  put(data, DCM_StudyDate, study.studyDate);
  put(data, DCM_StudyTime, study.studyTime);
  put(data, DCM_StudyID, study.studyId);
  put(data, DCM_AccessionNumber, study.accessionNumber);
  put(data, DCM_ReferringPhysicianName, study.referringPhysicianName);
  if (!study.studyDescription.empty()) put(data, DCM_StudyDescription, study.studyDescription);
  put(data, DCM_FrameOfReferenceUID, study.frameOfReferenceUid);
  put(data, DCM_PositionReferenceIndicator, "");
}

/// The attributes every slice of a series shares.
void putSeries(DcmDataset& data, const DicomSeriesDescription& series, const std::string& seriesUid,
               const ImageGeometry& geometry, const DicomRescale& rescale)
{
  put(data, DCM_SOPClassUID, UID_MRImageStorage);
  put(data, DCM_ImageType, "DERIVED\\SECONDARY\\OTHER");
  put(data, DCM_Modality, "MR");
  put(data, DCM_Manufacturer, "BrainShift");
  put(data, DCM_SoftwareVersions, "brainshift 0.1.0");
  put(data, DCM_SeriesInstanceUID, seriesUid);
  put(data, DCM_SeriesNumber, std::to_string(series.seriesNumber));
  put(data, DCM_SeriesDescription, series.description);
  put(data, DCM_BodyPartExamined, "HEAD"); // not a paired body part: no Laterality
  put(data, DCM_PatientPosition, ""); // type 2C for MR, empty: unknown to the update
  put(data, DCM_SeriesDate, dateTime("%Y%m%d"));
  put(data, DCM_SeriesTime, dateTime("%H%M%S"));
  put(data, DCM_ContentDate, dateTime("%Y%m%d"));
  put(data, DCM_ContentTime, dateTime("%H%M%S"));
  if (!series.derivation.empty()) put(data, DCM_DerivationDescription, series.derivation);
  put(data, DCM_ScanningSequence, "RM");
  put(data, DCM_SequenceVariant, "NONE");
  put(data, DCM_ScanOptions, "");
  put(data, DCM_MRAcquisitionType, "3D");
  put(data, DCM_RepetitionTime, "");
  put(data, DCM_EchoTime, "");
  put(data, DCM_EchoTrainLength, "");
  put(data, DCM_PixelSpacing, dicomDecimalString(geometry.spacing[1]) + "\\" + dicomDecimalString(geometry.spacing[0]));
  std::string orientation;
  for (int axis = 0; axis < 2; ++axis)
    for (int r = 0; r < 3; ++r) orientation += (orientation.empty() ? "" : "\\") + dicomDecimalString(geometry.direction[r][axis]);
  put(data, DCM_ImageOrientationPatient, orientation);
  put(data, DCM_SliceThickness, dicomDecimalString(geometry.spacing[2]));
  put(data, DCM_SpacingBetweenSlices, dicomDecimalString(geometry.spacing[2]));
  put(data, DCM_SamplesPerPixel, "1");
  put(data, DCM_PhotometricInterpretation, "MONOCHROME2");
  put(data, DCM_Rows, std::to_string(geometry.size[1]));
  put(data, DCM_Columns, std::to_string(geometry.size[0]));
  put(data, DCM_BitsAllocated, "16");
  put(data, DCM_BitsStored, "16");
  put(data, DCM_HighBit, "15");
  put(data, DCM_PixelRepresentation, "0");
  put(data, DCM_RescaleIntercept, dicomDecimalString(rescale.intercept));
  put(data, DCM_RescaleSlope, dicomDecimalString(rescale.slope));
}

/// A display window over the whole range of the values (VOI LUT module).
void putWindow(DcmDataset& data, const std::pair<double, double>& range)
{
  put(data, DCM_WindowCenter, dicomDecimalString((range.first + range.second) / 2));
  put(data, DCM_WindowWidth, dicomDecimalString(std::max(1.0, range.second - range.first)));
}
} // namespace

DicomStudyContext newDicomStudy()
{
  DicomStudyContext study;
  study.studyInstanceUid = newUid(SITE_STUDY_UID_ROOT);
  study.frameOfReferenceUid = newUid(SITE_INSTANCE_UID_ROOT);
  study.studyDate = dateTime("%Y%m%d");
  study.studyTime = dateTime("%H%M%S");
  study.studyId = "BRAINSHIFT";
  study.studyDescription = "BrainShift update";
  return study;
}

DicomStudyContext readDicomStudyOf(const fs::path& seriesFolder)
{
  std::error_code ec;
  if (!fs::is_directory(seriesFolder, ec)) throw InputError(seriesFolder.string() + ": not a folder of DICOM files");
  std::optional<DicomStudyContext> study;
  for (const fs::directory_entry& entry : fs::directory_iterator(seriesFolder)) {
    if (!entry.is_regular_file()) continue;
    DcmFileFormat file;
    if (file.loadFile(entry.path().c_str()).bad()) continue;
    DcmDataset& data = *file.getDataset();
    if (get(data, DCM_SOPInstanceUID).empty()) continue; // a DICOMDIR or other non-image object
    DicomStudyContext found;
    found.specificCharacterSet = get(data, DCM_SpecificCharacterSet);
    found.patientName = get(data, DCM_PatientName);
    found.patientId = get(data, DCM_PatientID);
    found.patientBirthDate = get(data, DCM_PatientBirthDate);
    found.patientSex = get(data, DCM_PatientSex);
    found.studyInstanceUid = get(data, DCM_StudyInstanceUID);
    found.studyDate = get(data, DCM_StudyDate);
    found.studyTime = get(data, DCM_StudyTime);
    found.studyId = get(data, DCM_StudyID);
    found.accessionNumber = get(data, DCM_AccessionNumber);
    found.referringPhysicianName = get(data, DCM_ReferringPhysicianName);
    found.studyDescription = get(data, DCM_StudyDescription);
    found.frameOfReferenceUid = get(data, DCM_FrameOfReferenceUID);
    found.sourceSeriesInstanceUid = get(data, DCM_SeriesInstanceUID);
    if (found.studyInstanceUid.empty() || found.frameOfReferenceUid.empty()) {
      throw InputError(entry.path().string() + ": a DICOM file without StudyInstanceUID or FrameOfReferenceUID");
    }
    if (!study) {
      study = found;
    } else if (found.patientId != study->patientId || found.patientName != study->patientName) {
      throw InputError(seriesFolder.string() + ": holds files of several patients ('" + study->patientId + "', '" +
                       found.patientId + "')");
    } else if (found.studyInstanceUid != study->studyInstanceUid ||
               found.frameOfReferenceUid != study->frameOfReferenceUid) {
      throw InputError(seriesFolder.string() + ": holds files of several studies or Frames of Reference");
    }
  }
  if (!study) throw InputError(seriesFolder.string() + ": holds no DICOM image file");
  return *study;
}

DicomRescale writeDicomSeries(const ScalarImage& image, const DicomStudyContext& study,
                              const DicomSeriesDescription& series, const fs::path& folder)
{
  const ImageGeometry geometry = ImageGeometry::of(&image);
  const DicomRescale rescale = rescaleFor(image);
  const float* first = image.GetBufferPointer();
  const auto [low, high] = std::minmax_element(first, first + geometry.numberOfVoxels());
  const std::pair<double, double> range{*low, *high};
  const std::string seriesUid = newUid(SITE_SERIES_UID_ROOT);
  fs::create_directories(folder);
  const std::size_t columns = geometry.size[0], rows = geometry.size[1];
  std::vector<Uint16> stored(columns * rows);
  const float* values = image.GetBufferPointer();
  for (std::size_t k = 0; k < geometry.size[2]; ++k) {
    DcmFileFormat file;
    DcmDataset& data = *file.getDataset();
    putStudy(data, study);
    putSeries(data, series, seriesUid, geometry, rescale);
    putWindow(data, range);
    put(data, DCM_SOPInstanceUID, newUid(SITE_INSTANCE_UID_ROOT));
    put(data, DCM_InstanceNumber, std::to_string(k + 1));
    std::string position;
    for (int r = 0; r < 3; ++r) {
      const double p = geometry.origin[r] + geometry.direction[r][2] * geometry.spacing[2] * static_cast<double>(k);
      position += (r ? "\\" : "") + dicomDecimalString(p);
    }
    put(data, DCM_ImagePositionPatient, position);
    const float* slice = values + k * columns * rows;
    for (std::size_t v = 0; v < columns * rows; ++v) {
      const double s = std::round((slice[v] - rescale.intercept) / rescale.slope);
      stored[v] = static_cast<Uint16>(std::clamp(s, 0.0, 65535.0));
    }
    OFCondition status = data.putAndInsertUint16Array(DCM_PixelData, stored.data(), static_cast<unsigned long>(stored.size()));
    char name[32];
    std::snprintf(name, sizeof name, "IM%04zu.dcm", k + 1);
    if (status.good()) status = file.saveFile((folder / name).c_str(), EXS_LittleEndianExplicit);
    if (status.bad()) throw std::runtime_error("cannot write " + (folder / name).string() + ": " + status.text());
  }
  return rescale;
}

void checkReferenceFitsUpdate(const fs::path& reference, const DicomStudyContext& referenceStudy,
                              const fs::path& intraopImage)
{
  std::error_code ec;
  if (fs::is_directory(intraopImage, ec)) {
    if (fs::equivalent(reference, intraopImage, ec)) return;
    const DicomStudyContext scan = readDicomStudyOf(intraopImage);
    if (scan.patientId != referenceStudy.patientId || scan.patientName != referenceStudy.patientName) {
      throw InputError(reference.string() + ": a series of another patient (PatientID '" + referenceStudy.patientId +
                       "'; the intraoperative scan " + intraopImage.string() + " is of '" + scan.patientId + "')");
    }
    if (scan.frameOfReferenceUid != referenceStudy.frameOfReferenceUid) {
      throw InputError(reference.string() + ": its Frame of Reference is not the intraoperative scan's (" +
                       intraopImage.string() + "); the update's coordinates are the scan's");
    }
    return;
  }
  // A scan given as a file carries no patient: the reference must be the series it came from.
  const ImageGeometry scanGrid = ImageGeometry::of(readScalarVolume(intraopImage).GetPointer());
  const ImageGeometry referenceGrid = ImageGeometry::of(readDicomSeries(reference).GetPointer());
  if (!scanGrid.sameGridAs(referenceGrid, 1e-3)) {
    throw InputError(reference.string() + ": not on the intraoperative scan's grid (" + referenceGrid.describe() +
                     "; the scan " + intraopImage.string() + " has " + scanGrid.describe() + "); give the DICOM series the scan was converted from, of the same patient");
  }
}

namespace {
ScalarImage::Pointer displacementMagnitude(const fs::path& fieldPath)
{
  DisplacementFieldImage::Pointer field = readDisplacementField(fieldPath);
  auto magnitude = ImageGeometry::of(field.GetPointer()).allocate<ScalarImage>();
  itk::ImageRegionConstIterator<DisplacementFieldImage> in(field, field->GetLargestPossibleRegion());
  float* out = magnitude->GetBufferPointer();
  for (; !in.IsAtEnd(); ++in, ++out) *out = static_cast<float>(in.Get().GetNorm());
  return magnitude;
}

struct SeriesToWrite {
  std::string folder;
  fs::path source; ///< the file the values come from
  DicomSeriesDescription description;
  std::function<ScalarImage::Pointer()> load;
};

std::vector<SeriesToWrite> seriesOf(const UpdateFolderContents& contents)
{
  std::vector<SeriesToWrite> list;
  int number = 9001; // away from the scanner's own series numbers in a shared study
  for (const UpdateVolume& volume : contents.warpedVolumes) {
    const fs::path path = volume.path;
    list.push_back({volume.name, path,
                    {"BrainShift " + volume.name, number++,
                     "preoperative volume warped onto the intraoperative scan by BrainShift's biomechanical update" +
                       std::string(volume.isLabelMap ? " (labels, nearest neighbour)" : "")},
                    [path] { return readScalarVolume(path); }});
  }
  if (contents.displacementField) {
    const fs::path path = *contents.displacementField;
    list.push_back({"displacement_magnitude_mm", path,
                    {"BrainShift displacement magnitude (mm)", number++,
                     "length of the brain shift displacement at each intraoperative voxel, mm"},
                    [path] { return displacementMagnitude(path); }});
  }
  if (contents.uncertainty) {
    const fs::path path = *contents.uncertainty;
    list.push_back({"displacement_uncertainty_mm", path,
                    {"BrainShift displacement uncertainty (mm)", number++,
                     "expected error of the brain shift displacement at each intraoperative voxel, mm"},
                    [path] { return readScalarVolume(path); }});
  }
  return list;
}

constexpr const char* kLabelsVolume = "warped_preop_labels";
constexpr const char* kWarpedImageVolume = "warped_preop_image";
constexpr const char* kSegmentationFolder = "warped_preop_labels_seg";
constexpr const char* kSegmentationFile = "SEG0001.dcm";

/// Removes the staging folder unless it was emptied into place.
struct StagingFolder {
  fs::path path;
  ~StagingFolder()
  {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};
} // namespace

DicomExportResult exportUpdateToDicom(const UpdateFolderContents& contents, const fs::path& target,
                                      const std::optional<fs::path>& referenceSeries)
{
  DicomExportResult result;
  std::error_code ec;
  if (referenceSeries) {
    result.referenceSeries = *referenceSeries;
    result.study = readDicomStudyOf(*referenceSeries);
    checkReferenceFitsUpdate(*referenceSeries, result.study, contents.intraopImage);
  } else if (fs::is_directory(contents.intraopImage, ec)) {
    result.referenceSeries = contents.intraopImage;
    result.study = readDicomStudyOf(contents.intraopImage);
  } else {
    result.study = newDicomStudy();
  }
  result.fromReference = !result.referenceSeries.empty();
  const std::vector<SeriesToWrite> series = seriesOf(contents);
  std::vector<std::string> folders;
  for (const SeriesToWrite& s : series) folders.push_back(s.folder);
  if (dicomSegmentationAvailable()) folders.push_back(kSegmentationFolder);
  for (const std::string& folder : folders) {
    if (fs::exists(target / folder, ec)) {
      throw InputError((target / folder).string() + ": exists already; export into a new folder");
    }
  }
  if (fs::exists(target, ec) && !fs::is_directory(target, ec)) throw InputError(target.string() + ": not a folder");
  fs::create_directories(target);
  StagingFolder staging{target / (".brainshift-export-" + std::to_string(::getpid()))};
  fs::remove_all(staging.path, ec);
  ScalarImage::Pointer labels;
  fs::path labelsPath;
  std::optional<ImageGeometry> warpedImageGrid;
  for (const SeriesToWrite& s : series) {
    ScalarImage::Pointer image = s.load();
    writeDicomSeries(*image, result.study, s.description, staging.path / s.folder);
    result.files += static_cast<int>(image->GetLargestPossibleRegion().GetSize()[2]);
    result.seriesFolders.push_back(s.folder);
    if (s.folder == kLabelsVolume) {
      labels = image;
      labelsPath = s.source;
    }
    if (s.folder == kWarpedImageVolume) warpedImageGrid = ImageGeometry::of(image.GetPointer());
  }
  if (labels && dicomSegmentationAvailable()) {
    // The labels' own MR series stays for systems that read no Segmentation.
    const bool onImageGrid = warpedImageGrid && warpedImageGrid->sameGridAs(ImageGeometry::of(labels.GetPointer()));
    fs::create_directories(staging.path / kSegmentationFolder);
    writeDicomSegmentation(*labels, staging.path / (onImageGrid ? kWarpedImageVolume : kLabelsVolume),
                           {"BrainShift " + std::string(kLabelsVolume) + " (segmentation)", 9001 + static_cast<int>(series.size()),
                            labelsPath.string()},
                           staging.path / kSegmentationFolder / kSegmentationFile);
    result.files += 1;
    result.seriesFolders.push_back(kSegmentationFolder);
  }
  for (const std::string& folder : result.seriesFolders) fs::rename(staging.path / folder, target / folder);
  return result;
}

} // namespace brainshift
