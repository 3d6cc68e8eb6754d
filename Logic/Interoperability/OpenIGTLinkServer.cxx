#include "OpenIGTLinkServer.h"

#include "IgtlConnectedSocket.h"
#include "VolumeIO.h"

#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtlServerSocket.h>
#include <igtl_util.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>

namespace brainshift {
namespace fs = std::filesystem;
using detail::ConnectedSocket;

namespace {
template <class T>
void convertValues(const unsigned char* source, std::size_t count, bool swap, float* target)
{
  for (std::size_t i = 0; i < count; ++i) {
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, source + i * sizeof(T), sizeof(T));
    if (swap) std::reverse(bytes, bytes + sizeof(T));
    T value;
    std::memcpy(&value, bytes, sizeof(T));
    target[i] = static_cast<float>(value);
  }
}
} // namespace

ScalarImage::Pointer scalarImageFromIgtl(igtl::ImageMessage& message)
{
  const std::string device = message.GetDeviceName();
  int size[3], subSize[3], subOffset[3];
  float spacing[3];
  igtl::Matrix4x4 m;
  message.GetDimensions(size);
  message.GetSubVolume(subSize, subOffset);
  message.GetSpacing(spacing);
  message.GetMatrix(m);
  if (message.GetNumComponents() != 1) throw InputError("IMAGE " + device + ": several components per voxel");
  if (subSize[0] != size[0] || subSize[1] != size[1] || subSize[2] != size[2] || subOffset[0] != 0 || subOffset[1] != 0 ||
      subOffset[2] != 0 || size[0] < 1 || size[1] < 1 || size[2] < 1) {
    throw InputError("IMAGE " + device + ": a sub-volume or an empty image, not a whole scan");
  }
  const bool lps = message.GetCoordinateSystem() == igtl::ImageMessage::COORDINATE_LPS;
  const double flip[3] = {lps ? 1.0 : -1.0, lps ? 1.0 : -1.0, 1.0};
  ImageGeometry geometry;
  for (int c = 0; c < 3; ++c) {
    geometry.size[c] = static_cast<itk::SizeValueType>(size[c]);
    geometry.spacing[c] = spacing[c];
    if (!(spacing[c] > 0)) throw InputError("IMAGE " + device + ": spacing must be positive");
  }
  for (int r = 0; r < 3; ++r) {
    double corner = m[r][3]; // the translation is the volume's centre
    for (int c = 0; c < 3; ++c) {
      const double norm = std::sqrt(m[0][c] * m[0][c] + m[1][c] * m[1][c] + m[2][c] * m[2][c]);
      if (!(norm > 0)) throw InputError("IMAGE " + device + ": a zero axis in the matrix");
      corner -= m[r][c] / norm * spacing[c] * (size[c] - 1) / 2.0;
      geometry.direction[r][c] = flip[r] * m[r][c] / norm;
    }
    geometry.origin[r] = flip[r] * corner;
  }
  ScalarImage::Pointer image = geometry.allocate<ScalarImage>();
  const auto* values = static_cast<const unsigned char*>(message.GetScalarPointer());
  const bool hostLittle = igtl_is_little_endian() != 0;
  const bool swap = (message.GetEndian() == igtl::ImageMessage::ENDIAN_LITTLE) != hostLittle;
  const std::size_t n = geometry.numberOfVoxels();
  float* out = image->GetBufferPointer();
  switch (message.GetScalarType()) {
  case igtl::ImageMessage::TYPE_INT8: convertValues<std::int8_t>(values, n, swap, out); break;
  case igtl::ImageMessage::TYPE_UINT8: convertValues<std::uint8_t>(values, n, swap, out); break;
  case igtl::ImageMessage::TYPE_INT16: convertValues<std::int16_t>(values, n, swap, out); break;
  case igtl::ImageMessage::TYPE_UINT16: convertValues<std::uint16_t>(values, n, swap, out); break;
  case igtl::ImageMessage::TYPE_INT32: convertValues<std::int32_t>(values, n, swap, out); break;
  case igtl::ImageMessage::TYPE_UINT32: convertValues<std::uint32_t>(values, n, swap, out); break;
  case igtl::ImageMessage::TYPE_FLOAT32: convertValues<float>(values, n, swap, out); break;
  case igtl::ImageMessage::TYPE_FLOAT64: convertValues<double>(values, n, swap, out); break;
  default: throw InputError("IMAGE " + device + ": unknown scalar type " + std::to_string(message.GetScalarType()));
  }
  return image;
}

namespace {
/// libOpenIGTLink's server socket, listening on one address, accepting into ConnectedSockets.
class ListeningSocket : public igtl::ServerSocket {
public:
  typedef ListeningSocket Self;
  typedef igtl::ServerSocket Superclass;
  typedef igtl::SmartPointer<Self> Pointer;
  typedef igtl::SmartPointer<const Self> ConstPointer;
  igtlTypeMacro(ListeningSocket, igtl::ServerSocket);
  igtlNewMacro(ListeningSocket);

  void listenOn(const std::string& address, int port)
  {
    const std::string where = (address.empty() ? std::string("0.0.0.0") : address) + ":" + std::to_string(port);
    sockaddr_in server{};
    server.sin_family = AF_INET;
    server.sin_port = htons(static_cast<std::uint16_t>(port));
    server.sin_addr.s_addr = htonl(INADDR_ANY);
    if (!address.empty() && inet_pton(AF_INET, address.c_str(), &server.sin_addr) != 1) {
      throw ConnectionError("OpenIGTLink server " + where + ": '" + address + "' is not an IPv4 address of this machine");
    }
    m_SocketDescriptor = CreateSocket();
    int on = 1;
    setsockopt(m_SocketDescriptor, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on);
    if (m_SocketDescriptor < 0 || bind(m_SocketDescriptor, reinterpret_cast<sockaddr*>(&server), sizeof server) != 0 ||
        Listen(m_SocketDescriptor) != 0) {
      const std::string reason = std::strerror(errno);
      CloseSocket();
      throw ConnectionError("OpenIGTLink server " + where + ": cannot listen (" + reason + ")");
    }
  }
  int descriptor() const { return m_SocketDescriptor; }
  /// The next waiting client (the caller saw the socket readable); null if it went away.
  ConnectedSocket::Pointer acceptOne()
  {
    const int client = Accept(m_SocketDescriptor);
    if (client < 0) return nullptr;
    ConnectedSocket::Pointer socket = ConnectedSocket::New();
    socket->adopt(client);
    return socket;
  }

protected:
  ListeningSocket() = default;
  ~ListeningSocket() = default;
};

using Update = std::shared_ptr<const std::vector<PackedIgtlMessage>>;

struct Client {
  ConnectedSocket::Pointer socket;
  std::string name;
  bool dropped = false;
};

/// Sends every byte without raising SIGPIPE; the system's reason otherwise.
std::optional<std::string> sendAll(int descriptor, const std::string& bytes)
{
  std::size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = ::send(descriptor, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) return std::string("stopped reading");
      return std::string(std::strerror(errno));
    }
    sent += static_cast<std::size_t>(n);
  }
  return std::nullopt;
}
} // namespace

struct OpenIGTLinkServer::State {
  ListeningSocket::Pointer listener = ListeningSocket::New();
  fs::path receiveFolder;
  int port = 0;
  std::function<void(const IgtlServerEvent&)> onEvent;
  std::thread thread;

  mutable std::mutex mutex; // guards what follows
  std::condition_variable scanArrived;
  std::deque<std::pair<Update, bool>> outgoing;
  std::deque<ReceivedScan> scans;
  std::vector<IgtlServerEvent> events;
  bool stopping = false;

  // the server thread's own
  std::vector<Client> clients;
  Update latest;
  int received = 0;

  void report(const std::string& client, const std::string& event, const std::string& detail)
  {
    IgtlServerEvent e{client, event, detail};
    {
      std::lock_guard<std::mutex> lock(mutex);
      events.push_back(e);
    }
    if (onEvent) onEvent(e);
  }
  void drop(Client& client, const std::string& reason)
  {
    if (client.dropped) return;
    client.dropped = true;
    client.socket->CloseSocket();
    report(client.name, "dropped", reason);
  }
  void push(Client& client, const std::vector<PackedIgtlMessage>& messages)
  {
    for (const PackedIgtlMessage& m : messages) {
      if (client.dropped) return;
      if (auto failure = sendAll(client.socket->descriptor(), m.bytes)) {
        drop(client, *failure + " while receiving " + m.type + " " + m.device);
      }
    }
  }
  void run();
  void serveOnce(int timeoutMs);
  void accept();
  void receiveFrom(Client& client);
  void takeScan(Client& client, igtl::MessageHeader* header);
};

void OpenIGTLinkServer::State::run()
{
  // Signals are the main thread's; a peer that hung up shows as a failed send, not SIGPIPE.
  sigset_t blocked;
  sigemptyset(&blocked);
  for (int s : {SIGPIPE, SIGINT, SIGTERM, SIGHUP}) sigaddset(&blocked, s);
  pthread_sigmask(SIG_BLOCK, &blocked, nullptr);
  while (true) {
    std::deque<std::pair<Update, bool>> work;
    bool stop;
    {
      std::lock_guard<std::mutex> lock(mutex);
      work.swap(outgoing);
      stop = stopping;
    }
    for (const auto& [update, keep] : work) {
      if (keep) latest = update;
      for (Client& client : clients) push(client, *update);
    }
    clients.erase(std::remove_if(clients.begin(), clients.end(), [](const Client& c) { return c.dropped; }), clients.end());
    if (stop && work.empty()) break;
    serveOnce(work.empty() ? 100 : 0);
  }
  for (Client& client : clients) client.socket->CloseSocket();
  listener->CloseSocket();
}

void OpenIGTLinkServer::State::serveOnce(int timeoutMs)
{
  std::vector<pollfd> watched{{listener->descriptor(), POLLIN, 0}};
  for (const Client& client : clients) watched.push_back({client.socket->descriptor(), POLLIN, 0});
  if (::poll(watched.data(), watched.size(), timeoutMs) <= 0) return;
  for (std::size_t i = 1; i < watched.size(); ++i) {
    if (watched[i].revents & (POLLIN | POLLHUP | POLLERR)) receiveFrom(clients[i - 1]);
  }
  if (watched[0].revents & POLLIN) accept();
}

void OpenIGTLinkServer::State::accept()
{
  ConnectedSocket::Pointer socket = listener->acceptOne();
  if (!socket) return;
  sockaddr_in peer{};
  socklen_t length = sizeof peer;
  char address[INET_ADDRSTRLEN] = "?";
  int port = 0;
  if (getpeername(socket->descriptor(), reinterpret_cast<sockaddr*>(&peer), &length) == 0) {
    inet_ntop(AF_INET, &peer.sin_addr, address, sizeof address);
    port = ntohs(peer.sin_port);
  }
  socket->SetSendTimeout(10000); // a client that stops reading for 10 s is dropped
  socket->SetReceiveTimeout(10000);
  clients.push_back({socket, std::string(address) + ":" + std::to_string(port), false});
  report(clients.back().name, "connected", latest ? "sent the latest update" : "no update yet");
  if (latest) push(clients.back(), *latest);
}

void OpenIGTLinkServer::State::receiveFrom(Client& client)
{
  if (client.dropped) return;
  char byte;
  const ssize_t peeked = ::recv(client.socket->descriptor(), &byte, 1, MSG_PEEK | MSG_DONTWAIT);
  if (peeked == 0) return drop(client, "disconnected");
  if (peeked < 0) {
    if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) drop(client, std::strerror(errno));
    return;
  }
  auto header = igtl::MessageHeader::New();
  header->InitPack();
  if (client.socket->Receive(header->GetPackPointer(), header->GetPackSize()) != header->GetPackSize()) {
    return drop(client, "connection lost inside a message header");
  }
  header->Unpack();
  const std::string type = header->GetDeviceType(), device = header->GetDeviceName();
  if (type == "IMAGE" && device == igtlIncomingScanDevice) return takeScan(client, header);
  if (client.socket->Skip(static_cast<int>(header->GetBodySizeToRead()), 1) == 0 && header->GetBodySizeToRead() > 0) {
    return drop(client, "connection lost inside " + type + " " + device);
  }
  report(client.name, "ignored message", type + " " + device + " (only IMAGE " + igtlIncomingScanDevice + " is taken)");
}

void OpenIGTLinkServer::State::takeScan(Client& client, igtl::MessageHeader* header)
{
  auto message = igtl::ImageMessage::New();
  message->SetMessageHeader(header);
  message->AllocatePack();
  if (client.socket->Receive(message->GetPackBodyPointer(), message->GetPackBodySize()) != message->GetPackBodySize()) {
    return drop(client, "connection lost inside IMAGE " + std::string(igtlIncomingScanDevice));
  }
  if (!(message->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) {
    return report(client.name, "refused message", "IMAGE intraop: CRC check or unpacking failed");
  }
  char name[32];
  std::snprintf(name, sizeof name, "intraop-%03d.nii.gz", received + 1);
  const fs::path file = receiveFolder / name;
  try {
    ScalarImage::Pointer image = scalarImageFromIgtl(*message);
    writeScalarVolume(image, file); // atomically
  } catch (const std::exception& e) {
    return report(client.name, "refused message", e.what());
  }
  ++received;
  report(client.name, "received scan", file.string());
  std::lock_guard<std::mutex> lock(mutex);
  scans.push_back({file, client.name});
  scanArrived.notify_all();
}

OpenIGTLinkServer::OpenIGTLinkServer(const std::string& address, int port, fs::path receiveFolder,
                                     std::function<void(const IgtlServerEvent&)> onEvent)
  : state_(std::make_unique<State>())
{
  std::error_code ec;
  fs::create_directories(receiveFolder, ec);
  if (ec) throw InputError(receiveFolder.string() + ": cannot create the folder for received scans (" + ec.message() + ")");
  registerIOFactories();
  state_->receiveFolder = std::move(receiveFolder);
  state_->onEvent = std::move(onEvent);
  state_->listener->listenOn(address, port);
  state_->port = state_->listener->GetServerPort();
  state_->thread = std::thread([state = state_.get()] { state->run(); });
}

OpenIGTLinkServer::~OpenIGTLinkServer()
{
  close();
}

void OpenIGTLinkServer::close()
{
  {
    std::lock_guard<std::mutex> lock(state_->mutex);
    state_->stopping = true;
  }
  if (state_->thread.joinable()) state_->thread.join();
}

int OpenIGTLinkServer::port() const
{
  return state_->port;
}

void OpenIGTLinkServer::publish(std::vector<PackedIgtlMessage> messages, bool keepForLaterClients)
{
  auto update = std::make_shared<const std::vector<PackedIgtlMessage>>(std::move(messages));
  std::lock_guard<std::mutex> lock(state_->mutex);
  state_->outgoing.emplace_back(std::move(update), keepForLaterClients);
}

std::optional<ReceivedScan> OpenIGTLinkServer::nextScan(double seconds)
{
  std::unique_lock<std::mutex> lock(state_->mutex);
  state_->scanArrived.wait_for(lock, std::chrono::duration<double>(seconds), [&] { return !state_->scans.empty(); });
  if (state_->scans.empty()) return std::nullopt;
  ReceivedScan scan = state_->scans.front();
  state_->scans.pop_front();
  return scan;
}

std::vector<IgtlServerEvent> OpenIGTLinkServer::events() const
{
  std::lock_guard<std::mutex> lock(state_->mutex);
  return state_->events;
}

} // namespace brainshift
