#pragma once
// The scene as a 3D Slicer 5 .mrml file (format notes: Documentation/SlicerSceneFormat.md).
// Data files live beside the scene and are referenced by paths relative to the scene's folder.
#include "Scene.h"

#include <filesystem>

namespace brainshift {

struct SceneWriteOptions {
  /// Where nodes whose data is not in a file yet are written, relative to the scene's folder.
  std::filesystem::path dataFolder = ".";
};

/// Writes `scene` to `mrmlPath`. A node whose data changed since it was stored, or that has no
/// storage file yet, is first written as "<name>.<ext>" (volumes .nii.gz, surfaces .vtp, meshes
/// .vtu, linear transforms .tfm, fields .nrrd, composites .h5, landmarks as two .mrk.json point
/// lists "<name>_preop" and "<name>_intraop"); other nodes keep their files. Atomic.
void writeScene(Scene& scene, const std::filesystem::path& mrmlPath, const SceneWriteOptions& options = {});

/// Reads a .mrml scene into `scene` (added to what is there). All data are read before any node
/// is added, so on an InputError (naming the scene and the missing or bad file) the scene is
/// left as it was.
void readScene(Scene& scene, const std::filesystem::path& mrmlPath);

/// The Slicer colour node id for a BrainShift colour table name ("Grey" ->
/// "vtkMRMLColorTableNodeGrey"), and back.
std::string slicerColorNodeId(const std::string& colorTable);
std::string colorTableFromSlicerId(const std::string& colorNodeId);

} // namespace brainshift
