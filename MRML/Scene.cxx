#include "Scene.h"

#include <itkCompositeTransform.h>
#include <itkDisplacementFieldTransform.h>
#include <vtkUnstructuredGrid.h>

#include <algorithm>
#include <stdexcept>

namespace brainshift {

// ---- Node ---------------------------------------------------------------------------------
void Node::setName(const std::string& name)
{
  if (name == name_) return;
  name_ = name;
  modified();
}

void Node::setRole(const std::string& role)
{
  if (role == role_) return;
  role_ = role;
  modified();
}

void Node::setParentTransformId(const std::string& id)
{
  if (id == parentTransformId_) return;
  if (!id.empty() && id == id_) {
    throw std::invalid_argument("node " + id_ + " cannot be placed under itself");
  }
  parentTransformId_ = id;
  modified();
}

void Node::setAttribute(const std::string& key, const std::string& value)
{
  attributes_[key] = value;
  modified();
}

void Node::modified(bool dataChanged)
{
  if (dataChanged) dataModified_ = true;
  if (scene_) scene_->notify(SceneEventType::NodeModified, this, dataChanged);
}

// ---- Volumes ------------------------------------------------------------------------------
std::shared_ptr<ScalarVolumeNode> ScalarVolumeNode::create(const std::string& name, ScalarImage::Pointer image)
{
  std::shared_ptr<ScalarVolumeNode> node(new ScalarVolumeNode);
  node->setName(name);
  node->image_ = image;
  return node;
}

void ScalarVolumeNode::setImage(ScalarImage::Pointer image)
{
  image_ = image;
  modified(true);
}

void ScalarVolumeNode::setDisplay(const VolumeDisplay& display)
{
  display_ = display;
  modified();
}

std::shared_ptr<LabelMapVolumeNode> LabelMapVolumeNode::create(const std::string& name, LabelImage::Pointer image)
{
  std::shared_ptr<LabelMapVolumeNode> node(new LabelMapVolumeNode);
  node->setName(name);
  node->image_ = image;
  return node;
}

void LabelMapVolumeNode::setImage(LabelImage::Pointer image)
{
  image_ = image;
  modified(true);
}

void LabelMapVolumeNode::setDisplay(const VolumeDisplay& display)
{
  display_ = display;
  modified();
}

// ---- Model --------------------------------------------------------------------------------
std::shared_ptr<ModelNode> ModelNode::create(const std::string& name, vtkSmartPointer<vtkPointSet> mesh)
{
  std::shared_ptr<ModelNode> node(new ModelNode);
  node->setName(name);
  node->mesh_ = mesh;
  return node;
}

void ModelNode::setMesh(vtkSmartPointer<vtkPointSet> mesh)
{
  mesh_ = mesh;
  modified(true);
}

bool ModelNode::isVolumetric() const
{
  return vtkUnstructuredGrid::SafeDownCast(mesh_) != nullptr;
}

void ModelNode::setDisplay(const ModelDisplay& display)
{
  display_ = display;
  modified();
}

// ---- Transform ----------------------------------------------------------------------------
std::shared_ptr<TransformNode> TransformNode::create(const std::string& name, SpatialTransform::Pointer fromParent)
{
  std::shared_ptr<TransformNode> node(new TransformNode);
  node->setName(name);
  node->transform_ = fromParent;
  return node;
}

void TransformNode::setTransformFromParent(SpatialTransform::Pointer transform)
{
  transform_ = transform;
  modified(true);
}

TransformNode::Type TransformNode::type() const
{
  if (isLinearTransform(transform_)) return Type::Linear;
  if (displacementFieldOf(transform_)) return Type::DisplacementField;
  return Type::Composite;
}

const char* TransformNode::slicerClassName() const
{
  switch (type()) {
  case Type::Linear: return "vtkMRMLLinearTransformNode";
  case Type::DisplacementField: return "vtkMRMLGridTransformNode";
  case Type::Composite: break;
  }
  return "vtkMRMLTransformNode";
}

// ---- Landmarks ----------------------------------------------------------------------------
std::shared_ptr<LandmarksNode> LandmarksNode::create(const std::string& name, std::vector<LandmarkPair> pairs)
{
  std::shared_ptr<LandmarksNode> node(new LandmarksNode);
  node->setName(name);
  node->pairs_ = std::move(pairs);
  return node;
}

void LandmarksNode::setPairs(std::vector<LandmarkPair> pairs)
{
  pairs_ = std::move(pairs);
  modified(true);
}

// ---- Scene --------------------------------------------------------------------------------
Scene::~Scene()
{
  for (auto& n : nodes_) n->scene_ = nullptr;
}

void Scene::addNode(const std::shared_ptr<Node>& node)
{
  if (!node) throw std::invalid_argument("Scene::addNode: null node");
  if (node->scene_) throw std::invalid_argument("node '" + node->name() + "' already belongs to a scene");
  // Slicer-style ids: the class name and a counter, never reused within a scene.
  const std::string prefix = node->slicerClassName();
  std::string id;
  do {
    id = prefix + std::to_string(++idCounters_[prefix]);
  } while (this->node(id));
  node->id_ = id;
  node->scene_ = this;
  nodes_.push_back(node);
  notify(SceneEventType::NodeAdded, node.get());
}

void Scene::remove(const std::string& id)
{
  auto it = std::find_if(nodes_.begin(), nodes_.end(), [&](const auto& n) { return n->id() == id; });
  if (it == nodes_.end()) return;
  std::shared_ptr<Node> removed = *it; // keeps the node alive through the notifications
  notify(SceneEventType::NodeAboutToBeRemoved, removed.get());
  for (auto& n : nodes_) {
    if (n->parentTransformId() == id) n->setParentTransformId(removed->parentTransformId());
  }
  for (std::string* layer : {&sliceViewLayers_.backgroundVolumeId, &sliceViewLayers_.foregroundVolumeId,
                             &sliceViewLayers_.labelVolumeId}) {
    if (*layer == id) layer->clear();
  }
  nodes_.erase(std::find(nodes_.begin(), nodes_.end(), removed));
  notify(SceneEventType::NodeRemoved, removed.get());
  removed->scene_ = nullptr;
  removed->id_.clear();
}

void Scene::clear()
{
  while (!nodes_.empty()) remove(nodes_.back()->id());
}

void Scene::moveNodesFrom(Scene& source)
{
  if (&source == this) return;
  std::vector<std::shared_ptr<Node>> moved;
  moved.swap(source.nodes_);
  const SliceViewLayers sourceLayers = source.sliceViewLayers_;
  source.sliceViewLayers_ = SliceViewLayers{};
  std::map<std::string, std::string> newIdOf;
  std::vector<std::string> oldParentOf;
  for (const auto& n : moved) {
    source.notify(SceneEventType::NodeRemoved, n.get());
    oldParentOf.push_back(n->parentTransformId_);
    const std::string oldId = n->id_;
    n->scene_ = nullptr;
    n->parentTransformId_.clear();
    addNode(n);
    newIdOf[oldId] = n->id_;
  }
  for (std::size_t i = 0; i < moved.size(); ++i) {
    if (oldParentOf[i].empty()) continue;
    const auto parent = newIdOf.find(oldParentOf[i]);
    if (parent != newIdOf.end()) moved[i]->setParentTransformId(parent->second);
  }
  if (!sourceLayers.empty()) {
    SliceViewLayers layers = sourceLayers;
    for (std::string* id : {&layers.backgroundVolumeId, &layers.foregroundVolumeId, &layers.labelVolumeId}) {
      const auto mapped = newIdOf.find(*id);
      *id = mapped == newIdOf.end() ? std::string() : mapped->second;
    }
    setSliceViewLayers(layers);
  }
}

std::shared_ptr<Node> Scene::node(const std::string& id) const
{
  for (const auto& n : nodes_) {
    if (n->id() == id) return n;
  }
  return nullptr;
}

void Scene::setSliceViewLayers(const SliceViewLayers& layers)
{
  for (const std::string& id : {layers.backgroundVolumeId, layers.foregroundVolumeId, layers.labelVolumeId}) {
    if (id.empty()) continue;
    const auto volume = node(id);
    if (!volume || (volume->kind() != NodeKind::ScalarVolume && volume->kind() != NodeKind::LabelMapVolume)) {
      throw std::invalid_argument("slice view layer '" + id + "' is not a volume of the scene");
    }
  }
  sliceViewLayers_ = layers;
}

Scene::ObserverId Scene::addObserver(Observer observer)
{
  observers_.emplace_back(nextObserverId_, std::move(observer));
  return nextObserverId_++;
}

void Scene::removeObserver(ObserverId id)
{
  observers_.erase(std::remove_if(observers_.begin(), observers_.end(), [&](const auto& o) { return o.first == id; }),
                   observers_.end());
}

void Scene::notify(SceneEventType type, Node* node, bool dataChanged)
{
  // A copy: an observer may add or remove observers while being called.
  const auto observers = observers_;
  for (const auto& [id, observer] : observers) observer(SceneEvent{type, node, dataChanged});
}

} // namespace brainshift
