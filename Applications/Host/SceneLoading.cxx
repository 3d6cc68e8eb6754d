#include "SceneLoading.h"

#include "SceneIO.h"
#include "VolumeIO.h"

#include <itkMinimumMaximumImageCalculator.h>

#include <QFileInfo>

namespace brainshift {

namespace {
std::string baseName(const QString& path)
{
  QString name = QFileInfo(path).fileName();
  for (const char* extension : {".nii.gz", ".nii", ".nrrd", ".nhdr", ".mha", ".mhd"}) {
    if (name.endsWith(extension)) return name.left(name.size() - int(std::strlen(extension))).toStdString();
  }
  return name.toStdString();
}

template <class Read>
LoadResult guarded(const QString& what, Read read)
{
  try {
    return read();
  } catch (const std::exception& e) {
    return {QObject::tr("Cannot %1: %2").arg(what, QString::fromStdString(e.what())), nullptr};
  }
}
} // namespace

LoadResult loadScalarVolume(Scene& scene, const QString& path)
{
  return guarded("load the volume", [&] {
    auto node = ScalarVolumeNode::create(baseName(path), readScalarVolume(path.toStdString()));
    node->setStorageFile(path.toStdString());
    node->markStored();
    return LoadResult{{}, scene.add(node)};
  });
}

LoadResult loadLabelMap(Scene& scene, const QString& path)
{
  return guarded("load the label map", [&] {
    LabelImage::Pointer labels = readLabelVolume(path.toStdString());
    const ImageGeometry grid = ImageGeometry::of(labels.GetPointer());
    const auto volumes = scene.nodesOfType<ScalarVolumeNode>();
    bool onAGrid = volumes.empty();
    std::string grids;
    for (const auto& volume : volumes) {
      if (!volume->image()) continue;
      const ImageGeometry other = ImageGeometry::of(volume->image());
      onAGrid = onAGrid || grid.sameGridAs(other);
      grids += "\n  " + volume->name() + ": " + other.describe();
    }
    if (!onAGrid) {
      throw InputError(path.toStdString() + ": the label map's grid (" + grid.describe() +
                       ") is not the grid of any volume in the scene:" + grids);
    }
    auto node = LabelMapVolumeNode::create(baseName(path), labels);
    node->setStorageFile(path.toStdString());
    node->markStored();
    return LoadResult{{}, scene.add(node)};
  });
}

LoadResult loadOverlay(Scene& scene, const QString& path)
{
  return guarded("load the overlay", [&] {
    ScalarImage::Pointer image = readScalarVolume(path.toStdString());
    auto range = itk::MinimumMaximumImageCalculator<ScalarImage>::New();
    range->SetImage(image);
    range->Compute();
    auto node = ScalarVolumeNode::create(baseName(path), image);
    node->setRole("overlay");
    VolumeDisplay display;
    if (range->GetMinimum() < 0) {
      display = VolumeDisplay::statisticalMap();
    } else {
      display.colorTable = "ColdToHotRainbow";
      display.lowerThreshold = range->GetMinimum() + 0.25 * (range->GetMaximum() - range->GetMinimum());
    }
    display.opacity = 0.7;
    node->setDisplay(display);
    node->setStorageFile(path.toStdString());
    node->markStored();
    return LoadResult{{}, scene.add(node)};
  });
}

LoadResult loadScene(Scene& scene, const QString& path)
{
  return guarded("load the scene", [&] {
    readScene(scene, path.toStdString());
    return LoadResult{};
  });
}

LoadResult saveScene(Scene& scene, const QString& path)
{
  return guarded("save the scene", [&] {
    writeScene(scene, path.toStdString());
    return LoadResult{};
  });
}

} // namespace brainshift
