// brainshift-interop-test-tool: the independent receiving side of the command-line tests.
//   igtl-server PORTFILE OUTDIR   listens on a free port (written to PORTFILE), receives one
//                                 `brainshift send` session and checks every message against the
//                                 files of OUTDIR: type, device name, geometry, a checksum of the values.
//   igtl-refuse PORTFILE          accepts one client and hangs up at once.
//   compare-dicom SERIES FILE     reads SERIES with ITK's GDCM reader and compares it with FILE (a
//                                 volume, or a displacement field whose magnitude is compared):
//                                 same physical grid, values within half the series' RescaleSlope.
// Exit 0 when every check holds, 1 otherwise, with one line per finding.
#include "IgtlTestReceiver.h"
#include "ModelIO.h"
#include "OpenIGTLinkSender.h"
#include "TransformIO.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dctk.h>

#include <igtlImageMessage.h>
#include <igtlStatusMessage.h>

#include <itkImageRegionConstIteratorWithIndex.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>

namespace fs = std::filesystem;
using namespace brainshift;
using brainshift::testing::ReceivedMessage;

namespace {
int failures = 0;
void check(bool ok, const std::string& what)
{
  std::cout << (ok ? "ok      " : "FAILED  ") << what << '\n';
  if (!ok) ++failures;
}

void writePortFile(const fs::path& file, int port)
{
  const fs::path temporary = file.string() + ".tmp";
  std::ofstream(temporary) << port << '\n';
  fs::rename(temporary, file);
}

std::string hex(std::uint64_t v)
{
  char text[20];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(v));
  return text;
}

template <class TImage>
void checkImage(const ReceivedMessage& m, const TImage& expected, int scalarType)
{
  const ImageGeometry g = ImageGeometry::of(&expected);
  check(m.scalarType == scalarType, m.device + ": scalar type " + std::to_string(m.scalarType));
  check(m.coordinate == igtl::ImageMessage::COORDINATE_RAS, m.device + ": coordinate system RAS");
  check(m.geometry.sameGridAs(g, 1e-4), m.device + ": grid " + m.geometry.describe() + " (file: " + g.describe() + ")");
  const std::size_t bytes = g.numberOfVoxels() * sizeof(typename TImage::PixelType);
  const std::uint64_t sent = testing::fnv1a(m.values.data(), m.values.size());
  const std::uint64_t file = testing::fnv1a(expected.GetBufferPointer(), bytes);
  check(m.values.size() == bytes && sent == file, m.device + ": values checksum " + hex(sent) + " (file: " + hex(file) + ")");
}

void checkTransform(const ReceivedMessage& m, const SpatialTransform& intraopToPreop)
{
  // The matrix takes a preoperative RAS point to the intraoperative one: T(intraop) must give it back.
  double worst = 0;
  for (const auto& lps : std::vector<std::array<double, 3>>{{0, 0, 0}, {60, -40, 30}, {-70, 80, -20}}) {
    const double ras[3] = {-lps[0], -lps[1], lps[2]};
    SpatialTransform::InputPointType intraop;
    for (int r = 0; r < 3; ++r) {
      double v = m.matrix[r][3];
      for (int c = 0; c < 3; ++c) v += m.matrix[r][c] * ras[c];
      intraop[r] = r < 2 ? -v : v;
    }
    const auto preop = intraopToPreop.TransformPoint(intraop);
    for (int r = 0; r < 3; ++r) worst = std::max(worst, std::abs(preop[r] - lps[r]));
  }
  check(worst < 1e-3, m.device + ": maps preoperative to intraoperative points (worst " + std::to_string(worst) + " mm)");
}

void checkSurface(const ReceivedMessage& m, vtkPolyData& surface)
{
  bool pointsOk = static_cast<vtkIdType>(m.points.size()) == surface.GetNumberOfPoints();
  for (vtkIdType i = 0; pointsOk && i < surface.GetNumberOfPoints(); ++i) {
    double p[3];
    surface.GetPoint(i, p);
    pointsOk = std::abs(m.points[i][0] + p[0]) < 1e-3 && std::abs(m.points[i][1] + p[1]) < 1e-3 &&
               std::abs(m.points[i][2] - p[2]) < 1e-3;
  }
  check(pointsOk, m.device + ": " + std::to_string(m.points.size()) + " points in RAS");
  check(m.polygons == surface.GetNumberOfPolys(), m.device + ": " + std::to_string(m.polygons) + " polygons");
  vtkDataArray* magnitude = surface.GetPointData()->GetArray("DisplacementMagnitude");
  bool valuesOk = magnitude && m.attributeName == "DisplacementMagnitude" &&
                  static_cast<vtkIdType>(m.attribute.size()) == magnitude->GetNumberOfTuples();
  for (vtkIdType i = 0; valuesOk && i < magnitude->GetNumberOfTuples(); ++i) {
    valuesOk = m.attribute[i] == static_cast<float>(magnitude->GetComponent(i, 0));
  }
  check(valuesOk, m.device + ": DisplacementMagnitude values (" + std::to_string(m.attribute.size()) + ")");
}

int igtlServer(const fs::path& portFile, const fs::path& outputDir)
{
  testing::IgtlTestReceiver receiver;
  writePortFile(portFile, receiver.port());
  const std::vector<ReceivedMessage> messages = receiver.receiveSession();
  const UpdateFolderContents contents = inspectUpdateFolder(outputDir);
  std::map<std::string, const ReceivedMessage*> byDevice;
  for (const ReceivedMessage& m : messages) byDevice[m.device] = &m;
  check(byDevice.size() == messages.size(), std::to_string(messages.size()) + " messages, device names unique");
  const auto find = [&](const std::string& type, const std::string& device) -> const ReceivedMessage* {
    const auto it = byDevice.find(device);
    const bool found = it != byDevice.end() && it->second->type == type;
    check(found, type + " " + device + " received");
    return found ? it->second : nullptr;
  };
  if (const auto* m = find("IMAGE", "intraop_image")) {
    checkImage(*m, *readScalarVolume(contents.intraopImage), igtl::ImageMessage::TYPE_FLOAT32);
  }
  for (const UpdateVolume& volume : contents.warpedVolumes) {
    const auto* m = find("IMAGE", volume.name);
    if (m && volume.isLabelMap) checkImage(*m, *readLabelVolume(volume.path), igtl::ImageMessage::TYPE_UINT16);
    if (m && !volume.isLabelMap) checkImage(*m, *readScalarVolume(volume.path), igtl::ImageMessage::TYPE_FLOAT32);
  }
  if (const auto* m = find("TRANSFORM", "rigid_to_preop")) checkTransform(*m, *readTransform(*contents.rigidTransform));
  if (const auto* m = find("POLYDATA", "brain_surface")) {
    auto model = readModel(*contents.brainSurface);
    checkSurface(*m, *vtkPolyData::SafeDownCast(model));
  }
  check(!messages.empty() && messages.back().type == "STATUS" && messages.back().device == "brainshift" &&
          messages.back().statusCode == igtl::StatusMessage::STATUS_OK,
        "STATUS brainshift OK comes last");
  const std::size_t expected = 1 + contents.warpedVolumes.size() + 3;
  check(messages.size() == expected, std::to_string(messages.size()) + " messages, expected " + std::to_string(expected));
  return failures ? 1 : 0;
}

double rescaleSlopeOf(const fs::path& series)
{
  for (const fs::directory_entry& entry : fs::directory_iterator(series)) {
    DcmFileFormat file;
    Float64 slope = 1;
    if (file.loadFile(entry.path().c_str()).good() && file.getDataset()->findAndGetFloat64(DCM_RescaleSlope, slope).good()) {
      return slope;
    }
  }
  return 1;
}

int compareDicom(const fs::path& series, const fs::path& file)
{
  ScalarImage::Pointer expected;
  if (file.extension() == ".nrrd") {
    DisplacementFieldImage::Pointer field = readDisplacementField(file);
    expected = ImageGeometry::of(field.GetPointer()).allocate<ScalarImage>();
    for (std::size_t i = 0; i < ImageGeometry::of(field.GetPointer()).numberOfVoxels(); ++i) {
      expected->GetBufferPointer()[i] = static_cast<float>(field->GetBufferPointer()[i].GetNorm());
    }
  } else {
    expected = readScalarVolume(file);
  }
  ScalarImage::Pointer dicom = readDicomSeries(series);
  const double tolerance = rescaleSlopeOf(series) / 2 + 1e-6 * (1 + rescaleSlopeOf(series) * 65535);
  // Compared through physical space: a reader may order the slices the other way round.
  double worstValue = 0, worstPosition = 0;
  itk::ImageRegionConstIteratorWithIndex<ScalarImage> it(expected, expected->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint p;
    expected->TransformIndexToPhysicalPoint(it.GetIndex(), p);
    itk::ContinuousIndex<double, 3> c;
    dicom->TransformPhysicalPointToContinuousIndex(p, c);
    ScalarImage::IndexType index;
    for (int d = 0; d < 3; ++d) {
      index[d] = static_cast<itk::IndexValueType>(std::lround(c[d]));
      worstPosition = std::max(worstPosition, std::abs(c[d] - static_cast<double>(index[d])));
    }
    if (!dicom->GetLargestPossibleRegion().IsInside(index)) {
      worstValue = INFINITY;
      break;
    }
    worstValue = std::max(worstValue, std::abs(static_cast<double>(dicom->GetPixel(index)) - it.Get()));
  }
  const ImageGeometry a = ImageGeometry::of(expected.GetPointer()), b = ImageGeometry::of(dicom.GetPointer());
  check(a.numberOfVoxels() == b.numberOfVoxels(), series.string() + ": " + b.describe() + " (file: " + a.describe() + ")");
  check(worstPosition < 1e-3, series.string() + ": every voxel centre on the file's (worst " + std::to_string(worstPosition) + " voxel)");
  check(worstValue <= tolerance, series.string() + ": values within " + std::to_string(tolerance) + " (worst " +
                                   std::to_string(worstValue) + ")");
  return failures ? 1 : 0;
}
} // namespace

int main(int argc, char** argv)
{
  const std::string command = argc > 1 ? argv[1] : "";
  try {
    registerIOFactories();
    if (command == "igtl-server" && argc == 4) return igtlServer(argv[2], argv[3]);
    if (command == "igtl-refuse" && argc == 3) {
      testing::IgtlTestReceiver receiver;
      writePortFile(argv[2], receiver.port());
      receiver.refuseOne();
      return 0;
    }
    if (command == "compare-dicom" && argc == 4) return compareDicom(argv[2], argv[3]);
  } catch (const std::exception& e) {
    std::cout << "FAILED  " << e.what() << '\n';
    return 1;
  }
  std::cerr << "usage: brainshift-interop-test-tool igtl-server PORTFILE OUTDIR | igtl-refuse PORTFILE | "
               "compare-dicom SERIES FILE\n";
  return 2;
}
