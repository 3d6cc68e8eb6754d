#include "OpenIGTLinkSender.h"

#include "IgtlConnectedSocket.h"
#include "ModelIO.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

#include <igtlClientSocket.h>
#include <igtlImageMessage.h>
#include <igtlPolyDataMessage.h>
#include <igtlStatusMessage.h>
#include <igtlTransformMessage.h>
#include <igtl_util.h>

#include <vtkCellArray.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>

#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <unistd.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/types.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <iostream>

namespace brainshift {

namespace {
constexpr double lpsToRas[3] = {-1, -1, 1};

std::string deviceNameFor(const std::string& name)
{
  if (name.size() <= igtlDeviceNameLength) return name;
  const std::string shortened = name.substr(0, igtlDeviceNameLength);
  std::cerr << "brainshift: warning: OpenIGTLink device names hold " << igtlDeviceNameLength << " characters; '"
            << name << "' is sent as '" << shortened << "'\n";
  return shortened;
}

void toIgtl(const Matrix4& m, igtl::Matrix4x4& out)
{
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) out[r][c] = static_cast<float>(m[r][c]);
}

double seconds(std::chrono::steady_clock::time_point since)
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}
} // namespace

IgtlEndpoint parseIgtlEndpoint(const std::string& text)
{
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size()) {
    throw InputError("--igtl " + text + ": expected HOST:PORT, e.g. localhost:18944");
  }
  IgtlEndpoint endpoint;
  endpoint.host = text.substr(0, colon);
  const std::string port = text.substr(colon + 1);
  if (port.find_first_not_of("0123456789") != std::string::npos || port.size() > 5 || std::stoi(port) < 1 ||
      std::stoi(port) > 65535) {
    throw InputError("--igtl " + text + ": the port must be a number from 1 to 65535");
  }
  endpoint.port = std::stoi(port);
  return endpoint;
}

Matrix4 igtlImageMatrix(const ImageGeometry& geometry)
{
  Matrix4 m{};
  for (int r = 0; r < 3; ++r) {
    double centre = geometry.origin[r];
    for (int c = 0; c < 3; ++c) {
      m[r][c] = lpsToRas[r] * geometry.direction[r][c];
      centre += geometry.direction[r][c] * geometry.spacing[c] * (static_cast<double>(geometry.size[c]) - 1.0) / 2.0;
    }
    m[r][3] = lpsToRas[r] * centre;
  }
  m[3][3] = 1;
  return m;
}

Matrix4 igtlTransformMatrix(const SpatialTransform& intraopToPreop)
{
  if (!isLinearTransform(&intraopToPreop)) {
    throw InputError("the rigid transform is not linear (" + describeTransform(&intraopToPreop) + ")");
  }
  SpatialTransform::Pointer preopToIntraop = intraopToPreop.GetInverseTransform();
  if (!preopToIntraop) throw InputError("the rigid transform cannot be inverted");
  const AffineParameters p = affineParametersOf(preopToIntraop);
  Matrix4 m{};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m[r][c] = lpsToRas[r] * p.matrix[r][c] * lpsToRas[c];
    m[r][3] = lpsToRas[r] * p.translation[r];
  }
  m[3][3] = 1;
  return m;
}

namespace {
/// A TCP connection to `endpoint` (TCP_NODELAY, as libOpenIGTLink sets it). ConnectionError with the
/// system's reason otherwise.
int connectTo(const IgtlEndpoint& endpoint)
{
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (getaddrinfo(endpoint.host.c_str(), std::to_string(endpoint.port).c_str(), &hints, &found) != 0 || !found) {
    throw ConnectionError("OpenIGTLink server " + endpoint.text() + ": unknown host '" + endpoint.host + "'");
  }
  std::string reason = "no address";
  int descriptor = -1;
  for (addrinfo* a = found; a && descriptor < 0; a = a->ai_next) {
    descriptor = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (descriptor < 0) {
      reason = std::strerror(errno);
      continue;
    }
    int on = 1;
    setsockopt(descriptor, IPPROTO_TCP, TCP_NODELAY, &on, sizeof on);
    if (connect(descriptor, a->ai_addr, a->ai_addrlen) != 0) {
      reason = std::strerror(errno);
      close(descriptor);
      descriptor = -1;
    }
  }
  freeaddrinfo(found);
  if (descriptor < 0) {
    throw ConnectionError("OpenIGTLink server " + endpoint.text() + ": cannot connect (" + reason +
                          "; is the server, e.g. 3D Slicer's OpenIGTLinkIF connector, started?)");
  }
  return descriptor;
}
} // namespace

using detail::ConnectedSocket;

struct OpenIGTLinkSender::Socket {
  ConnectedSocket::Pointer client = ConnectedSocket::New();
};

OpenIGTLinkSender::OpenIGTLinkSender(const IgtlEndpoint& endpoint, int sendTimeoutMs)
  : socket_(std::make_unique<Socket>()), endpoint_(endpoint)
{
  socket_->client->adopt(connectTo(endpoint));
  socket_->client->SetSendTimeout(sendTimeoutMs);
}

OpenIGTLinkSender::OpenIGTLinkSender(std::vector<PackedIgtlMessage>& recorder)
  : recorder_(&recorder), endpoint_{"(recorded)", 0}
{
}

OpenIGTLinkSender::~OpenIGTLinkSender()
{
  if (socket_ && socket_->client) socket_->client->CloseSocket();
}

void OpenIGTLinkSender::transmit(const char* type, const std::string& device, const void* data, std::size_t bytes)
{
  if (recorder_) {
    recorder_->push_back({type, device, std::string(static_cast<const char*>(data), bytes)});
  } else if (socket_->client->Send(data, static_cast<int>(bytes)) != 1) {
    throw ConnectionError("OpenIGTLink server " + endpoint_.text() + " closed the connection while receiving " + type +
                          " " + device);
  }
  bytesSent_ += bytes;
  ++messagesSent_;
}

void OpenIGTLinkSender::checkStillConnected()
{
  // A server's own messages are not read; peeking shows an end of stream or a reset without taking them.
  if (recorder_) return;
  char byte;
  errno = 0;
  const ssize_t n = recv(socket_->client->descriptor(), &byte, 1, MSG_PEEK | MSG_DONTWAIT);
  if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)) {
    throw ConnectionError("OpenIGTLink server " + endpoint_.text() +
                          " closed the connection (it refused this client); the update was not received");
  }
}

namespace {
template <class TImage>
igtl::ImageMessage::Pointer imageMessage(const std::string& device, const TImage& image, int scalarType)
{
  const ImageGeometry geometry = ImageGeometry::of(&image);
  auto message = igtl::ImageMessage::New();
  message->SetDeviceName(device.c_str());
  message->SetDimensions(static_cast<int>(geometry.size[0]), static_cast<int>(geometry.size[1]),
                         static_cast<int>(geometry.size[2]));
  message->SetSpacing(static_cast<float>(geometry.spacing[0]), static_cast<float>(geometry.spacing[1]),
                      static_cast<float>(geometry.spacing[2]));
  message->SetScalarType(scalarType);
  message->SetEndian(igtl_is_little_endian() ? igtl::ImageMessage::ENDIAN_LITTLE : igtl::ImageMessage::ENDIAN_BIG);
  message->SetCoordinateSystem(igtl::ImageMessage::COORDINATE_RAS);
  igtl::Matrix4x4 matrix;
  toIgtl(igtlImageMatrix(geometry), matrix);
  message->SetMatrix(matrix);
  message->AllocateScalars();
  std::memcpy(message->GetScalarPointer(), image.GetBufferPointer(), message->GetImageSize());
  message->Pack();
  return message;
}
} // namespace

void OpenIGTLinkSender::sendImage(const std::string& device, const ScalarImage& image)
{
  const std::string name = deviceNameFor(device);
  auto message = imageMessage(name, image, igtl::ImageMessage::TYPE_FLOAT32);
  transmit("IMAGE", name, message->GetPackPointer(), message->GetPackSize());
}

void OpenIGTLinkSender::sendLabelImage(const std::string& device, const LabelImage& labels)
{
  static_assert(sizeof(LabelPixel) == 2, "labels travel as uint16");
  const std::string name = deviceNameFor(device);
  auto message = imageMessage(name, labels, igtl::ImageMessage::TYPE_UINT16);
  transmit("IMAGE", name, message->GetPackPointer(), message->GetPackSize());
}

void OpenIGTLinkSender::sendTransform(const std::string& device, const SpatialTransform& intraopToPreop)
{
  const std::string name = deviceNameFor(device);
  auto message = igtl::TransformMessage::New();
  message->SetDeviceName(name.c_str());
  igtl::Matrix4x4 matrix;
  toIgtl(igtlTransformMatrix(intraopToPreop), matrix);
  message->SetMatrix(matrix);
  message->Pack();
  transmit("TRANSFORM", name, message->GetPackPointer(), message->GetPackSize());
}

void OpenIGTLinkSender::sendSurface(const std::string& device, vtkPolyData& surface, const std::string& scalarArray)
{
  const std::string name = deviceNameFor(device);
  auto points = igtl::PolyDataPointArray::New();
  for (vtkIdType i = 0; i < surface.GetNumberOfPoints(); ++i) {
    double p[3];
    surface.GetPoint(i, p);
    points->AddPoint(static_cast<igtlFloat32>(-p[0]), static_cast<igtlFloat32>(-p[1]), static_cast<igtlFloat32>(p[2]));
  }
  auto polygons = igtl::PolyDataCellArray::New();
  auto cell = vtkSmartPointer<vtkIdList>::New();
  vtkCellArray* polys = surface.GetPolys();
  for (vtkIdType c = 0; polys && c < polys->GetNumberOfCells(); ++c) {
    polys->GetCellAtId(c, cell);
    std::list<igtlUint32> ids;
    for (vtkIdType k = 0; k < cell->GetNumberOfIds(); ++k) ids.push_back(static_cast<igtlUint32>(cell->GetId(k)));
    polygons->AddCell(ids);
  }
  auto message = igtl::PolyDataMessage::New();
  message->SetDeviceName(name.c_str());
  message->SetPoints(points);
  message->SetPolygons(polygons);
  if (vtkDataArray* values = surface.GetPointData()->GetArray(scalarArray.c_str())) {
    std::vector<igtlFloat32> data(static_cast<std::size_t>(values->GetNumberOfTuples()));
    for (vtkIdType i = 0; i < values->GetNumberOfTuples(); ++i) data[i] = static_cast<igtlFloat32>(values->GetComponent(i, 0));
    auto attribute = igtl::PolyDataAttribute::New();
    attribute->SetType(igtl::PolyDataAttribute::POINT_SCALAR);
    attribute->SetName(scalarArray.c_str());
    attribute->SetSize(static_cast<igtlUint32>(data.size()));
    attribute->SetData(data.data());
    message->AddAttribute(attribute);
  }
  message->Pack();
  transmit("POLYDATA", name, message->GetPackPointer(), message->GetPackSize());
}

void OpenIGTLinkSender::sendStatus(const std::string& device, bool ok, const std::string& text)
{
  const std::string name = deviceNameFor(device);
  auto message = igtl::StatusMessage::New();
  message->SetDeviceName(name.c_str());
  message->SetCode(ok ? igtl::StatusMessage::STATUS_OK : igtl::StatusMessage::STATUS_UNKNOWN_ERROR);
  message->SetSubCode(0);
  message->SetErrorName(ok ? "" : "update failed");
  message->SetStatusString(text.c_str());
  message->Pack();
  transmit("STATUS", name, message->GetPackPointer(), message->GetPackSize());
}

UpdateSendSummary sendUpdate(const UpdateFolderContents& contents, OpenIGTLinkSender& sender,
                             const std::function<void(const std::string&)>& progress)
{
  using Clock = std::chrono::steady_clock;
  UpdateSendSummary summary;
  const auto tell = [&](const std::string& what) {
    if (progress) progress(what);
  };
  const auto timed = [](double& total, const auto& work) {
    const auto start = Clock::now();
    work();
    total += seconds(start);
  };
  ScalarImage::Pointer intraop;
  timed(summary.readSeconds, [&] { intraop = readScalarVolume(contents.intraopImage); });
  tell("IMAGE intraop_image");
  timed(summary.sendSeconds, [&] { sender.sendImage("intraop_image", *intraop); });
  for (const UpdateVolume& volume : contents.warpedVolumes) {
    tell("IMAGE " + volume.name);
    if (volume.isLabelMap) {
      LabelImage::Pointer labels;
      timed(summary.readSeconds, [&] { labels = readLabelVolume(volume.path); });
      timed(summary.sendSeconds, [&] { sender.sendLabelImage(volume.name, *labels); });
    } else {
      ScalarImage::Pointer image;
      timed(summary.readSeconds, [&] { image = readScalarVolume(volume.path); });
      timed(summary.sendSeconds, [&] { sender.sendImage(volume.name, *image); });
    }
  }
  if (contents.rigidTransform) {
    SpatialTransform::Pointer rigid;
    timed(summary.readSeconds, [&] { rigid = readTransform(*contents.rigidTransform); });
    tell("TRANSFORM rigid_to_preop");
    timed(summary.sendSeconds, [&] { sender.sendTransform("rigid_to_preop", *rigid); });
  }
  if (contents.brainSurface) {
    vtkSmartPointer<vtkPointSet> model;
    timed(summary.readSeconds, [&] { model = readModel(*contents.brainSurface); });
    auto* surface = vtkPolyData::SafeDownCast(model);
    if (!surface) throw InputError(contents.brainSurface->string() + ": not a surface (vtkPolyData)");
    tell("POLYDATA brain_surface");
    timed(summary.sendSeconds, [&] { sender.sendSurface("brain_surface", *surface, "DisplacementMagnitude"); });
  }
  tell("STATUS brainshift");
  timed(summary.sendSeconds, [&] {
    sender.sendStatus("brainshift", true, "BrainShift update of " + contents.folder.string());
    sender.checkStillConnected();
  });
  summary.messages = sender.messagesSent();
  summary.bytes = sender.bytesSent();
  return summary;
}

} // namespace brainshift
