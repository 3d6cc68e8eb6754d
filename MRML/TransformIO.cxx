#include "TransformIO.h"

#include "AtomicItkWrite.h"
#include "LibraryMessages.h"
#include "FileNames.h"
#include "VolumeIO.h"

#include <itkCompositeTransform.h>
#include <itkDisplacementFieldTransform.h>
#include <itkMatrixOffsetTransformBase.h>
#include <itkTransformFileReader.h>
#include <itkTransformFileWriter.h>
#include <itkVersion.h>
#include <itk_hdf5.h>
#include <itksys/SystemInformation.hxx>

#include <algorithm>
#include <cstring>
#include <type_traits>

#include <fcntl.h>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
using CompositeTransform = itk::CompositeTransform<double, 3>;
using FieldTransform = itk::DisplacementFieldTransform<double, 3>;
using DoubleField = FieldTransform::DisplacementFieldType;
using MatrixOffsetTransform = itk::MatrixOffsetTransformBase<double, 3, 3>;

bool isTransformFile(const fs::path& path)
{
  return hasExtension(path, {".tfm", ".txt", ".mat", ".h5", ".hdf5"});
}

/// An HDF5 object closed when it leaves scope.
class Hdf5Handle {
public:
  Hdf5Handle(hid_t id, herr_t (*close)(hid_t), const char* what)
    : id_(id), close_(close)
  {
    if (id_ < 0) throw std::runtime_error(what);
  }
  ~Hdf5Handle()
  {
    if (id_ >= 0) close_(id_);
  }
  /// Closes it now, throwing if that fails.
  void close(const char* what)
  {
    const herr_t status = close_(id_);
    id_ = -1;
    if (status < 0) throw std::runtime_error(what);
  }
  Hdf5Handle(const Hdf5Handle&) = delete;
  Hdf5Handle& operator=(const Hdf5Handle&) = delete;
  hid_t id() const { return id_; }

private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

/// HDF5's printing of its error stack off while this lives (the failures are thrown, naming the
/// file), and the handler this thread had before (function and data) put back after it: other HDF5
/// users (ITK's reader, the command line's own setting) keep theirs. A handler HDF5 cannot report
/// (one set through the old H5Eset_auto1) is left alone.
class QuietHdf5Errors {
public:
  QuietHdf5Errors()
  {
    restore_ = H5Eget_auto2(H5E_DEFAULT, &printer_, &data_) >= 0;
    if (restore_) H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~QuietHdf5Errors()
  {
    if (restore_) H5Eset_auto2(H5E_DEFAULT, printer_, data_);
  }
  QuietHdf5Errors(const QuietHdf5Errors&) = delete;
  QuietHdf5Errors& operator=(const QuietHdf5Errors&) = delete;

private:
  H5E_auto2_t printer_ = nullptr;
  void* data_ = nullptr;
  bool restore_ = false;
};

void writeHdf5String(hid_t file, const std::string& name, const std::string& value)
{
  const Hdf5Handle type(H5Tcopy(H5T_C_S1), H5Tclose, "a string type");
  if (H5Tset_size(type.id(), H5T_VARIABLE) < 0) throw std::runtime_error("a variable-length string type");
  const hsize_t one = 1;
  const Hdf5Handle space(H5Screate_simple(1, &one, nullptr), H5Sclose, "a dataspace");
  const Hdf5Handle set(H5Dcreate2(file, name.c_str(), type.id(), space.id(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Dclose,
                       name.c_str());
  const char* data[1] = {value.c_str()};
  if (H5Dwrite(set.id(), type.id(), H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0) throw std::runtime_error(name);
}

void writeHdf5Doubles(hid_t file, const std::string& name, const double* values, std::size_t count)
{
  const hsize_t size = count;
  const Hdf5Handle space(H5Screate_simple(1, &size, nullptr), H5Sclose, "a dataspace");
  const Hdf5Handle set(H5Dcreate2(file, name.c_str(), H5T_NATIVE_DOUBLE, space.id(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                       H5Dclose, name.c_str());
  if (count > 0 && H5Dwrite(set.id(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) < 0) {
    throw std::runtime_error(name);
  }
}

/// ITK's HDF5 transform file (itk::HDF5TransformIO's layout: the version strings, then
/// /TransformGroup/<n>/TransformType, TransformFixedParameters, TransformParameters; a composite
/// first, its parts after it in its queue's order), written straight from a displacement field's
/// voxels. ITK's writer copies a field transform's parameters twice before writing them (two
/// 94 MB copies for a 256x256x60 field: 0.5 s of a later scan's 4.4 s); this writes the same
/// datasets from the field's buffer. Read back by ITK's reader like the file ITK writes
/// (TransformIOTest compares the two).
void writeHdf5TransformFile(const SpatialTransform* transform, const fs::path& file)
{
  std::vector<const SpatialTransform*> parts{transform};
  if (const auto* composite = dynamic_cast<const CompositeTransform*>(transform)) {
    for (const auto& part : composite->GetTransformQueue()) {
      if (dynamic_cast<const CompositeTransform*>(part.GetPointer())) {
        throw std::invalid_argument("a composite transform within a composite transform cannot be written to an ITK transform file");
      }
      parts.push_back(part.GetPointer());
    }
  }
  off_t bytes = 1 << 20; // the strings and HDF5's own structures, with room to spare
  for (const SpatialTransform* part : parts) bytes += off_t(8 * (part->GetNumberOfParameters() + part->GetFixedParameters().Size()));
  const QuietHdf5Errors quiet; // failures are thrown, naming the file, not printed by HDF5
  const Hdf5Handle access(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, "file access properties");
  if (H5Pset_libver_bounds(access.id(), H5F_LIBVER_V18, H5F_LIBVER_V18) < 0) throw std::runtime_error("HDF5 1.8 compatibility");
  Hdf5Handle h5(H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, access.id()), H5Fclose, "the file");
  // The file's room taken before HDF5 writes into it (HDF5 cuts the file to its end when it closes
  // it): a full disk or a file-size limit refuses it here, while the file is sound. A write that
  // HDF5 1.10 finds failing leaves the file half-closed, and the program crashed at its exit.
  void* handle = nullptr;
  if (H5Fget_vfd_handle(h5.id(), access.id(), &handle) < 0 || !handle) throw std::runtime_error("the file (no descriptor)");
  if (const int error = posix_fallocate(*static_cast<int*>(handle), 0, bytes)) {
    throw std::runtime_error("room for " + std::to_string(bytes) + " bytes (" + std::strerror(error) + ")");
  }
  itksys::SystemInformation system;
  system.RunOSCheck();
  writeHdf5String(h5.id(), "/ITKVersion", itk::Version::GetITKVersion());
  writeHdf5String(h5.id(), "/HDFVersion", H5_VERS_INFO);
  writeHdf5String(h5.id(), "/OSName", system.GetOSName());
  writeHdf5String(h5.id(), "/OSVersion", system.GetOSRelease());
  Hdf5Handle group(H5Gcreate2(h5.id(), "/TransformGroup", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, "/TransformGroup");
  for (std::size_t n = 0; n < parts.size(); ++n) {
    const std::string name = "/TransformGroup/" + std::to_string(n);
    const Hdf5Handle part(H5Gcreate2(h5.id(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, name.c_str());
    const std::string type = parts[n]->GetTransformTypeAsString();
    writeHdf5String(h5.id(), name + "/TransformType", type);
    if (type.find("CompositeTransform") != std::string::npos) continue; // a composite holds no parameters of its own
    const auto fixed = parts[n]->GetFixedParameters();
    writeHdf5Doubles(h5.id(), name + "/TransformFixedParameters", fixed.data_block(), fixed.Size());
    if (const auto* field = dynamic_cast<const FieldTransform*>(parts[n])) {
      const DoubleField* image = field->GetDisplacementField();
      const std::size_t values = image->GetLargestPossibleRegion().GetNumberOfPixels() * 3;
      writeHdf5Doubles(h5.id(), name + "/TransformParameters", image->GetBufferPointer()->GetDataPointer(), values);
    } else {
      const auto parameters = parts[n]->GetParameters();
      writeHdf5Doubles(h5.id(), name + "/TransformParameters", parameters.data_block(), parameters.Size());
    }
  }
  group.close("/TransformGroup");
  haddr_t end = 0; // where HDF5's file ends, within the room taken
  if (H5Fflush(h5.id(), H5F_SCOPE_GLOBAL) < 0 || H5Fget_eoa(h5.id(), &end) < 0) throw std::runtime_error("the file's last blocks");
  h5.close("the file's last blocks");
  std::error_code ec;
  if (fs::file_size(file, ec) > end && !ec) fs::resize_file(file, end, ec); // the room not used
  if (ec) throw std::runtime_error("the file's end (" + ec.message() + ")");
}
} // namespace

SpatialTransform::Pointer makeDisplacementFieldTransform(DisplacementFieldImage* field)
{
  // The composite transforms of ITK are double; the field is converted once here.
  auto doubleField = DoubleField::New();
  doubleField->CopyInformation(field);
  doubleField->SetRegions(field->GetLargestPossibleRegion());
  doubleField->Allocate();
  const std::size_t n = field->GetLargestPossibleRegion().GetNumberOfPixels();
  const DisplacementVector* in = field->GetBufferPointer();
  DoubleField::PixelType* out = doubleField->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) {
    for (unsigned k = 0; k < 3; ++k) out[i][k] = in[i][k];
  }
  auto transform = FieldTransform::New();
  transform->SetDisplacementField(doubleField);
  return transform.GetPointer();
}

SpatialTransform::Pointer makeDisplacementFieldTransform(DoubleDisplacementFieldImage* field)
{
  static_assert(std::is_same_v<DoubleDisplacementFieldImage, DoubleField>, "the composite transforms' field type");
  auto transform = FieldTransform::New();
  transform->SetDisplacementField(field);
  return transform.GetPointer();
}

DisplacementFieldImage::Pointer displacementFieldOf(const SpatialTransform* transform)
{
  const auto* fieldTransform = dynamic_cast<const FieldTransform*>(transform);
  if (!fieldTransform) return nullptr;
  const DoubleField* doubleField = fieldTransform->GetDisplacementField();
  auto field = DisplacementFieldImage::New();
  field->CopyInformation(doubleField);
  field->SetRegions(doubleField->GetLargestPossibleRegion());
  field->Allocate();
  const std::size_t n = doubleField->GetLargestPossibleRegion().GetNumberOfPixels();
  const DoubleField::PixelType* in = doubleField->GetBufferPointer();
  DisplacementVector* out = field->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) {
    for (unsigned k = 0; k < 3; ++k) out[i][k] = static_cast<float>(in[i][k]);
  }
  return field;
}

SpatialTransform::Pointer readTransform(const fs::path& path)
{
  registerIOFactories();
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    throw InputError(path.string() + ": no such file");
  }
  if (!isTransformFile(path)) {
    if (!isVolumePath(path)) {
      throw InputError(path.string() +
                       ": not a transform file (expected .tfm, .txt, .mat, .h5, or a displacement field image)");
    }
    DisplacementFieldImage::Pointer field = readDisplacementField(path);
    return makeDisplacementFieldTransform(field);
  }
  auto reader = itk::TransformFileReaderTemplate<double>::New();
  reader->SetFileName(path.string());
  try {
    reader->Update();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(path.string() + ": cannot read the transform: " + oneLine(e.GetDescription()));
  } catch (const std::exception& e) { // ITK's text parser lets std::string's errors through on a garbled line
    throw InputError(path.string() + ": cannot read the transform: the file is garbled (" + oneLine(e.what()) + ")");
  }
  const auto* list = reader->GetTransformList();
  if (list->empty()) {
    throw InputError(path.string() + ": the file holds no transform");
  }
  auto* first = dynamic_cast<SpatialTransform*>(list->front().GetPointer());
  if (!first) {
    throw InputError(path.string() + ": the transform is not a 3D transform");
  }
  if (list->size() > 1 && !dynamic_cast<CompositeTransform*>(first)) {
    throw InputError(path.string() + ": the file holds " + std::to_string(list->size()) +
                     " separate transforms; one transform or one composite transform is expected");
  }
  return first;
}

void writeTransform(const SpatialTransform* transform, const fs::path& path)
{
  registerIOFactories();
  if (!isTransformFile(path)) {
    DisplacementFieldImage::Pointer field = displacementFieldOf(transform);
    if (!field) {
      throw std::invalid_argument("cannot write " + describeTransform(transform) + " to " + path.string() +
                                  ": only a displacement field transform is written as an image");
    }
    writeDisplacementField(field, path);
    return;
  }
  if (dynamic_cast<const CompositeTransform*>(transform) && !hasExtension(path, {".h5", ".hdf5"})) {
    throw std::invalid_argument("cannot write a composite transform to " + path.string() + ": use .h5");
  }
  if (hasExtension(path, {".h5", ".hdf5"}) && !isLinearTransform(transform)) {
    // A field's doubles hardly compress (seconds for a few %), and ITK's writer copies them twice.
    AtomicFile file(path);
    try {
      writeHdf5TransformFile(transform, file.temporaryPath());
    } catch (const std::runtime_error& e) {
      throw MethodError("cannot write " + path.string() + ": HDF5 failed to write " + e.what() + " (disk full or not writable?)");
    }
    file.commit();
    return;
  }
  auto writer = itk::TransformFileWriterTemplate<double>::New();
  writer->SetInput(transform);
  // Linear transforms are tiny: compressed.
  writeAtomically(writer.GetPointer(), path, isLinearTransform(transform));
}

bool isLinearTransform(const SpatialTransform* transform)
{
  return transform && transform->IsLinear();
}

AffineParameters affineParametersOf(const SpatialTransform* transform)
{
  if (!isLinearTransform(transform)) {
    throw std::invalid_argument(describeTransform(transform) + " is not linear");
  }
  AffineParameters p{};
  // A linear transform is determined by the images of the origin and the unit vectors.
  SpatialTransform::InputPointType origin;
  origin.Fill(0.0);
  const auto o = transform->TransformPoint(origin);
  for (int i = 0; i < 3; ++i) p.translation[i] = o[i];
  for (int c = 0; c < 3; ++c) {
    SpatialTransform::InputPointType e;
    e.Fill(0.0);
    e[c] = 1.0;
    const auto image = transform->TransformPoint(e);
    for (int r = 0; r < 3; ++r) p.matrix[r][c] = image[r] - o[r];
  }
  return p;
}

std::string describeTransform(const SpatialTransform* transform)
{
  if (!transform) return "no transform";
  std::string name = transform->GetNameOfClass();
  if (const auto* composite = dynamic_cast<const CompositeTransform*>(transform)) {
    name += " (" + std::to_string(composite->GetNumberOfTransforms()) + " transforms)";
  }
  return name;
}

} // namespace brainshift
