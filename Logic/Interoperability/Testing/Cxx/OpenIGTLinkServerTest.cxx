// The session's OpenIGTLink server against clients built on libOpenIGTLink alone: an IMAGE turned
// back into BrainShift's grid (oblique, RAS or LPS, big-endian int16), the latest update sent to a
// client as it connects and each published one to every client, an IMAGE intraop written as a scan
// with the sent grid and values, a client that hangs up dropped and reported, a port already taken
// a ConnectionError. Every wait is bounded.
#include "BrainShiftTestingSupport.h"
#include "IgtlTestReceiver.h"
#include "OpenIGTLinkServer.h"
#include "SyntheticData.h"
#include "VolumeIO.h"

#include <igtlClientSocket.h>
#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtl_util.h>

#include <chrono>
#include <cstring>
#include <thread>

namespace {
using namespace brainshift;

/// The message as a receiver unpacks it from `packed` (header, then body).
igtl::ImageMessage::Pointer unpackImage(const PackedIgtlMessage& packed)
{
  auto header = igtl::MessageHeader::New();
  header->InitPack();
  std::memcpy(header->GetPackPointer(), packed.bytes.data(), header->GetPackSize());
  header->Unpack();
  auto message = igtl::ImageMessage::New();
  message->SetMessageHeader(header);
  message->AllocatePack();
  std::memcpy(message->GetPackBodyPointer(), packed.bytes.data() + header->GetPackSize(), message->GetPackBodySize());
  BS_CHECK(message->Unpack(1) & igtl::MessageHeader::UNPACK_BODY);
  return message;
}

igtl::ClientSocket::Pointer connectTo(int port)
{
  auto socket = igtl::ClientSocket::New();
  BS_CHECK(socket->ConnectToServer("127.0.0.1", port) == 0);
  socket->SetReceiveTimeout(20000);
  return socket;
}

bool waitFor(const OpenIGTLinkServer& server, const std::string& event)
{
  for (int i = 0; i < 200; ++i) { // at most 20 s
    for (const IgtlServerEvent& e : server.events())
      if (e.event == event) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return false;
}

void checkImageConversion(const ImageGeometry& g, const ScalarImage& image)
{
  std::vector<PackedIgtlMessage> packed;
  OpenIGTLinkSender recorder(packed);
  recorder.sendImage("intraop", image);
  BS_CHECK(packed.size() == 1 && packed[0].type == "IMAGE" && packed[0].device == "intraop");
  ScalarImage::Pointer back = scalarImageFromIgtl(*unpackImage(packed[0]));
  BS_CHECK_MSG(ImageGeometry::of(back.GetPointer()).sameGridAs(g, 1e-5), ImageGeometry::of(back.GetPointer()).describe());
  BS_CHECK(std::memcmp(back->GetBufferPointer(), image.GetBufferPointer(), g.numberOfVoxels() * sizeof(float)) == 0);

  // int16, big endian, LPS: values and grid as meant, not as the bytes fall on this machine.
  auto message = igtl::ImageMessage::New();
  message->SetDeviceName("intraop");
  message->SetDimensions(2, 1, 1);
  message->SetSpacing(1.5f, 2.0f, 3.0f);
  message->SetScalarType(igtl::ImageMessage::TYPE_INT16);
  message->SetEndian(igtl::ImageMessage::ENDIAN_BIG);
  message->SetCoordinateSystem(igtl::ImageMessage::COORDINATE_LPS);
  igtl::Matrix4x4 m;
  igtl::IdentityMatrix(m);
  m[0][3] = 10.75f; // the centre: first voxel at x = 10
  message->SetMatrix(m);
  message->AllocateScalars();
  const unsigned char bigEndian[4] = {0x01, 0x02, 0xff, 0xfe}; // 258, -2
  std::memcpy(message->GetScalarPointer(), bigEndian, 4);
  ScalarImage::Pointer small = scalarImageFromIgtl(*message);
  BS_CHECK(small->GetBufferPointer()[0] == 258.0f && small->GetBufferPointer()[1] == -2.0f);
  BS_CHECK_NEAR(small->GetOrigin()[0], 10.0, 1e-6);
  message->SetNumComponents(3);
  BS_CHECK_THROWS(scalarImageFromIgtl(*message), InputError, "components");
}
} // namespace

int OpenIGTLinkServerTest(int, char*[])
{
  return brainshift::testing::runTest("OpenIGTLinkServerTest", [] {
    using namespace brainshift::testing;
    registerIOFactories();
    const ImageGeometry g = grid({5, 4, 3}, {0.7, 1.1, 2.3}, point(10, -20, 30), rotationAbout(1, 2, 3, 30));
    auto image = imageOn<ScalarImage>(g, [](const PhysicalPoint& p) { return static_cast<float>(p[0] * 0.5 + p[1] - p[2] / 3); });
    checkImageConversion(g, *image);

    const std::filesystem::path folder = temporaryFolder("OpenIGTLinkServerTest");
    OpenIGTLinkServer server("127.0.0.1", 0, folder / "received");
    BS_CHECK(server.port() > 0);
    BS_CHECK_THROWS(OpenIGTLinkServer("127.0.0.1", server.port(), folder / "other"), ConnectionError, "cannot listen");
    std::vector<PackedIgtlMessage> update;
    {
      OpenIGTLinkSender recorder(update);
      recorder.sendImage("warped_preop_image", *image);
      recorder.sendStatus("brainshift", true, "first");
    }
    server.publish(update);
    auto first = connectTo(server.port()); // connects after the update: receives it on connecting
    const auto received = receiveUntilStatus(first);
    BS_CHECK(received.size() == 2 && received[0].device == "warped_preop_image" && received[1].statusText == "first");
    BS_CHECK(std::memcmp(received[0].values.data(), image->GetBufferPointer(), received[0].values.size()) == 0);

    auto dropping = connectTo(server.port());
    BS_CHECK(receiveUntilStatus(dropping).size() == 2);
    dropping->CloseSocket();
    BS_CHECK_MSG(waitFor(server, "dropped"), "the client that hung up is not reported");

    // Other messages are skipped, a scan that cannot be taken is refused; the connection stays.
    std::vector<PackedIgtlMessage> other;
    OpenIGTLinkSender(other).sendStatus("scanner", true, "ready");
    OpenIGTLinkSender(other).sendImage("intraop", *image);
    other[1].bytes.back() ^= 0x5a; // a damaged value: the CRC check fails
    for (const PackedIgtlMessage& m : other) BS_CHECK(first->Send(m.bytes.data(), static_cast<int>(m.bytes.size())) == 1);
    BS_CHECK(waitFor(server, "ignored message") && waitFor(server, "refused message"));

    // IMAGE intraop from the client: a scan file with the sent grid and values.
    std::vector<PackedIgtlMessage> scan;
    OpenIGTLinkSender(scan).sendImage("intraop", *image);
    BS_CHECK(first->Send(scan[0].bytes.data(), static_cast<int>(scan[0].bytes.size())) == 1);
    const std::optional<ReceivedScan> taken = server.nextScan(20);
    BS_CHECK(taken && taken->file == folder / "received" / "intraop-001.nii.gz");
    ScalarImage::Pointer written = readScalarVolume(taken->file);
    BS_CHECK(ImageGeometry::of(written.GetPointer()).sameGridAs(g, 1e-5));
    BS_CHECK(std::memcmp(written->GetBufferPointer(), image->GetBufferPointer(), g.numberOfVoxels() * sizeof(float)) == 0);
    BS_CHECK(!server.nextScan(0.01));

    // A later update reaches the client still connected; closing flushes it.
    std::vector<PackedIgtlMessage> later;
    OpenIGTLinkSender(later).sendStatus("brainshift", true, "second");
    server.publish(later);
    server.close();
    const auto second = receiveUntilStatus(first);
    BS_CHECK(second.size() == 1 && second[0].statusText == "second");
  });
}
