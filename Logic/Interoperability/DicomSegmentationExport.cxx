#include "DicomSegmentationExport.h"

#include "BrainShiftErrors.h"
#include "DicomSeriesExport.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dctk.h>
#include <dcmtk/dcmdata/dcuid.h>

#ifdef BRAINSHIFT_HAVE_DCMSEG
#include <dcmtk/dcmfg/fgderimg.h>
#include <dcmtk/dcmfg/fgfracon.h>
#include <dcmtk/dcmfg/fgpixmsr.h>
#include <dcmtk/dcmfg/fgplanor.h>
#include <dcmtk/dcmfg/fgplanpo.h>
#include <dcmtk/dcmiod/cielabutil.h>
#include <dcmtk/dcmiod/iodmacro.h>
#include <dcmtk/dcmseg/segdoc.h>
#include <dcmtk/dcmseg/segment.h>
#endif

#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>

namespace brainshift {
namespace fs = std::filesystem;

#ifndef BRAINSHIFT_HAVE_DCMSEG
bool dicomSegmentationAvailable() { return false; }

std::vector<DicomSegmentInfo> writeDicomSegmentation(const ScalarImage&, const fs::path&,
                                                     const DicomSegmentationDescription&, const fs::path& file)
{
  throw std::runtime_error(file.string() + ": BrainShift was built without DCMTK's dcmseg; no DICOM Segmentation");
}
#else
bool dicomSegmentationAvailable() { return true; }

namespace {
/// A SNOMED CT concept (scheme SCT): its code value and the meaning DICOM PS3.16 gives it.
struct Code {
  const char* value;
  const char* meaning;
};

/// BrainShift's label values, their segment labels and their SNOMED CT category and type
/// (DICOM PS3.16 CID 7150 Segmentation Property Categories, CID 7151 Segmentation Property Types).
struct LabelConcept {
  int value;
  const char* label;
  Code category, type;
  std::array<double, 3> rgb; ///< recommended display colour, 0..1
};

const LabelConcept kLabels[] = {
  {1, "head", {"91723000", "Anatomical Structure"}, {"69536005", "Head"}, {0.87, 0.72, 0.53}},
  {2, "parenchyma", {"85756007", "Tissue"}, {"12738006", "Brain"}, {0.98, 0.82, 0.82}},
  {3, "ventricles", {"91723000", "Anatomical Structure"}, {"35764002", "Cerebral ventricle"}, {0.35, 0.6, 0.95}},
  {4, "tumour", {"49755003", "Morphologically Altered Structure"}, {"108369006", "Neoplasm"}, {0.9, 0.2, 0.15}},
};

void check(const OFCondition& status, const fs::path& file, const char* what)
{
  if (status.bad()) throw std::runtime_error(file.string() + ": DCMTK cannot " + what + ": " + status.text());
}

std::string newUid(const char* root)
{
  char uid[100];
  dcmGenerateUniqueIdentifier(uid, root);
  return uid;
}

std::string sliceFileName(std::size_t k)
{
  char name[32];
  std::snprintf(name, sizeof name, "IM%04zu.dcm", k + 1);
  return name;
}

/// Per label value, the first and last slice it occupies (first > last: absent).
std::vector<std::pair<std::size_t, std::size_t>> sliceRanges(const ScalarImage& labels, const std::string& source)
{
  const ImageGeometry g = ImageGeometry::of(&labels);
  std::vector<std::pair<std::size_t, std::size_t>> ranges(5, {g.size[2], 0});
  const float* v = labels.GetBufferPointer();
  const std::size_t sliceSize = g.size[0] * g.size[1];
  for (std::size_t i = 0; i < g.numberOfVoxels(); ++i) {
    const float value = v[i];
    if (value == 0) continue;
    if (value != std::round(value) || value < 1 || value > 4) {
      throw InputError(source + ": label value " + std::to_string(value) +
                       " is none of BrainShift's (1 head, 2 parenchyma, 3 ventricles, 4 tumour)");
    }
    auto& range = ranges[static_cast<std::size_t>(value)];
    range.first = std::min(range.first, i / sliceSize);
    range.second = std::max(range.second, i / sliceSize);
  }
  return ranges;
}

/// The source series' slices in order (headers; DCMTK leaves the pixel data in the files). InputError
/// when they are not one file per slice of the labels' rows and columns.
std::vector<std::unique_ptr<DcmFileFormat>> sourceSlices(const fs::path& folder, const ImageGeometry& g, const fs::path& file)
{
  const std::string problem = file.string() + ": the source series " + folder.string() + " is not one file per slice of " +
                              g.describe();
  std::error_code ec;
  std::size_t files = 0;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder, ec)) files += entry.is_regular_file() ? 1 : 0;
  if (ec || files != g.size[2]) throw InputError(problem);
  std::vector<std::unique_ptr<DcmFileFormat>> slices;
  for (std::size_t k = 0; k < g.size[2]; ++k) {
    auto slice = std::make_unique<DcmFileFormat>();
    Uint16 rows = 0, columns = 0;
    if (slice->loadFile((folder / sliceFileName(k)).c_str()).bad() ||
        slice->getDataset()->findAndGetUint16(DCM_Rows, rows).bad() ||
        slice->getDataset()->findAndGetUint16(DCM_Columns, columns).bad() || rows != g.size[1] || columns != g.size[0]) {
      throw InputError(problem);
    }
    slices.push_back(std::move(slice));
  }
  return slices;
}

/// Geometry shared by every frame, dimensions (segment, position) and the segments.
void putSharedGroups(DcmSegmentation& seg, const ImageGeometry& g, const fs::path& file)
{
  FGPixelMeasures measures;
  check(measures.setPixelSpacing((dicomDecimalString(g.spacing[1]) + "\\" + dicomDecimalString(g.spacing[0])).c_str()),
        file, "set PixelSpacing");
  check(measures.setSliceThickness(dicomDecimalString(g.spacing[2]).c_str()), file, "set SliceThickness");
  check(measures.setSpacingBetweenSlices(dicomDecimalString(g.spacing[2]).c_str()), file, "set SpacingBetweenSlices");
  check(seg.addForAllFrames(measures), file, "add the pixel measures");
  std::unique_ptr<FGPlaneOrientationPatient> orientation(FGPlaneOrientationPatient::createMinimal(
    dicomDecimalString(g.direction[0][0]).c_str(), dicomDecimalString(g.direction[1][0]).c_str(),
    dicomDecimalString(g.direction[2][0]).c_str(), dicomDecimalString(g.direction[0][1]).c_str(),
    dicomDecimalString(g.direction[1][1]).c_str(), dicomDecimalString(g.direction[2][1]).c_str()));
  if (!orientation) throw std::runtime_error(file.string() + ": DCMTK cannot create the plane orientation");
  check(seg.addForAllFrames(*orientation), file, "add the plane orientation");
  const std::string dimensionUid = newUid(SITE_INSTANCE_UID_ROOT);
  IODMultiframeDimensionModule& dimensions = seg.getDimensions();
  check(dimensions.addDimensionIndex(DCM_ReferencedSegmentNumber, dimensionUid.c_str(), DCM_SegmentIdentificationSequence,
                                     "ReferencedSegmentNumber"),
        file, "add the segment dimension");
  check(dimensions.addDimensionIndex(DCM_ImagePositionPatient, dimensionUid.c_str(), DCM_PlanePositionSequence,
                                     "ImagePositionPatient"),
        file, "add the position dimension");
}

Uint16 addSegment(DcmSegmentation& seg, const LabelConcept& concept, const fs::path& file)
{
  DcmSegment* segment = nullptr;
  check(DcmSegment::create(segment, concept.label, CodeSequenceMacro(concept.category.value, "SCT", concept.category.meaning),
                           CodeSequenceMacro(concept.type.value, "SCT", concept.type.meaning), DcmSegTypes::SAT_AUTOMATIC,
                           "BrainShift"),
        file, "create a segment");
  std::unique_ptr<DcmSegment> owned(segment);
  double lab[3];
  IODCIELabUtil::rgb2DicomLab(lab[0], lab[1], lab[2], concept.rgb[0], concept.rgb[1], concept.rgb[2]);
  check(segment->setRecommendedDisplayCIELabValue(static_cast<Uint16>(lab[0]), static_cast<Uint16>(lab[1]),
                                                  static_cast<Uint16>(lab[2])),
        file, "set a segment's colour");
  check(segment->setSegmentDescription(("BrainShift label " + std::to_string(concept.value) + ", warped onto the "
                                        "intraoperative scan").c_str()),
        file, "set a segment's description");
  Uint16 number = 0;
  check(seg.addSegment(segment, number), file, "add a segment");
  owned.release();
  return number;
}

/// The frames of one segment: slices first..last, each derived from the source series' slice. Their
/// pixels are also appended to `allFrames` (one byte per pixel, 0 or 1).
void addFrames(DcmSegmentation& seg, const ScalarImage& labels, int value, Uint16 segmentNumber,
               std::pair<std::size_t, std::size_t> range, const std::vector<std::unique_ptr<DcmFileFormat>>& slices,
               std::vector<Uint8>& allFrames, const fs::path& file)
{
  const ImageGeometry g = ImageGeometry::of(&labels);
  const std::size_t sliceSize = g.size[0] * g.size[1];
  std::vector<Uint8> frame(sliceSize);
  FGPlanePosPatient position;
  FGFrameContent content;
  FGDerivationImage derivation;
  const OFVector<FGBase*> groups{&position, &content, &derivation};
  for (std::size_t k = range.first; k <= range.second; ++k) {
    std::string p[3];
    for (int r = 0; r < 3; ++r) p[r] = dicomDecimalString(g.origin[r] + g.direction[r][2] * g.spacing[2] * static_cast<double>(k));
    check(position.setImagePositionPatient(p[0].c_str(), p[1].c_str(), p[2].c_str()), file, "set a frame's position");
    check(content.setDimensionIndexValues(segmentNumber, 0), file, "set a frame's segment index");
    check(content.setDimensionIndexValues(static_cast<Uint32>(k + 1), 1), file, "set a frame's position index");
    derivation.clearData();
    DerivationImageItem* item = nullptr;
    check(derivation.addDerivationImageItem(CodeSequenceMacro("113076", "DCM", "Segmentation"), "", item), file,
          "add a frame's derivation");
    SourceImageItem* source = nullptr;
    check(item->addSourceImageItem(slices[k]->getDataset(),
                                   CodeSequenceMacro("121322", "DCM", "Source image for image processing operation"), source),
          file, "reference a source slice");
    const float* v = labels.GetBufferPointer() + k * sliceSize;
    for (std::size_t i = 0; i < sliceSize; ++i) frame[i] = v[i] == static_cast<float>(value) ? 1 : 0;
    check(seg.addFrame(frame.data(), segmentNumber, groups), file, "add a frame");
    allFrames.insert(allFrames.end(), frame.begin(), frame.end());
  }
}

/// The source series and the slices the frames were derived from (Common Instance Reference module).
void referenceSourceSeries(DcmSegmentation& seg, const std::vector<std::unique_ptr<DcmFileFormat>>& slices,
                           const std::vector<bool>& used, const fs::path& file)
{
  OFString seriesUid;
  check(slices.front()->getDataset()->findAndGetOFString(DCM_SeriesInstanceUID, seriesUid), file,
        "read the source series' SeriesInstanceUID");
  auto series = std::make_unique<IODSeriesAndInstanceReferenceMacro::ReferencedSeriesItem>();
  check(series->setSeriesInstanceUID(seriesUid), file, "reference the source series");
  for (std::size_t k = 0; k < slices.size(); ++k) {
    if (!used[k]) continue;
    OFString classUid, instanceUid;
    check(slices[k]->getDataset()->findAndGetOFString(DCM_SOPClassUID, classUid), file, "read a source SOPClassUID");
    check(slices[k]->getDataset()->findAndGetOFString(DCM_SOPInstanceUID, instanceUid), file, "read a source SOPInstanceUID");
    auto instance = std::make_unique<SOPInstanceReferenceMacro>();
    check(instance->setReferencedSOPClassUID(classUid), file, "reference a source slice");
    check(instance->setReferencedSOPInstanceUID(instanceUid), file, "reference a source slice");
    series->getReferencedInstanceItems().push_back(instance.release());
  }
  seg.getCommonInstanceReference().getReferencedSeriesItems().push_back(series.release());
}

/// The frames' pixels one bit each, frame after frame without padding, the first pixel in the
/// lowest bit (PS3.5 8.1.1), the whole padded to an even length.
std::vector<Uint8> packBits(const std::vector<Uint8>& pixels)
{
  std::vector<Uint8> packed((pixels.size() + 7) / 8, 0);
  for (std::size_t i = 0; i < pixels.size(); ++i)
    if (pixels[i]) packed[i / 8] = static_cast<Uint8>(packed[i / 8] | (1u << (i % 8)));
  if (packed.size() % 2) packed.push_back(0);
  return packed;
}

/// Writes the object, with what DCMTK's module classes leave out, to `file` (through a temporary
/// file beside it, renamed into place). The Pixel Data is packed here: DCMTK 3.6.7 corrupts the
/// bits of a frame that does not end on a byte (rows x columns not a multiple of 8) when it joins
/// the frames (its mask of the shared byte is lost to integer promotion).
void save(DcmSegmentation& seg, const std::vector<Uint8>& allFrames, const fs::path& file)
{
  DcmFileFormat out;
  DcmDataset& data = *out.getDataset();
  // DCMTK checks the dimensions while it writes, before the per-frame groups are in the dataset
  // (a warning on stderr, no check); check them on the whole dataset instead.
  seg.setCheckDimensionsOnWrite(OFFalse);
  check(seg.writeDataset(data), file, "write the Segmentation");
  check(seg.getDimensions().checkDimensions(&data), file, "find the frames' dimension index values consistent");
  const std::vector<Uint8> packed = packBits(allFrames);
  check(data.putAndInsertUint8Array(DCM_PixelData, packed.data(), static_cast<unsigned long>(packed.size())), file,
        "set the Pixel Data");
  check(data.putAndInsertString(DCM_SegmentsOverlap, "NO"), file, "set SegmentsOverlap"); // one label per voxel
  check(data.putAndInsertString(DCM_BodyPartExamined, "HEAD"), file, "set BodyPartExamined");
  OFString date, time;
  DcmDate::getCurrentDate(date);
  DcmTime::getCurrentTime(time);
  check(data.putAndInsertOFStringArray(DCM_SeriesDate, date), file, "set SeriesDate");
  check(data.putAndInsertOFStringArray(DCM_SeriesTime, time), file, "set SeriesTime");
  const fs::path partial = file.string() + ".part";
  check(out.saveFile(partial.c_str(), EXS_LittleEndianExplicit), file, "save the Segmentation");
  fs::rename(partial, file);
}
} // namespace

std::vector<DicomSegmentInfo> writeDicomSegmentation(const ScalarImage& labels, const fs::path& sourceSeriesFolder,
                                                     const DicomSegmentationDescription& description, const fs::path& file)
{
  const ImageGeometry g = ImageGeometry::of(&labels);
  const auto ranges =
    sliceRanges(labels, description.labelsSource.empty() ? file.string() : description.labelsSource);
  const auto slices = sourceSlices(sourceSeriesFolder, g, file);
  DcmSegmentation* created = nullptr;
  check(DcmSegmentation::createBinarySegmentation(
          created, static_cast<Uint16>(g.size[1]), static_cast<Uint16>(g.size[0]),
          IODGeneralEquipmentModule::EquipmentInfo("BrainShift", "BrainShift", "1", "brainshift 0.1.0"),
          ContentIdentificationMacro("1", "WARPED_LABELS", "BrainShift labels warped onto the intraoperative scan", "")),
        file, "create a binary Segmentation");
  std::unique_ptr<DcmSegmentation> seg(created);
  check(seg->importFromSourceImage(*slices.front()->getDataset()), file, "take the source's patient, study and Frame of Reference");
  check(seg->getSeries().setSeriesInstanceUID(newUid(SITE_SERIES_UID_ROOT).c_str()), file, "set SeriesInstanceUID");
  check(seg->getSeries().setSeriesDescription(description.description.c_str()), file, "set SeriesDescription");
  check(seg->getSeries().setSeriesNumber(std::to_string(description.seriesNumber).c_str()), file, "set SeriesNumber");
  putSharedGroups(*seg, g, file);
  std::vector<DicomSegmentInfo> written;
  std::vector<bool> used(g.size[2], false);
  std::vector<Uint8> allFrames;
  for (const LabelConcept& concept : kLabels) {
    const auto range = ranges[static_cast<std::size_t>(concept.value)];
    if (range.first > range.second) continue;
    const Uint16 number = addSegment(*seg, concept, file);
    addFrames(*seg, labels, concept.value, number, range, slices, allFrames, file);
    for (std::size_t k = range.first; k <= range.second; ++k) used[k] = true;
    written.push_back({concept.value, concept.label, static_cast<int>(range.second - range.first + 1)});
  }
  if (written.empty()) throw InputError(file.string() + ": the labels hold no label value; no Segmentation to write");
  referenceSourceSeries(*seg, slices, used, file);
  save(*seg, allFrames, file);
  return written;
}
#endif

} // namespace brainshift
