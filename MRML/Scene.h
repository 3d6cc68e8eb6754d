#pragma once
// The scene: the nodes of one case and the observers that follow them (views, panels).
// Not thread-safe: change a scene from one thread (the GUI thread in the host); long work runs
// on copies of the data and hands results back.
#include "LandmarksNode.h"
#include "ModelNode.h"
#include "TransformNode.h"
#include "VolumeNodes.h"

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace brainshift {

enum class SceneEventType { NodeAdded, NodeModified, NodeAboutToBeRemoved, NodeRemoved };

struct SceneEvent {
  SceneEventType type;
  Node* node;        ///< valid during the call
  bool dataChanged;  ///< NodeModified: the data (not only display or name) changed
};

/// What the slice views show on load (3D Slicer's slice composite nodes, the same for the Red,
/// Yellow and Green views): volume ids of this scene, empty for an empty layer.
struct SliceViewLayers {
  std::string backgroundVolumeId;
  std::string foregroundVolumeId;
  double foregroundOpacity = 0.5;
  std::string labelVolumeId;
  double labelOpacity = 0.6;

  bool empty() const { return backgroundVolumeId.empty() && foregroundVolumeId.empty() && labelVolumeId.empty(); }
};

class Scene {
public:
  using Observer = std::function<void(const SceneEvent&)>;
  using ObserverId = unsigned long;

  Scene() = default;
  ~Scene();
  Scene(const Scene&) = delete;
  Scene& operator=(const Scene&) = delete;

  /// Adds a node, gives it a unique id, and returns it. A node belongs to one scene.
  template <class TNode>
  std::shared_ptr<TNode> add(std::shared_ptr<TNode> node)
  {
    addNode(node);
    return node;
  }
  void addNode(const std::shared_ptr<Node>& node);

  /// Removes the node (children placed under a removed transform move to its parent).
  void remove(const std::string& id);
  void clear();
  /// Moves every node of `source` into this scene, in its order (each gets an id of this scene; the
  /// transforms they live under and `source`'s slice view layers follow them), and takes those
  /// layers when it has any. `source` is left empty. For a scene read aside (off the GUI thread)
  /// and then handed to the scene the views follow.
  void moveNodesFrom(Scene& source);

  std::shared_ptr<Node> node(const std::string& id) const;
  const std::vector<std::shared_ptr<Node>>& nodes() const { return nodes_; }

  template <class TNode>
  std::vector<std::shared_ptr<TNode>> nodesOfType() const
  {
    std::vector<std::shared_ptr<TNode>> found;
    for (const auto& n : nodes_) {
      if (auto typed = std::dynamic_pointer_cast<TNode>(n)) found.push_back(typed);
    }
    return found;
  }

  /// The first node of the type with this name, or null.
  template <class TNode>
  std::shared_ptr<TNode> findByName(const std::string& name) const
  {
    for (const auto& n : nodes_) {
      auto typed = std::dynamic_pointer_cast<TNode>(n);
      if (typed && typed->name() == name) return typed;
    }
    return nullptr;
  }

  /// The slice views' layers. Setting refuses an id that is not a volume of this scene; removing
  /// a node empties the layers that showed it.
  const SliceViewLayers& sliceViewLayers() const { return sliceViewLayers_; }
  void setSliceViewLayers(const SliceViewLayers& layers);

  ObserverId addObserver(Observer observer);
  void removeObserver(ObserverId id);

private:
  friend class Node;
  void notify(SceneEventType type, Node* node, bool dataChanged = false);

  std::vector<std::shared_ptr<Node>> nodes_;
  std::vector<std::pair<ObserverId, Observer>> observers_;
  ObserverId nextObserverId_ = 1;
  std::map<std::string, int> idCounters_;
  SliceViewLayers sliceViewLayers_;
};

} // namespace brainshift
