#pragma once
// The receiving side of the OpenIGTLink tests, on libOpenIGTLink alone: a server that accepts one
// client and unpacks every message (CRC checked) the way 3D Slicer's OpenIGTLinkIF reads it.
#include "ImageTypes.h"

#include <igtlServerSocket.h>

#include <array>
#include <string>
#include <vector>

namespace brainshift::testing {

/// One message as received.
struct ReceivedMessage {
  std::string type, device;
  // IMAGE: the grid in LPS, as OpenIGTLinkIF computes it (the matrix's origin is the volume's centre)
  ImageGeometry geometry;
  int scalarType = 0, coordinate = 0;
  std::vector<unsigned char> values; ///< IMAGE scalars, little endian as sent
  // TRANSFORM: the 4x4 matrix (RAS)
  std::array<std::array<double, 4>, 4> matrix{};
  // POLYDATA: points (RAS), polygon count, the first point scalar attribute
  std::vector<std::array<float, 3>> points;
  int polygons = 0;
  std::string attributeName;
  std::vector<float> attribute;
  // STATUS
  int statusCode = 0;
  std::string statusText;
};

/// A server on a free port of this machine.
class IgtlTestReceiver {
public:
  IgtlTestReceiver();
  int port() const { return port_; }
  /// Accepts one client (waits up to `timeoutMs`) and receives until STATUS, then until the client
  /// closes. Throws on a CRC or unpack failure.
  std::vector<ReceivedMessage> receiveSession(unsigned long timeoutMs = 20000);
  /// Accepts one client and closes the connection at once (a server that refuses the client).
  void refuseOne(unsigned long timeoutMs = 20000);

private:
  igtl::ServerSocket::Pointer server_;
  int port_ = 0;
};

/// Receives one message (CRC checked); false when the peer closed the connection or the socket's
/// receive timeout passed. Throws on a truncated message or an unpack failure.
bool receiveMessage(igtl::ClientSocket* socket, ReceivedMessage& message);
/// Receives messages up to and with the next STATUS; throws if the connection ends first.
std::vector<ReceivedMessage> receiveUntilStatus(igtl::ClientSocket* socket);

/// 64-bit FNV-1a of bytes: the checksum the tests print and compare.
std::uint64_t fnv1a(const void* data, std::size_t bytes);

} // namespace brainshift::testing
