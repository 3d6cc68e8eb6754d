#pragma once
// An OpenIGTLink server for a whole watch session (libOpenIGTLink, protocol version 2): clients
// (3D Slicer's OpenIGTLinkIF connector in client mode, a navigation system) connect at any time;
// each published update (the messages `send` sends, packed once by OpenIGTLinkSender) is pushed to
// every connected client, and the latest one to a client as it connects. A client that hangs up, or
// stops reading, is dropped and reported; that is never fatal to the session. A client may also
// send an IMAGE with device name `intraop` (the scanner's side): it is written as a NIfTI file
// (RAS -> LPS as the sender turns LPS -> RAS) and queued as a new scan.
//
// The sockets live on one thread of the server's own; the caller only publishes and takes scans.
#include "ImageTypes.h"
#include "OpenIGTLinkSender.h"

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace igtl {
class ImageMessage;
}

namespace brainshift {

/// Something that happened to a client: "connected", "dropped", "received scan", "refused message".
struct IgtlServerEvent {
  std::string client; ///< ADDRESS:PORT of the peer
  std::string event;
  std::string detail;
};

/// A scan a client sent (IMAGE `intraop`), written into the server's receive folder.
struct ReceivedScan {
  std::filesystem::path file;
  std::string client;
};

/// The device name of an incoming scan.
inline constexpr const char* igtlIncomingScanDevice = "intraop";

/// The image of an IMAGE message on BrainShift's grid (LPS): scalar values of any of the protocol's
/// types as float, the matrix's centre translation turned back into the first voxel's position.
/// InputError naming the device when the message holds several components or a sub-volume.
ScalarImage::Pointer scalarImageFromIgtl(igtl::ImageMessage& message);

class OpenIGTLinkServer {
public:
  /// Listens on `address` ("" or "0.0.0.0": every address of this machine) and `port`; scans that
  /// clients send are written into `receiveFolder` (created). ConnectionError when the port cannot
  /// be taken. `onEvent` (may be empty) is called on the server's thread.
  OpenIGTLinkServer(const std::string& address, int port, std::filesystem::path receiveFolder,
                    std::function<void(const IgtlServerEvent&)> onEvent = {});
  /// Pushes what was published and not yet sent, then closes every connection.
  ~OpenIGTLinkServer();
  OpenIGTLinkServer(const OpenIGTLinkServer&) = delete;
  OpenIGTLinkServer& operator=(const OpenIGTLinkServer&) = delete;

  int port() const;

  /// Pushes what was published and not yet sent, then closes every connection and stops
  /// listening. Nothing more can be published; the events stay.
  void close();

  /// Pushes `messages` to every connected client; with `keepForLaterClients`, also to each client
  /// that connects afterwards, until the next such update.
  void publish(std::vector<PackedIgtlMessage> messages, bool keepForLaterClients = true);

  /// The next scan a client sent, waiting up to `seconds` for one.
  std::optional<ReceivedScan> nextScan(double seconds);

  /// Everything that happened so far, in order.
  std::vector<IgtlServerEvent> events() const;

private:
  struct State;
  std::unique_ptr<State> state_;
};

} // namespace brainshift
