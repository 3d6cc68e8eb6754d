#pragma once
// A DICOM Segmentation read back with DCMTK's own reader (DcmSegmentation::loadFile), for the
// tests: the segments with their frames and set voxels, the study, Frame of Reference and the
// geometry of the functional groups. Shared by the test driver and the command-line tests' tool.
#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dctk.h>
#include <dcmtk/dcmfg/fgderimg.h>
#include <dcmtk/dcmfg/fgpixmsr.h>
#include <dcmtk/dcmfg/fgplanor.h>
#include <dcmtk/dcmfg/fgplanpo.h>
#include <dcmtk/dcmfg/fgseg.h>
#include <dcmtk/dcmseg/segdoc.h>
#include <dcmtk/dcmseg/segment.h>
#include <dcmtk/dcmseg/segutils.h>

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace brainshift::testing {

struct ReadBackSegment {
  std::string label, algorithmName, algorithmType, categoryCode, typeCode;
  std::size_t frames = 0, voxels = 0;
  std::vector<std::string> positions; ///< ImagePositionPatient of each frame, as written
  std::vector<std::string> sourceInstances; ///< the SOPInstanceUID each frame is derived from
};

struct ReadBackSegmentation {
  std::string studyUid, frameOfReferenceUid, seriesUid, modality, orientation, pixelSpacing;
  std::vector<ReadBackSegment> segments;
};

inline std::string fgString(FGBase* group, const DcmTagKey& tag)
{
  // Functional groups read their values from items; write the group into one to read a tag back.
  DcmItem item;
  if (!group || group->write(item).bad()) return {};
  DcmItem* inner = nullptr;
  OFString value;
  for (unsigned long i = 0; i < item.card(); ++i) {
    DcmSequenceOfItems* sequence = dynamic_cast<DcmSequenceOfItems*>(item.getElement(i));
    if (sequence && sequence->card() > 0) inner = sequence->getItem(0);
  }
  if (!inner || inner->findAndGetOFStringArray(tag, value, OFTrue).bad()) return {};
  return value.c_str();
}

inline ReadBackSegmentation readBackSegmentation(const std::string& file)
{
  DcmSegmentation* loaded = nullptr;
  const OFCondition status = DcmSegmentation::loadFile(file.c_str(), loaded);
  std::unique_ptr<DcmSegmentation> seg(loaded);
  if (status.bad() || !seg) throw std::runtime_error(file + ": DCMTK cannot read the Segmentation: " + status.text());
  ReadBackSegmentation result;
  OFString value;
  seg->getStudy().getStudyInstanceUID(value);
  result.studyUid = value.c_str();
  seg->getFrameOfReference().getFrameOfReferenceUID(value);
  result.frameOfReferenceUid = value.c_str();
  seg->getSeries().getSeriesInstanceUID(value);
  result.seriesUid = value.c_str();
  seg->getModality(value);
  result.modality = value.c_str();
  FGInterface& groups = seg->getFunctionalGroups();
  OFBool perFrame = OFFalse;
  result.orientation = fgString(groups.get(0, DcmFGTypes::EFG_PLANEORIENTPATIENT, perFrame), DCM_ImageOrientationPatient);
  result.pixelSpacing = fgString(groups.get(0, DcmFGTypes::EFG_PIXELMEASURES, perFrame), DCM_PixelSpacing);
  Uint16 rows = 0, columns = 0;
  DcmIODImage<IODImagePixelModule<Uint8>>& image = *seg;
  image.getImagePixel().getRows(rows);
  image.getImagePixel().getColumns(columns);
  for (std::size_t number = 1; number <= seg->getNumberOfSegments(); ++number) {
    DcmSegment* segment = seg->getSegment(number);
    if (!segment) throw std::runtime_error(file + ": no segment " + std::to_string(number));
    ReadBackSegment s;
    segment->getSegmentLabel(value);
    s.label = value.c_str();
    segment->getSegmentAlgorithmName(value);
    s.algorithmName = value.c_str();
    s.algorithmType = DcmSegTypes::algoType2OFString(segment->getSegmentAlgorithmType()).c_str();
    segment->getSegmentedPropertyCategoryCode().getCodeValue(value);
    s.categoryCode = value.c_str();
    segment->getSegmentedPropertyTypeCode().getCodeValue(value);
    s.typeCode = value.c_str();
    OFVector<size_t> frames;
    seg->getFramesForSegment(number, frames);
    s.frames = frames.size();
    for (size_t f : frames) {
      s.positions.push_back(fgString(groups.get(f, DcmFGTypes::EFG_PLANEPOSPATIENT, perFrame), DCM_ImagePositionPatient));
      auto* derivation = dynamic_cast<FGDerivationImage*>(groups.get(f, DcmFGTypes::EFG_DERIVATIONIMAGE, perFrame));
      std::string source;
      if (derivation && !derivation->getDerivationImageItems().empty() &&
          !derivation->getDerivationImageItems()[0]->getSourceImageItems().empty()) {
        derivation->getDerivationImageItems()[0]->getSourceImageItems()[0]->getImageSOPInstanceReference().getReferencedSOPInstanceUID(value);
        source = value.c_str();
      }
      s.sourceInstances.push_back(source);
      const DcmIODTypes::Frame* frame = seg->getFrame(f);
      if (!frame) throw std::runtime_error(file + ": no frame " + std::to_string(f));
      std::unique_ptr<DcmIODTypes::Frame> unpacked(DcmSegUtils::unpackBinaryFrame(frame, rows, columns));
      if (!unpacked) throw std::runtime_error(file + ": frame " + std::to_string(f) + " does not unpack");
      for (size_t i = 0; i < unpacked->length; ++i) s.voxels += unpacked->pixData[i] ? 1 : 0;
    }
    result.segments.push_back(s);
  }
  return result;
}

} // namespace brainshift::testing
