#pragma once
// Loading data into the host's scene and saving it, without dialogs: each function returns the
// message for the user (naming the file and the problem) or an empty string on success. On
// failure the scene is as it was.
#include "Scene.h"

#include <QString>

#include <memory>

namespace brainshift {

struct LoadResult {
  QString error;               ///< empty on success
  std::shared_ptr<Node> node;  ///< the node added (volume loads)
  explicit operator bool() const { return error.isEmpty(); }
};

/// A scalar volume (NIfTI, NRRD, MetaImage, or a DICOM folder), named after its file.
LoadResult loadScalarVolume(Scene& scene, const QString& path);
/// A label map; refused when the scene has volumes and it lies on none of their grids.
LoadResult loadLabelMap(Scene& scene, const QString& path);
/// An overlay (fMRI statistics, MRA): a scalar volume with role "overlay" and a colour map; a map
/// with negative values is shown as a statistical map (|t| >= 3).
LoadResult loadOverlay(Scene& scene, const QString& path);
/// A .mrml scene, added to what is there.
LoadResult loadScene(Scene& scene, const QString& path);
/// Writes the scene and the data not yet in files beside it.
LoadResult saveScene(Scene& scene, const QString& path);

} // namespace brainshift
