// ITK transform files: rigid transforms through .tfm and .h5, a composite through .h5, and a
// displacement field as a vector image (x = y + d(y)); the refusals; the affine parameters.
#include "BrainShiftTestingSupport.h"
#include "SyntheticData.h"
#include "TransformIO.h"

#include <itkCompositeTransform.h>

#include <fstream>
#include <vector>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;
using brainshift::testing::point;
using CompositeTransform = itk::CompositeTransform<double, 3>;

/// Points inside and outside the field's grid.
const std::vector<PhysicalPoint>& probePoints()
{
  static const std::vector<PhysicalPoint> points = {point(0, 0, 0),      point(3.3, -2.1, 5.7), point(-7.5, 6.2, -1.4),
                                                    point(11.9, 8, -8),  point(-4.4, 1.1, 9.0), point(60, -45, 30)};
  return points;
}

void checkSameMapping(const SpatialTransform* expected, const SpatialTransform* actual, double tolerance,
                      const std::string& what)
{
  BS_CHECK_MSG(actual != nullptr, what);
  for (const PhysicalPoint& y : probePoints()) {
    const auto a = expected->TransformPoint(y);
    const auto b = actual->TransformPoint(y);
    BS_CHECK_MSG(a.EuclideanDistanceTo(b) < tolerance, what << ": at " << y << ", " << a << " became " << b);
  }
}

} // namespace

int TransformIOTest(int, char*[])
{
  return brainshift::testing::runTest("TransformIOTest", [&] {
    const fs::path folder = testing::temporaryFolder("TransformIOTest");
    const auto rigid = testing::makeRigidTransform();

    // Rigid: .tfm (text) and .h5 keep the transform and its type.
    for (const char* name : {"rigid.tfm", "rigid.h5"}) {
      writeTransform(rigid, folder / name);
      const SpatialTransform::Pointer read = readTransform(folder / name);
      checkSameMapping(rigid, read, 1e-6, name);
      BS_CHECK_MSG(std::string(read->GetNameOfClass()) == "Euler3DTransform", read->GetNameOfClass());
      BS_CHECK(isLinearTransform(read));
    }

    // The affine parameters are ITK's matrix and offset (y -> A y + t, the centre folded in).
    const AffineParameters affine = affineParametersOf(rigid);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) BS_CHECK_NEAR(affine.matrix[r][c], rigid->GetMatrix()(r, c), 1e-12);
      BS_CHECK_NEAR(affine.translation[r], rigid->GetOffset()[r], 1e-12);
    }

    // A displacement field as a vector image: readTransform maps y to y + d(y). The field is smooth,
    // on an oblique 7x6x5 grid of 3.5 mm.
    const DisplacementFieldImage::Pointer field = testing::makeSmoothDisplacementField(
      testing::grid({{7, 6, 5}}, {3.5, 3.5, 3.5}, point(-10, -9, -7), testing::rotationAbout(0, 1, 3, 15.0)), 0.1);
    const SpatialTransform::Pointer warp = makeDisplacementFieldTransform(field);
    BS_CHECK(!isLinearTransform(warp));
    BS_CHECK_THROWS(affineParametersOf(warp), std::invalid_argument, "not linear");
    writeTransform(warp, folder / "warp.nrrd");
    const SpatialTransform::Pointer warpRead = readTransform(folder / "warp.nrrd");
    checkSameMapping(warp, warpRead, 1e-4, "warp.nrrd");
    BS_CHECK(displacementFieldOf(warpRead) != nullptr);
    for (const itk::Index<3>& index : {itk::Index<3>{{0, 0, 0}}, itk::Index<3>{{3, 2, 1}}, itk::Index<3>{{6, 5, 4}}}) {
      PhysicalPoint y;
      field->TransformIndexToPhysicalPoint(index, y);
      const auto x = warpRead->TransformPoint(y);
      for (int k = 0; k < 3; ++k) BS_CHECK_NEAR(x[k], y[k] + field->GetPixel(index)[k], 1e-4);
    }

    // A composite (field and rigid) through .h5, and only through .h5.
    auto composite = CompositeTransform::New();
    composite->AddTransform(warp);
    composite->AddTransform(rigid);
    writeTransform(composite, folder / "total.h5");
    const SpatialTransform::Pointer compositeRead = readTransform(folder / "total.h5");
    BS_CHECK(dynamic_cast<const CompositeTransform*>(compositeRead.GetPointer()) != nullptr);
    BS_CHECK_MSG(describeTransform(compositeRead) == "CompositeTransform (2 transforms)", describeTransform(compositeRead));
    checkSameMapping(composite, compositeRead, 1e-6, "total.h5");
    BS_CHECK_THROWS(writeTransform(composite, folder / "total.tfm"), std::invalid_argument, ".h5");
    BS_CHECK(!fs::exists(folder / "total.tfm"));

    // Files that are not transforms.
    const fs::path notes = folder / "notes.tfm";
    std::ofstream(notes) << "These are not the transforms you are looking for.\n";
    BS_CHECK_THROWS(readTransform(notes), InputError, notes.string());
    const fs::path table = folder / "table.txt";
    std::ofstream(table) << "a,b,c\n1,2,3\n";
    BS_CHECK_THROWS(readTransform(table), InputError, table.string());
    BS_CHECK_THROWS(readTransform(folder / "missing.h5"), InputError, (folder / "missing.h5").string());
    // A garbled transform line (found by the fuzz run of issue 18): ITK's text parser threw
    // std::out_of_range, an internal error; it is bad input naming the file.
    const fs::path garbled = folder / "garbled.tfm";
    std::ofstream(garbled) << "#Insight Transfoile V1.0\n#Transform 0\nTransform: VersorRigid3DTransform_double_3_3\n"
                              "Transform: VersorRigid3DTrble_3_3\nParameters: 0 0 0 1 2 3\nFixedParameters: 0 0 0\n";
    BS_CHECK_THROWS(readTransform(garbled), InputError, garbled.string() + ": cannot read the transform");
  });
}
