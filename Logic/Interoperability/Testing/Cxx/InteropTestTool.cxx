// brainshift-interop-test-tool: the independent receiving side of the command-line tests.
//   igtl-server PORTFILE OUTDIR   listens on a free port (written to PORTFILE), receives one
//                                 `brainshift send` session and checks every message against the
//                                 files of OUTDIR: type, device name, geometry, a checksum of the values.
//   igtl-refuse PORTFILE          accepts one client and hangs up at once.
//   compare-dicom SERIES FILE     reads SERIES with ITK's GDCM reader and compares it with FILE (a
//                                 volume, or a displacement field whose magnitude is compared):
//                                 same physical grid, values within half the series' RescaleSlope.
//   igtl-watch-client PORT SESSION SCAN
//                                 a client of `watch --igtl-server 127.0.0.1:PORT` (see igtlWatchClient).
//   check-seg SEG LABELS SERIES   reads the DICOM Segmentation SEG with DCMTK's reader and checks it
//                                 against the label volume LABELS and the MR series SERIES it was
//                                 derived from: a segment per label value present, a frame per slice
//                                 from the label's first to its last, each segment's voxels the
//                                 label's, the series' study and Frame of Reference.
// Exit 0 when every check holds, 1 otherwise, with one line per finding.
#include "IgtlTestReceiver.h"
#include "ModelIO.h"
#include "OpenIGTLinkSender.h"
#include "TransformIO.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dctk.h>
#ifdef BRAINSHIFT_HAVE_DCMSEG
#include "DicomSegmentationReadBack.h"
#endif

#include <igtlImageMessage.h>
#include <igtlStatusMessage.h>
#include <igtl_util.h>

#include <itkImageRegionConstIteratorWithIndex.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <thread>
#include <chrono>
#include <cstring>

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

/// Every message of one update against the files of `outputDir`: type, device, grid, checksum.
void checkUpdate(const std::vector<ReceivedMessage>& messages, const fs::path& outputDir)
{
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
}

int igtlServer(const fs::path& portFile, const fs::path& outputDir)
{
  testing::IgtlTestReceiver receiver;
  writePortFile(portFile, receiver.port());
  checkUpdate(receiver.receiveSession(), outputDir);
  return failures ? 1 : 0;
}

/// A client of `watch --igtl-server` on 127.0.0.1:port, retrying for up to a minute while the session starts.
igtl::ClientSocket::Pointer connectToWatch(int port)
{
  for (int attempt = 0; attempt < 600; ++attempt) {
    auto socket = igtl::ClientSocket::New();
    if (socket->ConnectToServer("127.0.0.1", port) == 0) {
      socket->SetReceiveTimeout(120000); // every wait bounded: a registration of the small case takes seconds
      return socket;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  throw std::runtime_error("cannot connect to the watch session's server on 127.0.0.1:" + std::to_string(port));
}

/// IMAGE intraop (float32, RAS, the matrix's translation the volume's centre) of `image`.
void sendScan(igtl::ClientSocket* socket, const ScalarImage& image)
{
  const ImageGeometry g = ImageGeometry::of(&image);
  auto message = igtl::ImageMessage::New();
  message->SetDeviceName("intraop");
  message->SetDimensions(int(g.size[0]), int(g.size[1]), int(g.size[2]));
  message->SetSpacing(float(g.spacing[0]), float(g.spacing[1]), float(g.spacing[2]));
  message->SetScalarType(igtl::ImageMessage::TYPE_FLOAT32);
  message->SetEndian(igtl_is_little_endian() ? igtl::ImageMessage::ENDIAN_LITTLE : igtl::ImageMessage::ENDIAN_BIG);
  message->SetCoordinateSystem(igtl::ImageMessage::COORDINATE_RAS);
  igtl::Matrix4x4 m;
  const Matrix4 matrix = igtlImageMatrix(g);
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m[r][c] = float(matrix[r][c]);
  message->SetMatrix(m);
  message->AllocateScalars();
  std::memcpy(message->GetScalarPointer(), image.GetBufferPointer(), message->GetImageSize());
  message->Pack();
  if (socket->Send(message->GetPackPointer(), message->GetPackSize()) != 1) throw std::runtime_error("cannot send IMAGE intraop");
}

/// The navigation side of `watch --igtl-server`: a client that drops out after one message header,
/// a client that receives the first scan's update, a client that connects after it and gets it on
/// connecting, then IMAGE intraop from SCAN that becomes the second scan, whose update both receive.
int igtlWatchClient(int port, const fs::path& session, const fs::path& scanFile)
{
  std::thread dropping([port] {
    try {
      auto socket = connectToWatch(port);
      char header[58];
      socket->Receive(header, sizeof header); // inside the first update
      socket->CloseSocket();
    } catch (const std::exception& e) {
      std::cout << "FAILED  dropping client: " << e.what() << '\n';
    }
  });
  auto first = connectToWatch(port);
  std::cout << "-- first client, scan 1\n";
  checkUpdate(testing::receiveUntilStatus(first), session / "scan-01");
  dropping.join();
  const auto connecting = std::chrono::steady_clock::now();
  auto late = connectToWatch(port);
  const std::vector<ReceivedMessage> latest = testing::receiveUntilStatus(late);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - connecting).count();
  std::size_t bytes = 0;
  for (const ReceivedMessage& m : latest) bytes += m.values.size() + m.points.size() * 12 + m.attribute.size() * 4;
  std::cout << "-- client connected after scan 1: the latest update on connecting (" << latest.size() << " messages, "
            << bytes / 1000 << " kB of values, connect to STATUS " << seconds << " s)\n";
  checkUpdate(latest, session / "scan-01");
  ScalarImage::Pointer scan = readScalarVolume(scanFile);
  sendScan(first, *scan);
  for (auto* client : {first.GetPointer(), late.GetPointer()}) {
    std::cout << "-- scan 2 (IMAGE intraop)\n";
    const std::vector<ReceivedMessage> update = testing::receiveUntilStatus(client);
    checkUpdate(update, session / "scan-02");
    // The scan sent comes back as the update's intraop_image: same grid, same values.
    for (const ReceivedMessage& m : update) {
      if (m.device == "intraop_image") checkImage(m, *scan, igtl::ImageMessage::TYPE_FLOAT32);
    }
  }
  first->CloseSocket();
  late->CloseSocket();
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

#ifdef BRAINSHIFT_HAVE_DCMSEG
std::string fileTag(const fs::path& file, const DcmTagKey& tag)
{
  DcmFileFormat dicom;
  OFString value;
  if (dicom.loadFile(file.c_str()).bad()) return {};
  dicom.getDataset()->findAndGetOFString(tag, value);
  return value.c_str();
}

int checkSegmentation(const fs::path& segFile, const fs::path& labelsFile, const fs::path& series)
{
  const testing::ReadBackSegmentation seg = testing::readBackSegmentation(segFile.string());
  ScalarImage::Pointer labels = readScalarVolume(labelsFile);
  const ImageGeometry g = ImageGeometry::of(labels.GetPointer());
  std::map<int, std::size_t> voxels, firstSlice, lastSlice;
  for (std::size_t i = 0; i < g.numberOfVoxels(); ++i) {
    const int value = static_cast<int>(labels->GetBufferPointer()[i]);
    if (value == 0) continue;
    const std::size_t k = i / (g.size[0] * g.size[1]);
    if (!voxels.count(value)) firstSlice[value] = k;
    ++voxels[value];
    lastSlice[value] = k;
  }
  check(seg.modality == "SEG", segFile.string() + ": Modality SEG (" + seg.modality + ")");
  check(seg.segments.size() == voxels.size(), segFile.string() + ": " + std::to_string(voxels.size()) + " segments (" +
                                                std::to_string(seg.segments.size()) + ")");
  std::size_t s = 0;
  for (const auto& [value, count] : voxels) {
    if (s >= seg.segments.size()) break;
    const testing::ReadBackSegment& segment = seg.segments[s++];
    const std::size_t frames = lastSlice[value] - firstSlice[value] + 1;
    check(segment.frames == frames, segFile.string() + ": segment '" + segment.label + "' has " + std::to_string(frames) +
                                      " frames (" + std::to_string(segment.frames) + ")");
    check(segment.voxels == count, segFile.string() + ": segment '" + segment.label + "' has label " + std::to_string(value) +
                                     "'s " + std::to_string(count) + " voxels (" + std::to_string(segment.voxels) + ")");
    std::cout << "segment " << s << " '" << segment.label << "': " << segment.frames << " frames, " << segment.voxels << " voxels\n";
  }
  check(seg.studyUid == fileTag(series / "IM0001.dcm", DCM_StudyInstanceUID), segFile.string() + ": the series' StudyInstanceUID");
  check(seg.frameOfReferenceUid == fileTag(series / "IM0001.dcm", DCM_FrameOfReferenceUID),
        segFile.string() + ": the series' FrameOfReferenceUID");
  if (!seg.segments.empty() && !voxels.empty()) {
    char slice[32];
    std::snprintf(slice, sizeof slice, "IM%04zu.dcm", firstSlice[voxels.begin()->first] + 1);
    check(seg.segments[0].sourceInstances.at(0) == fileTag(series / slice, DCM_SOPInstanceUID),
          segFile.string() + ": the first frame derived from " + (series / slice).string());
  }
  return failures ? 1 : 0;
}
#endif
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
    if (command == "igtl-watch-client" && argc == 5) return igtlWatchClient(std::stoi(argv[2]), argv[3], argv[4]);
#ifdef BRAINSHIFT_HAVE_DCMSEG
    if (command == "check-seg" && argc == 5) return checkSegmentation(argv[2], argv[3], argv[4]);
#endif
  } catch (const std::exception& e) {
    std::cout << "FAILED  " << e.what() << '\n';
    return 1;
  }
  std::cerr << "usage: brainshift-interop-test-tool igtl-server PORTFILE OUTDIR | igtl-refuse PORTFILE | "
               "compare-dicom SERIES FILE | igtl-watch-client PORT SESSION SCAN | check-seg SEG LABELS SERIES\n";
  return 2;
}
