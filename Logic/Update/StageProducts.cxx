#include "StageProducts.h"

#include "ModelIO.h"
#include "VolumeIO.h"

#include <algorithm>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
LabelImage::Pointer copyOf(const LabelImage& labels)
{
  LabelImage::Pointer copy = LabelImage::New();
  copy->CopyInformation(&labels);
  copy->SetRegions(labels.GetLargestPossibleRegion());
  copy->Allocate();
  std::copy_n(labels.GetBufferPointer(), labels.GetLargestPossibleRegion().GetNumberOfPixels(), copy->GetBufferPointer());
  return copy;
}

vtkSmartPointer<vtkPointSet> copyOf(vtkPointSet* model)
{
  vtkSmartPointer<vtkPointSet> copy;
  copy.TakeReference(model->NewInstance());
  copy->DeepCopy(model);
  return copy;
}
} // namespace

std::optional<StageProducts::Stamp> StageProducts::stampOf(const fs::path& file)
{
  std::error_code ec;
  Stamp stamp;
  stamp.size = fs::file_size(file, ec);
  if (ec) return std::nullopt;
  stamp.time = fs::last_write_time(file, ec);
  if (ec) return std::nullopt;
  return stamp;
}

fs::path StageProducts::keyOf(const fs::path& file)
{
  std::error_code ec;
  const fs::path absolute = fs::absolute(file, ec);
  return (ec ? file : absolute).lexically_normal();
}

LabelImage::Pointer StageProducts::readLabelVolume(const fs::path& file)
{
  const auto kept = labels_.find(keyOf(file));
  if (kept != labels_.end() && stampOf(file) == kept->second.stamp) {
    ++fromMemory_;
    return copyOf(*kept->second.product);
  }
  ++fromFiles_;
  return brainshift::readLabelVolume(file);
}

void StageProducts::writeLabelVolume(const LabelImage* labels, const fs::path& file)
{
  brainshift::writeLabelVolume(labels, file);
  if (const std::optional<Stamp> stamp = stampOf(file)) labels_[keyOf(file)] = {*stamp, copyOf(*labels)};
}

vtkSmartPointer<vtkPointSet> StageProducts::readModel(const fs::path& file)
{
  const auto kept = models_.find(keyOf(file));
  if (kept != models_.end() && stampOf(file) == kept->second.stamp) {
    ++fromMemory_;
    return copyOf(kept->second.product);
  }
  ++fromFiles_;
  return brainshift::readModel(file);
}

void StageProducts::writeModel(vtkPointSet* model, const fs::path& file)
{
  brainshift::writeModel(model, file);
  if (const std::optional<Stamp> stamp = stampOf(file)) models_[keyOf(file)] = {*stamp, copyOf(model)};
}

} // namespace brainshift
