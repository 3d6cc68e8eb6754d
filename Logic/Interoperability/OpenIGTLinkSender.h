#pragma once
// Sends an update to a navigation system over OpenIGTLink (protocol version 2, libOpenIGTLink):
// IMAGE, TRANSFORM, POLYDATA and STATUS messages as 3D Slicer's OpenIGTLinkIF connector reads them.
//
// The protocol's space is RAS (3D Slicer's world); BrainShift's is LPS, so x and y change sign on
// the way out. An IMAGE message's matrix holds the unit directions of i, j and k and, as its
// translation, the centre of the volume (not its first voxel): OpenIGTLinkIF places the volume by
// subtracting half the field of view again.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"
#include "TransformIO.h"

#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

class vtkPolyData;

namespace brainshift {

struct UpdateFolderContents;

/// The connection could not be made or was lost. Bad input for the command line (exit 2): the
/// address is wrong or nothing is listening there.
class ConnectionError : public InputError {
public:
  using InputError::InputError;
};

/// HOST:PORT of an OpenIGTLink server.
struct IgtlEndpoint {
  std::string host;
  int port = 0;
  std::string text() const { return host + ":" + std::to_string(port); }
};

/// Parses "HOST:PORT" (port 1-65535). InputError naming the text otherwise.
IgtlEndpoint parseIgtlEndpoint(const std::string& text);

using Matrix4 = std::array<std::array<double, 4>, 4>;

/// The matrix of an IMAGE message for a volume on `geometry` (LPS): columns 0-2 the unit
/// directions of i, j, k in RAS; column 3 the centre of the volume in RAS.
Matrix4 igtlImageMatrix(const ImageGeometry& geometry);

/// The matrix of the TRANSFORM message for a linear intraop_to_preop transform (LPS, resampling):
/// what 3D Slicer shows for the same .tfm file, the transform to parent in RAS (preoperative to
/// intraoperative), under which the preoperative-frame surface overlays the intraoperative scan.
Matrix4 igtlTransformMatrix(const SpatialTransform& intraopToPreop);

/// OpenIGTLink's device names hold at most 20 characters.
constexpr std::size_t igtlDeviceNameLength = 20;

/// One packed message (header, body and CRC) as it goes onto the wire.
struct PackedIgtlMessage {
  std::string type, device;
  std::string bytes;
};

/// One connection to an OpenIGTLink server. Every message is packed with its CRC and sent whole;
/// a failure to send is a ConnectionError naming the server and the message.
class OpenIGTLinkSender {
public:
  /// Packs the messages into `recorder` instead of sending them (a server sends them to its
  /// clients: OpenIGTLinkServer). `recorder` must outlive the sender.
  explicit OpenIGTLinkSender(std::vector<PackedIgtlMessage>& recorder);
  /// Connects to `endpoint`. ConnectionError when the host is unknown or refuses the connection.
  /// `sendTimeoutMs`: a server that stops reading for this long is taken as lost.
  explicit OpenIGTLinkSender(const IgtlEndpoint& endpoint, int sendTimeoutMs = 10000);
  ~OpenIGTLinkSender();
  OpenIGTLinkSender(const OpenIGTLinkSender&) = delete;
  OpenIGTLinkSender& operator=(const OpenIGTLinkSender&) = delete;

  /// IMAGE, float32 values (little endian) on the image's grid.
  void sendImage(const std::string& device, const ScalarImage& image);
  /// IMAGE, uint16 label values.
  void sendLabelImage(const std::string& device, const LabelImage& labels);
  /// TRANSFORM: igtlTransformMatrix(intraopToPreop).
  void sendTransform(const std::string& device, const SpatialTransform& intraopToPreop);
  /// POLYDATA: points in RAS, polygons, and the point scalars `scalarArray` if the surface has them.
  void sendSurface(const std::string& device, vtkPolyData& lpsSurface, const std::string& scalarArray);
  /// STATUS: OK or an error code with `text`.
  void sendStatus(const std::string& device, bool ok, const std::string& text);

  /// Throws ConnectionError if the server has closed or reset the connection (a server that
  /// accepts and hangs up shows it only after the data is gone into the socket's buffers).
  void checkStillConnected();

  std::size_t bytesSent() const { return bytesSent_; }
  int messagesSent() const { return messagesSent_; }
  const IgtlEndpoint& endpoint() const { return endpoint_; }

private:
  struct Socket;
  void transmit(const char* type, const std::string& device, const void* data, std::size_t bytes);
  std::unique_ptr<Socket> socket_;
  std::vector<PackedIgtlMessage>* recorder_ = nullptr;
  IgtlEndpoint endpoint_;
  std::size_t bytesSent_ = 0;
  int messagesSent_ = 0;
};

/// What `sendUpdate` sent, and how long the reading and the sending took.
struct UpdateSendSummary {
  int messages = 0;
  std::size_t bytes = 0;
  double readSeconds = 0;  ///< reading the folder's files
  double sendSeconds = 0;  ///< packing and sending the messages
};

/// Sends the update in `contents`: IMAGE `intraop_image`, an IMAGE per warped volume (device name
/// = node name), TRANSFORM `rigid_to_preop`, POLYDATA `brain_surface` (with DisplacementMagnitude),
/// then STATUS `brainshift`. `progress` (may be empty) hears "TYPE device" before each message.
UpdateSendSummary sendUpdate(const UpdateFolderContents& contents, OpenIGTLinkSender& sender,
                             const std::function<void(const std::string&)>& progress = {});

} // namespace brainshift
