#pragma once
// Internal to Logic/Interoperability: libOpenIGTLink's client socket on a connection made or
// accepted here. libOpenIGTLink's ConnectToServer reports a failure only on stderr and loses errno,
// and the descriptor is needed to see a peer that hung up (poll, MSG_PEEK) and to send without
// SIGPIPE.
#include <igtlClientSocket.h>

namespace brainshift::detail {

/// libOpenIGTLink's client socket on a connection made here: ConnectToServer reports a failure only
/// on stderr and loses errno, and the descriptor is needed to see a server that hung up.
class ConnectedSocket : public igtl::ClientSocket {
public:
  typedef ConnectedSocket Self;
  typedef igtl::ClientSocket Superclass;
  typedef igtl::SmartPointer<Self> Pointer;
  typedef igtl::SmartPointer<const Self> ConstPointer;
  igtlTypeMacro(ConnectedSocket, igtl::ClientSocket);
  igtlNewMacro(ConnectedSocket);
  void adopt(int descriptor) { m_SocketDescriptor = descriptor; }
  int descriptor() const { return m_SocketDescriptor; }

protected:
  ConnectedSocket() = default;
  ~ConnectedSocket() = default;
};

} // namespace brainshift::detail
