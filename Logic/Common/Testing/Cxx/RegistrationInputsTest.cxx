// The inputs of an update are checked before any work: grids, empty labels, constant images,
// overlay arguments. Each error names the file.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "RegistrationInputs.h"
#include "VolumeIO.h"

namespace {
using namespace brainshift;

template <class TImage>
typename TImage::Pointer makeImage(unsigned size, double spacing, typename TImage::PixelType fill)
{
  auto image = TImage::New();
  typename TImage::RegionType region;
  region.SetSize({{size, size, size}});
  image->SetRegions(region);
  typename TImage::SpacingType s;
  s.Fill(spacing);
  image->SetSpacing(s);
  image->Allocate();
  image->FillBuffer(fill);
  return image;
}
} // namespace

int RegistrationInputsTest(int, char*[])
{
  return brainshift::testing::runTest("RegistrationInputsTest", [] {
    namespace fs = std::filesystem;
    const fs::path folder = testing::temporaryFolder("RegistrationInputsTest");
    auto image = makeImage<ScalarImage>(12, 2.0, 0.0f);
    image->SetPixel({{5, 5, 5}}, 100.0f);
    auto labels = makeImage<LabelImage>(12, 2.0, 0);
    labels->SetPixel({{5, 5, 5}}, 2);
    writeScalarVolume(image, folder / "preop.nii.gz");
    writeLabelVolume(labels, folder / "labels.nii.gz");
    writeScalarVolume(image, folder / "intraop.nrrd");
    writeScalarVolume(makeImage<ScalarImage>(12, 2.0, 7.0f), folder / "constant.nii.gz");
    writeLabelVolume(makeImage<LabelImage>(12, 2.5, 2), folder / "other-grid.nii.gz");
    writeLabelVolume(makeImage<LabelImage>(12, 2.0, 1), folder / "no-brain.nii.gz");

    RegistrationInputPaths paths{folder / "preop.nii.gz", folder / "labels.nii.gz", folder / "intraop.nrrd",
                                 {parseOverlayArgument("fmri=" + (folder / "preop.nii.gz").string())}};
    const RegistrationInputs inputs = loadRegistrationInputs(paths);
    BS_CHECK(inputs.overlays.size() == 1 && inputs.overlays[0].name == "fmri");
    BS_CHECK(inputs.preopLabels->GetPixel({{5, 5, 5}}) == 2);

    auto refused = [&](RegistrationInputPaths p, const std::string& file, const std::string& fragment) {
      BS_CHECK_THROWS(loadRegistrationInputs(p), InputError, file);
      BS_CHECK_THROWS(loadRegistrationInputs(p), InputError, fragment);
    };
    RegistrationInputPaths p = paths;
    p.preopLabels = folder / "other-grid.nii.gz";
    refused(p, "other-grid.nii.gz", "another grid");
    p = paths;
    p.preopLabels = folder / "no-brain.nii.gz";
    refused(p, "no-brain.nii.gz", "no brain tissue");
    p = paths;
    p.intraopImage = folder / "constant.nii.gz";
    refused(p, "constant.nii.gz", "constant image");
    p = paths;
    p.intraopImage = folder / "absent.nii.gz";
    refused(p, "absent.nii.gz", "no such file");
    p = paths;
    p.overlays.push_back(p.overlays.front());
    refused(p, "fmri", "given twice");

    BS_CHECK_THROWS(parseOverlayArgument("fmri"), InputError, "NAME=FILE");
    BS_CHECK_THROWS(parseOverlayArgument("=x.nii"), InputError, "NAME=FILE");
    BS_CHECK_THROWS(parseOverlayArgument("f/mri=x.nii"), InputError, "letters, digits");
    BS_CHECK(parseOverlayArgument("mra_1=a=b.nii").file == "a=b.nii");
  });
}
