#include "SceneNodeModel.h"

#include <algorithm>

namespace brainshift {

SceneNodeModel::SceneNodeModel(std::set<NodeKind> kinds, QString role, QObject* parent)
  : QAbstractListModel(parent)
  , kinds_(std::move(kinds))
  , role_(std::move(role))
{
}

SceneNodeModel::~SceneNodeModel()
{
  setScene(nullptr);
}

void SceneNodeModel::setScene(Scene* scene)
{
  if (scene == scene_) return;
  if (scene_) scene_->removeObserver(observer_);
  scene_ = scene;
  if (scene_) observer_ = scene_->addObserver([this](const SceneEvent& event) { onSceneEvent(event); });
  rebuild();
}

bool SceneNodeModel::accepts(const Node& node) const
{
  return (kinds_.empty() || kinds_.count(node.kind())) && (role_.isEmpty() || role_.toStdString() == node.role());
}

void SceneNodeModel::rebuild()
{
  beginResetModel();
  rows_.clear();
  if (scene_) {
    for (const auto& node : scene_->nodes()) {
      if (accepts(*node)) rows_.push_back(node.get());
    }
  }
  endResetModel();
}

void SceneNodeModel::onSceneEvent(const SceneEvent& event)
{
  Node* node = event.node;
  const auto found = std::find(rows_.begin(), rows_.end(), node);
  const int row = found == rows_.end() ? -1 : int(found - rows_.begin());
  switch (event.type) {
  case SceneEventType::NodeAdded:
    if (accepts(*node)) {
      beginInsertRows(QModelIndex(), int(rows_.size()), int(rows_.size()));
      rows_.push_back(node);
      endInsertRows();
    }
    break;
  case SceneEventType::NodeAboutToBeRemoved:
    if (row >= 0) {
      beginRemoveRows(QModelIndex(), row, row);
      rows_.erase(found);
      endRemoveRows();
    }
    break;
  case SceneEventType::NodeModified:
    // A change of role may move the node in or out of the model; a rename changes its row.
    if (row >= 0 && !accepts(*node)) {
      beginRemoveRows(QModelIndex(), row, row);
      rows_.erase(found);
      endRemoveRows();
    } else if (row < 0 && accepts(*node)) {
      rebuild(); // keeps the scene's order
    } else if (row >= 0) {
      emit dataChanged(index(row), index(row));
    }
    break;
  case SceneEventType::NodeRemoved:
    break;
  }
}

int SceneNodeModel::rowCount(const QModelIndex& parent) const
{
  return parent.isValid() ? 0 : int(rows_.size());
}

QVariant SceneNodeModel::data(const QModelIndex& index, int role) const
{
  if (!index.isValid() || index.row() < 0 || index.row() >= int(rows_.size())) return {};
  const Node* node = rows_[std::size_t(index.row())];
  switch (role) {
  case Qt::DisplayRole: return QString::fromStdString(node->name());
  case Qt::ToolTipRole:
    return QString::fromStdString(node->id() + (node->role().empty() ? "" : " (" + node->role() + ")"));
  case NodeIdRole: return QString::fromStdString(node->id());
  case NodeRoleRole: return QString::fromStdString(node->role());
  case NodeKindRole: return int(node->kind());
  default: return {};
  }
}

QHash<int, QByteArray> SceneNodeModel::roleNames() const
{
  auto names = QAbstractListModel::roleNames();
  names[NodeIdRole] = "nodeId";
  names[NodeRoleRole] = "nodeRole";
  names[NodeKindRole] = "nodeKind";
  return names;
}

int SceneNodeModel::rowOf(const QString& nodeId) const
{
  for (std::size_t i = 0; i < rows_.size(); ++i) {
    if (QString::fromStdString(rows_[i]->id()) == nodeId) return int(i);
  }
  return -1;
}

QString SceneNodeModel::nodeIdAt(int row) const
{
  return row >= 0 && row < int(rows_.size()) ? QString::fromStdString(rows_[std::size_t(row)]->id()) : QString();
}

} // namespace brainshift
