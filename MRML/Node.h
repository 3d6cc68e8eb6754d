#pragma once
// The base of every scene node: identity, name, role, the transform it lives under, and the file
// that stores its data. Node kinds are only what the workflow uses (see Scene.h).
#include <filesystem>
#include <map>
#include <string>

namespace brainshift {

class Scene;

enum class NodeKind { ScalarVolume, LabelMapVolume, Model, Transform, Landmarks };

class Node {
public:
  virtual ~Node() = default;
  Node(const Node&) = delete;
  Node& operator=(const Node&) = delete;

  virtual NodeKind kind() const = 0;
  /// The Slicer class this node is saved as ("vtkMRMLScalarVolumeNode", ...); ids derive from it.
  virtual const char* slicerClassName() const = 0;

  /// Unique in its scene ("vtkMRMLScalarVolumeNode1"); empty until the node is added.
  const std::string& id() const { return id_; }

  const std::string& name() const { return name_; }
  void setName(const std::string& name);

  /// What the node is in the workflow: "preop", "intraop", "warped", "overlay", "truth", ...
  const std::string& role() const { return role_; }
  void setRole(const std::string& role);

  /// The id of the transform node this node is placed under (its data are in that transform's
  /// child frame); empty for the world frame.
  const std::string& parentTransformId() const { return parentTransformId_; }
  void setParentTransformId(const std::string& id);

  /// The file holding the node's data; relative paths are relative to the scene file's folder.
  const std::filesystem::path& storageFile() const { return storageFile_; }
  void setStorageFile(const std::filesystem::path& file) { storageFile_ = file; }
  /// True when the data changed since it was last read from or written to storageFile().
  bool dataModifiedSinceStorage() const { return dataModified_; }
  void markStored() { dataModified_ = false; }

  /// Free-form key/value attributes, saved with the scene.
  const std::map<std::string, std::string>& attributes() const { return attributes_; }
  void setAttribute(const std::string& key, const std::string& value);

  Scene* scene() const { return scene_; }

protected:
  Node() = default;
  /// Tells the scene's observers that this node changed (data or properties).
  void modified(bool dataChanged = false);

private:
  friend class Scene;
  Scene* scene_ = nullptr;
  std::string id_;
  std::string name_;
  std::string role_;
  std::string parentTransformId_;
  std::filesystem::path storageFile_;
  bool dataModified_ = true;
  std::map<std::string, std::string> attributes_;
};

} // namespace brainshift
