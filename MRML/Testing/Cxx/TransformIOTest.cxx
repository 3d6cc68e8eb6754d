// ITK transform files: rigid transforms through .tfm and .h5, a composite through .h5, and a
// displacement field as a vector image (x = y + d(y)); the refusals; the affine parameters.
#include "BrainShiftTestingSupport.h"
#include "SyntheticData.h"
#include "TransformIO.h"

#include <itkCompositeTransform.h>
#include <itkTransformFileWriter.h>
#include <itk_hdf5.h>

#include <csignal>
#include <fstream>
#include <map>
#include <vector>

#include <sys/resource.h>

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

/// A dataset of an HDF5 file: its text (a string), or its numbers and their stored width.
struct StoredDataset {
  std::string text;
  std::vector<double> values;
  std::size_t bytesPerValue = 0;
  bool operator==(const StoredDataset& o) const { return text == o.text && values == o.values && bytesPerValue == o.bytesPerValue; }
};

herr_t collectDataset(hid_t file, const char* name, const H5O_info_t* info, void* into)
{
  if (info->type != H5O_TYPE_DATASET) return 0;
  auto& datasets = *static_cast<std::map<std::string, StoredDataset>*>(into);
  StoredDataset& d = datasets[name];
  const hid_t set = H5Dopen2(file, name, H5P_DEFAULT);
  const hid_t type = H5Dget_type(set);
  if (H5Tget_class(type) == H5T_STRING) {
    const hid_t text = H5Tcopy(H5T_C_S1);
    H5Tset_size(text, H5T_VARIABLE);
    char* value[1] = {nullptr};
    if (H5Dread(set, text, H5S_ALL, H5S_ALL, H5P_DEFAULT, value) >= 0 && value[0]) d.text = value[0];
    H5free_memory(value[0]);
    H5Tclose(text);
  } else {
    const hid_t space = H5Dget_space(set);
    d.values.resize(std::size_t(H5Sget_simple_extent_npoints(space)));
    d.bytesPerValue = H5Tget_size(type);
    if (!d.values.empty()) H5Dread(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, d.values.data());
    H5Sclose(space);
  }
  H5Tclose(type);
  H5Dclose(set);
  return 0;
}

/// Every dataset of an HDF5 file by its path.
std::map<std::string, StoredDataset> datasetsOf(const fs::path& file)
{
  std::map<std::string, StoredDataset> datasets;
  const hid_t h5 = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  BS_CHECK_MSG(h5 >= 0, file.string() + ": not an HDF5 file");
  H5Ovisit(h5, H5_INDEX_NAME, H5_ITER_INC, collectDataset, &datasets);
  H5Fclose(h5);
  return datasets;
}

/// The file BrainShift writes holds the datasets of the file ITK's own writer makes, value for value.
void checkSameFileAsItkWrites(const SpatialTransform* transform, const fs::path& folder, const std::string& name)
{
  writeTransform(transform, folder / (name + ".h5"));
  auto writer = itk::TransformFileWriterTemplate<double>::New();
  writer->SetInput(transform);
  writer->SetFileName((folder / (name + "-itk.h5")).string());
  writer->Update();
  BS_CHECK_MSG(fs::file_size(folder / (name + ".h5")) == fs::file_size(folder / (name + "-itk.h5")),
               name << ": " << fs::file_size(folder / (name + ".h5")) << " bytes against ITK's " << fs::file_size(folder / (name + "-itk.h5")));
  const auto ours = datasetsOf(folder / (name + ".h5")), itks = datasetsOf(folder / (name + "-itk.h5"));
  BS_CHECK_MSG(ours.size() == itks.size() && ours.size() >= 6, name << ": " << ours.size() << " datasets against ITK's " << itks.size());
  for (const auto& [path, dataset] : itks) {
    BS_CHECK_MSG(ours.count(path) == 1, name << ": no " << path);
    BS_CHECK_MSG(ours.at(path) == dataset, name << ": " << path << " differs from ITK's (\"" << ours.at(path).text << "\" against \""
                                              << dataset.text << "\", " << ours.at(path).values.size() << " against "
                                              << dataset.values.size() << " values)");
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
    // Written from the field's voxels (ITK's writer copies them twice: 0.5 s of a later scan), the
    // same file as ITK writes: a field alone and the composite.
    checkSameFileAsItkWrites(warp, folder, "field");
    checkSameFileAsItkWrites(composite, folder, "composite");
    BS_CHECK_MSG(datasetsOf(folder / "composite.h5").at("TransformGroup/1/TransformType").text == "DisplacementFieldTransform_double_3_3",
                 "the composite's first part is its field");
    BS_CHECK(datasetsOf(folder / "composite.h5").at("TransformGroup/1/TransformParameters").values.size() == 7 * 6 * 5 * 3);
    auto nested = CompositeTransform::New();
    nested->AddTransform(composite);
    BS_CHECK_THROWS(writeTransform(nested, folder / "nested.h5"), std::invalid_argument, "within a composite");
    BS_CHECK_THROWS(writeTransform(composite, folder / "total.tfm"), std::invalid_argument, ".h5");
    BS_CHECK(!fs::exists(folder / "total.tfm"));

    // A disk that fills while the field is written (a 1.5 MB field under a 256 KiB file-size
    // limit): one error naming the file, the file before it kept, no temporary left.
    {
      const SpatialTransform::Pointer large = makeDisplacementFieldTransform(
        testing::makeSmoothDisplacementField(testing::grid({{40, 40, 40}}, {2, 2, 2}, point(-40, -40, -40), testing::rotationAbout(0, 0, 1, 0)), 0.1));
      const fs::path kept = folder / "kept.h5";
      writeTransform(warp, kept);
      const auto keptBytes = fs::file_size(kept);
      const auto previousSignal = std::signal(SIGXFSZ, SIG_IGN); // a write past the limit fails with EFBIG
      rlimit before{};
      getrlimit(RLIMIT_FSIZE, &before);
      rlimit limited = before;
      limited.rlim_cur = 256 * 1024;
      setrlimit(RLIMIT_FSIZE, &limited);
      // HDF5's error handler is the caller's: after BrainShift writes (refused here) it is the one
      // the caller had, function and data (a handler of the test's own, not HDF5's default).
      H5E_auto2_t defaultPrinter = nullptr;
      void* defaultPrinterData = nullptr;
      H5Eget_auto2(H5E_DEFAULT, &defaultPrinter, &defaultPrinterData);
      BS_CHECK(defaultPrinter != nullptr); // HDF5's own, not switched off by the writes above
      int ownHandlerCalls = 0;
      const H5E_auto2_t ownHandler = [](hid_t, void* calls) -> herr_t {
        ++*static_cast<int*>(calls);
        return 0;
      };
      H5Eset_auto2(H5E_DEFAULT, ownHandler, &ownHandlerCalls);
      bool refused = false;
      std::string message;
      try {
        writeTransform(large, kept);
      } catch (const MethodError& e) {
        refused = true;
        message = e.what();
      }
      setrlimit(RLIMIT_FSIZE, &before);
      std::signal(SIGXFSZ, previousSignal);
      BS_CHECK_MSG(refused && message.find("cannot write " + kept.string()) != std::string::npos, message);
      BS_CHECK(fs::file_size(kept) == keptBytes);
      H5E_auto2_t printerAfter = nullptr;
      void* printerDataAfter = nullptr;
      H5Eget_auto2(H5E_DEFAULT, &printerAfter, &printerDataAfter);
      BS_CHECK(printerAfter == ownHandler && printerDataAfter == &ownHandlerCalls);
      BS_CHECK_MSG(ownHandlerCalls == 0, ownHandlerCalls); // nothing reported through it while BrainShift wrote
      H5Eset_auto2(H5E_DEFAULT, defaultPrinter, defaultPrinterData);
      for (const auto& entry : fs::directory_iterator(folder)) {
        BS_CHECK_MSG(entry.path().filename().string().rfind(".tmp-", 0) != 0, entry.path().string() + " was left behind");
      }
      writeTransform(large, kept); // and without the limit, the whole field
      BS_CHECK(datasetsOf(kept).at("TransformGroup/0/TransformParameters").values.size() == 40 * 40 * 40 * 3);
    }

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
