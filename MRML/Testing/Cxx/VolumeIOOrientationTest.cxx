// Orientation through every volume format: an anisotropic, oblique phantom written and read
// back keeps its spheres where they belong in LPS, and its grid. A NIfTI file whose qform and
// sform disagree is read with one warning.
#include "BrainShiftTestingSupport.h"
#include "OrientationPhantom.h"
#include "SyntheticData.h"
#include "VolumeIO.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <vector>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;

void checkSameGeometry(const ScalarImage* expected, const ScalarImage* actual, const std::string& what)
{
  BS_CHECK_MSG(expected->GetLargestPossibleRegion().GetSize() == actual->GetLargestPossibleRegion().GetSize(), what);
  for (unsigned r = 0; r < 3; ++r) {
    BS_CHECK_MSG(std::abs(actual->GetOrigin()[r] - expected->GetOrigin()[r]) < 1e-3,
                 what << ": origin " << actual->GetOrigin() << ", expected " << expected->GetOrigin());
    BS_CHECK_MSG(std::abs(actual->GetSpacing()[r] - expected->GetSpacing()[r]) < 1e-3,
                 what << ": spacing " << actual->GetSpacing() << ", expected " << expected->GetSpacing());
    for (unsigned c = 0; c < 3; ++c) {
      BS_CHECK_MSG(std::abs(actual->GetDirection()(r, c) - expected->GetDirection()(r, c)) < 1e-3,
                   what << ": direction\n" << actual->GetDirection() << "expected\n" << expected->GetDirection());
    }
  }
}

void checkSpheres(const testing::OrientationPhantom& phantom, const ScalarImage* image, const std::string& what)
{
  const std::pair<float, PhysicalPoint> spheres[] = {{300.f, phantom.left}, {200.f, phantom.anterior}, {100.f, phantom.superior}};
  for (const auto& [value, where] : spheres) {
    const PhysicalPoint centroid = testing::centroidOfValue(image, value);
    BS_CHECK_MSG(centroid.EuclideanDistanceTo(where) < 0.5,
                 what << ": the sphere of value " << value << " is at " << centroid << ", expected " << where);
  }
}

std::vector<char> readBytes(const fs::path& path)
{
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeBytes(const fs::path& path, const std::vector<char>& bytes)
{
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

template <class T>
T fieldAt(const std::vector<char>& header, std::size_t offset)
{
  T value;
  std::memcpy(&value, header.data() + offset, sizeof(T));
  return value;
}

template <class T>
void setFieldAt(std::vector<char>& header, std::size_t offset, T value)
{
  std::memcpy(header.data() + offset, &value, sizeof(T));
}
} // namespace

int VolumeIOOrientationTest(int, char*[])
{
  return brainshift::testing::runTest("VolumeIOOrientationTest", [&] {
    const fs::path folder = testing::temporaryFolder("VolumeIOOrientationTest");

    ScalarImage::SpacingType spacing;
    spacing[0] = 1.2;
    spacing[1] = 0.9;
    spacing[2] = 2.0;
    const PhysicalPoint centre{{12.5, -30.0, 41.0}};
    const testing::OrientationPhantom phantom =
      testing::makeOrientationPhantom({{72, 90, 44}}, spacing, testing::rotationAbout(1, -1, 2, 20.0), centre);
    checkSpheres(phantom, phantom.image, "the phantom itself");

    for (const char* name : {"phantom.nii.gz", "phantom.nrrd", "phantom.mha"}) {
      const fs::path file = folder / name;
      writeScalarVolume(phantom.image, file);
      Warnings warnings;
      const ScalarImage::Pointer image = readScalarVolume(file, &warnings);
      checkSameGeometry(phantom.image, image, name);
      checkSpheres(phantom, image, name);
      BS_CHECK_MSG(warnings.empty(), name << ": " << warnings.front());
    }

    // DICOM: int16 on disk; the phantom's values are integers, so they survive.
    const fs::path dicom = folder / "dicom";
    testing::writeDicomSeries(phantom.image, dicom);
    const ScalarImage::Pointer series = readScalarVolume(dicom);
    checkSameGeometry(phantom.image, series, "DICOM series");
    checkSpheres(phantom, series, "DICOM series");

    // NIfTI qform against sform: ITK writes both; a copy whose sform is 5 mm off gets one warning.
    const fs::path consistent = folder / "consistent.nii";
    writeScalarVolume(phantom.image, consistent);
    std::vector<char> bytes = readBytes(consistent);
    BS_CHECK(bytes.size() > 352 && fieldAt<std::int32_t>(bytes, 0) == 348); // uncompressed NIfTI-1
    BS_CHECK(fieldAt<std::int16_t>(bytes, 252) > 0);                        // qform_code
    BS_CHECK(fieldAt<std::int16_t>(bytes, 254) > 0);                        // sform_code
    Warnings none;
    readScalarVolume(consistent, &none);
    BS_CHECK_MSG(none.empty(), none.front());

    const fs::path disagreeing = folder / "disagreeing.nii";
    const std::size_t sformRowX = 280, offsetColumn = 3 * sizeof(float);
    setFieldAt<float>(bytes, sformRowX + offsetColumn, fieldAt<float>(bytes, sformRowX + offsetColumn) + 5.0f);
    writeBytes(disagreeing, bytes);
    Warnings warnings;
    readScalarVolume(disagreeing, &warnings);
    BS_CHECK_MSG(warnings.size() == 1, warnings.size() << " warnings");
    BS_CHECK_MSG(warnings.front().find("qform and sform disagree") != std::string::npos, warnings.front());
    BS_CHECK_MSG(warnings.front().find(disagreeing.string()) != std::string::npos, warnings.front());
  });
}
