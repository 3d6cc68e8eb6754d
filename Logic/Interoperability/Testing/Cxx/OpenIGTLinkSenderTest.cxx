// OpenIGTLink out, against a receiver built on libOpenIGTLink alone: an oblique volume keeps its
// grid (read back as 3D Slicer's OpenIGTLinkIF reads it) and its exact values, labels travel as
// uint16, the transform takes preoperative points to intraoperative ones, the surface arrives in
// RAS with its scalars, device names are capped at 20 characters, and a server that is not there
// or hangs up is a ConnectionError.
#include "BrainShiftTestingSupport.h"
#include "IgtlTestReceiver.h"
#include "OpenIGTLinkSender.h"
#include "SyntheticData.h"

#include <igtlImageMessage.h>
#include <igtlStatusMessage.h>
#include <vtkFloatArray.h>
#include <vtkPointData.h>

#include <future>

int OpenIGTLinkSenderTest(int, char*[])
{
  return brainshift::testing::runTest("OpenIGTLinkSenderTest", [] {
    using namespace brainshift;
    using namespace brainshift::testing;
    BS_CHECK(parseIgtlEndpoint("localhost:18944").port == 18944);
    BS_CHECK(parseIgtlEndpoint("10.0.0.5:1").host == "10.0.0.5");
    BS_CHECK_THROWS(parseIgtlEndpoint("localhost"), InputError, "HOST:PORT");
    BS_CHECK_THROWS(parseIgtlEndpoint("localhost:70000"), InputError, "1 to 65535");
    BS_CHECK_THROWS(parseIgtlEndpoint("localhost:x1"), InputError, "1 to 65535");

    const ImageGeometry g = grid({5, 4, 3}, {0.7, 1.1, 2.3}, point(10, -20, 30), rotationAbout(1, 2, 3, 30));
    auto image = imageOn<ScalarImage>(g, [](const PhysicalPoint& p) { return static_cast<float>(p[0] * 0.5 + p[1] - p[2] / 3); });
    auto labels = imageOn<LabelImage>(g, [](const PhysicalPoint& p) { return static_cast<LabelPixel>(p[2] > 30 ? 4 : 2); });
    auto rigid = makeRigidTransform();
    auto surface = makeTriangleSurface();
    auto magnitude = vtkSmartPointer<vtkFloatArray>::New();
    magnitude->SetName("DisplacementMagnitude");
    for (vtkIdType i = 0; i < surface->GetNumberOfPoints(); ++i) magnitude->InsertNextValue(0.25f * static_cast<float>(i));
    surface->GetPointData()->AddArray(magnitude);

    IgtlTestReceiver receiver;
    auto received = std::async(std::launch::async, [&] { return receiver.receiveSession(); });
    {
      OpenIGTLinkSender sender({"localhost", receiver.port()});
      sender.sendImage("warped_preop_image", *image);
      sender.sendLabelImage("a_name_longer_than_twenty", *labels);
      sender.sendTransform("rigid_to_preop", *rigid);
      sender.sendSurface("brain_surface", *surface, "DisplacementMagnitude");
      sender.sendStatus("brainshift", true, "done");
      sender.checkStillConnected();
      BS_CHECK(sender.messagesSent() == 5);
    }
    const std::vector<ReceivedMessage> messages = received.get();
    BS_CHECK(messages.size() == 5);
    BS_CHECK(messages[0].type == "IMAGE" && messages[0].device == "warped_preop_image");
    BS_CHECK(messages[0].coordinate == igtl::ImageMessage::COORDINATE_RAS);
    BS_CHECK_MSG(messages[0].geometry.sameGridAs(g, 1e-5), messages[0].geometry.describe() + " vs " + g.describe());
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) BS_CHECK_NEAR(messages[0].geometry.direction[r][c], g.direction[r][c], 1e-6);
    BS_CHECK(messages[0].values.size() == g.numberOfVoxels() * 4);
    BS_CHECK(std::memcmp(messages[0].values.data(), image->GetBufferPointer(), messages[0].values.size()) == 0);
    BS_CHECK(messages[1].device == "a_name_longer_than_t" && messages[1].scalarType == igtl::ImageMessage::TYPE_UINT16);
    BS_CHECK(std::memcmp(messages[1].values.data(), labels->GetBufferPointer(), g.numberOfVoxels() * 2) == 0);
    // TRANSFORM: matrix (RAS, preop -> intraop) then the file's transform (LPS, intraop -> preop) is the identity.
    const auto& m = messages[2].matrix;
    const double preop[3] = {12, -34, 56};
    const double ras[3] = {-preop[0], -preop[1], preop[2]};
    itk::Point<double, 3> intraop;
    for (int r = 0; r < 3; ++r) {
      double v = m[r][3];
      for (int c = 0; c < 3; ++c) v += m[r][c] * ras[c];
      intraop[r] = r < 2 ? -v : v;
    }
    const auto back = rigid->TransformPoint(intraop);
    for (int r = 0; r < 3; ++r) BS_CHECK_NEAR(back[r], preop[r], 1e-4);
    BS_CHECK(messages[3].type == "POLYDATA" && messages[3].polygons == surface->GetNumberOfPolys());
    double p[3];
    surface->GetPoint(1, p);
    BS_CHECK_NEAR(messages[3].points[1][0], -p[0], 1e-5);
    BS_CHECK_NEAR(messages[3].points[1][1], -p[1], 1e-5);
    BS_CHECK_NEAR(messages[3].points[1][2], p[2], 1e-5);
    BS_CHECK(messages[3].attributeName == "DisplacementMagnitude" && static_cast<vtkIdType>(messages[3].attribute.size()) == magnitude->GetNumberOfTuples());
    BS_CHECK_NEAR(messages[3].attribute[2], 0.5, 1e-7);
    BS_CHECK(messages[4].type == "STATUS" && messages[4].statusCode == igtl::StatusMessage::STATUS_OK);

    // A server that hangs up on the client; a port where nothing listens.
    IgtlTestReceiver refusing;
    auto refused = std::async(std::launch::async, [&] { refusing.refuseOne(); });
    BS_CHECK_THROWS(
      {
        OpenIGTLinkSender sender({"127.0.0.1", refusing.port()});
        refused.get();
        for (int i = 0; i < 20; ++i) sender.sendImage("warped_preop_image", *image);
        sender.checkStillConnected();
      },
      ConnectionError, "closed the connection");
    int closedPort = 0;
    {
      IgtlTestReceiver gone;
      closedPort = gone.port();
    }
    BS_CHECK_THROWS(OpenIGTLinkSender({"127.0.0.1", closedPort}), ConnectionError, "cannot connect");
    BS_CHECK_THROWS(OpenIGTLinkSender({"no-such-host.invalid", 18944}), ConnectionError, "unknown host");
  });
}
