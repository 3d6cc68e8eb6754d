#include "IgtlTestReceiver.h"

#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtlPolyDataMessage.h>
#include <igtlStatusMessage.h>
#include <igtlTransformMessage.h>

#include <cmath>
#include <cstring>
#include <stdexcept>

namespace brainshift::testing {

std::uint64_t fnv1a(const void* data, std::size_t bytes)
{
  std::uint64_t hash = 1469598103934665603ull;
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) hash = (hash ^ p[i]) * 1099511628211ull;
  return hash;
}

IgtlTestReceiver::IgtlTestReceiver() : server_(igtl::ServerSocket::New())
{
  if (server_->CreateServer(0) != 0) throw std::runtime_error("cannot create an OpenIGTLink server");
  port_ = server_->GetServerPort();
}

namespace {
template <class TMessage>
typename TMessage::Pointer unpack(igtl::ClientSocket* socket, igtl::MessageHeader* header)
{
  auto message = TMessage::New();
  message->SetMessageHeader(header);
  message->AllocatePack();
  if (socket->Receive(message->GetPackBodyPointer(), message->GetPackBodySize()) != message->GetPackBodySize()) {
    throw std::runtime_error("connection lost inside a message body");
  }
  if (!(message->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) {
    throw std::runtime_error(std::string("CRC or unpack failure in ") + header->GetDeviceType() + " " + header->GetDeviceName());
  }
  return message;
}

/// The grid as OpenIGTLinkIF builds it (igtlioImageConverter::IGTLToVTKTransform), then in LPS.
void readImage(igtl::ImageMessage* image, ReceivedMessage& out)
{
  int size[3];
  float spacing[3];
  igtl::Matrix4x4 m;
  image->GetDimensions(size);
  image->GetSpacing(spacing);
  image->GetMatrix(m);
  const double flip[3] = {-1, -1, 1};
  for (int c = 0; c < 3; ++c) {
    out.geometry.size[c] = static_cast<itk::SizeValueType>(size[c]);
    out.geometry.spacing[c] = spacing[c];
  }
  for (int r = 0; r < 3; ++r) {
    double corner = m[r][3];
    for (int c = 0; c < 3; ++c) {
      const double norm = std::sqrt(m[0][c] * m[0][c] + m[1][c] * m[1][c] + m[2][c] * m[2][c]);
      corner -= m[r][c] / norm * spacing[c] * (size[c] - 1) / 2.0;
      out.geometry.direction[r][c] = flip[r] * m[r][c] / norm;
    }
    out.geometry.origin[r] = flip[r] * corner;
  }
  out.scalarType = image->GetScalarType();
  out.coordinate = image->GetCoordinateSystem();
  const auto* scalars = static_cast<const unsigned char*>(image->GetScalarPointer());
  out.values.assign(scalars, scalars + image->GetImageSize());
}

void readPolyData(igtl::PolyDataMessage* poly, ReceivedMessage& out)
{
  igtl::PolyDataPointArray* points = poly->GetPoints();
  for (int i = 0; points && i < points->GetNumberOfPoints(); ++i) {
    std::array<float, 3> p;
    points->GetPoint(i, p.data());
    out.points.push_back(p);
  }
  out.polygons = poly->GetPolygons() ? static_cast<int>(poly->GetPolygons()->GetNumberOfCells()) : 0;
  if (poly->GetNumberOfAttributes() > 0) {
    igtl::PolyDataAttribute* attribute = poly->GetAttribute(0);
    out.attributeName = attribute->GetName();
    out.attribute.resize(attribute->GetSize() * attribute->GetNumberOfComponents());
    attribute->GetData(out.attribute.data());
  }
}
} // namespace

bool receiveMessage(igtl::ClientSocket* socket, ReceivedMessage& out)
{
  auto header = igtl::MessageHeader::New();
  header->InitPack();
  const int n = socket->Receive(header->GetPackPointer(), header->GetPackSize());
  if (n == 0) return false; // the peer closed the connection (or the receive timed out)
  if (n != header->GetPackSize()) throw std::runtime_error("connection lost inside a message header");
  header->Unpack();
  out = ReceivedMessage{};
  out.type = header->GetDeviceType();
  out.device = header->GetDeviceName();
  if (out.type == "IMAGE") {
    readImage(unpack<igtl::ImageMessage>(socket, header), out);
  } else if (out.type == "TRANSFORM") {
    igtl::Matrix4x4 m;
    unpack<igtl::TransformMessage>(socket, header)->GetMatrix(m);
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) out.matrix[r][c] = m[r][c];
  } else if (out.type == "POLYDATA") {
    readPolyData(unpack<igtl::PolyDataMessage>(socket, header), out);
  } else if (out.type == "STATUS") {
    auto status = unpack<igtl::StatusMessage>(socket, header);
    out.statusCode = status->GetCode();
    out.statusText = status->GetStatusString();
  } else {
    socket->Skip(header->GetBodySizeToRead(), 0);
  }
  return true;
}

std::vector<ReceivedMessage> receiveUntilStatus(igtl::ClientSocket* socket)
{
  std::vector<ReceivedMessage> messages;
  ReceivedMessage m;
  while (receiveMessage(socket, m)) {
    messages.push_back(m);
    if (m.type == "STATUS") return messages;
  }
  throw std::runtime_error("the connection ended (or timed out) after " + std::to_string(messages.size()) +
                           " messages, before a STATUS");
}

std::vector<ReceivedMessage> IgtlTestReceiver::receiveSession(unsigned long timeoutMs)
{
  igtl::ClientSocket::Pointer socket = server_->WaitForConnection(timeoutMs);
  if (!socket) throw std::runtime_error("no client connected");
  std::vector<ReceivedMessage> messages;
  ReceivedMessage out;
  while (receiveMessage(socket, out)) messages.push_back(std::move(out));
  socket->CloseSocket();
  return messages;
}

void IgtlTestReceiver::refuseOne(unsigned long timeoutMs)
{
  igtl::ClientSocket::Pointer socket = server_->WaitForConnection(timeoutMs);
  if (socket) socket->CloseSocket();
}

} // namespace brainshift::testing
