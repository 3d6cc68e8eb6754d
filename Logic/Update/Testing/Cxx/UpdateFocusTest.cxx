// Where the surgeon looks first (updateFocusPoint), against points known by construction: the
// voxel of the overlay's largest |value| (a negative t counts by its magnitude; NaN voxels are
// ignored; the confidence map is never an overlay to look at), else the centroid of the warped
// tumour, else nothing.
#include "BrainShiftTestingSupport.h"
#include "Scene.h"
#include "UpdateFocus.h"

#include <cmath>
#include <limits>

namespace {
using namespace brainshift;

template <class Image>
typename Image::Pointer grid()
{
  auto image = Image::New();
  typename Image::SizeType size;
  size.Fill(10);
  image->SetRegions(size);
  const double spacing[3] = {2.0, 2.0, 3.0}, origin[3] = {-10.0, 5.0, 20.0};
  image->SetSpacing(spacing);
  image->SetOrigin(origin);
  image->Allocate();
  image->FillBuffer(0);
  return image;
}

void checkPoint(const std::optional<std::array<double, 3>>& p, double x, double y, double z)
{
  BS_CHECK(p.has_value());
  BS_CHECK_NEAR((*p)[0], x, 1e-9);
  BS_CHECK_NEAR((*p)[1], y, 1e-9);
  BS_CHECK_NEAR((*p)[2], z, 1e-9);
}
} // namespace

int UpdateFocusTest(int, char*[])
{
  return brainshift::testing::runTest("UpdateFocusTest", [] {
    Scene scene;
    BS_CHECK(!updateFocusPoint(scene)); // nothing to look at

    // The warped tumour: voxels (2..3, 4, 5) -> centroid x = -10 + 2 * 2.5, y = 5 + 2 * 4, z = 20 + 3 * 5.
    auto labels = grid<LabelImage>();
    for (long i : {2, 3}) labels->SetPixel({{i, 4, 5}}, 4);
    labels->SetPixel({{7, 7, 7}}, 2); // parenchyma does not count
    scene.add(LabelMapVolumeNode::create("warped preop labels", labels));
    checkPoint(updateFocusPoint(scene), -5.0, 13.0, 35.0);

    // The confidence map is not an overlay to look at, even where it is largest.
    auto uncertainty = grid<ScalarImage>();
    uncertainty->SetPixel({{9, 9, 9}}, 50.0f);
    scene.add(ScalarVolumeNode::create(DisplacementUncertaintyNodeName, uncertainty))->setRole("overlay");
    checkPoint(updateFocusPoint(scene), -5.0, 13.0, 35.0);

    // A statistics overlay: its strongest |t| (negative here), NaN ignored.
    auto fmri = grid<ScalarImage>();
    fmri->SetPixel({{1, 2, 3}}, 4.0f);
    fmri->SetPixel({{6, 1, 8}}, -7.5f);
    fmri->SetPixel({{0, 0, 0}}, std::numeric_limits<float>::quiet_NaN());
    scene.add(ScalarVolumeNode::create("warped fmri", fmri))->setRole("overlay");
    checkPoint(updateFocusPoint(scene), -10.0 + 2 * 6, 5.0 + 2 * 1, 20.0 + 3 * 8);

    // An overlay without a finite voxel falls back to the tumour.
    Scene blank;
    auto empty = grid<ScalarImage>();
    empty->FillBuffer(std::numeric_limits<float>::quiet_NaN());
    blank.add(ScalarVolumeNode::create("warped mra", empty))->setRole("overlay");
    BS_CHECK(!updateFocusPoint(blank));
    blank.add(LabelMapVolumeNode::create("warped preop labels", labels));
    checkPoint(updateFocusPoint(blank), -5.0, 13.0, 35.0);
  });
}
