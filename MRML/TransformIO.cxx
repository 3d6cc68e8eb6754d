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

#include <algorithm>
#include <type_traits>

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
  auto writer = itk::TransformFileWriterTemplate<double>::New();
  writer->SetInput(transform);
  // Linear transforms are tiny; a field transform's doubles hardly compress (seconds for a few %).
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
