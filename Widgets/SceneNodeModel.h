#pragma once
// A Qt list model of the scene's nodes of some kinds (and optionally one role), kept current by
// the scene's observers: what node selectors, layer lists and panels show.
#include "Scene.h"

#include <QAbstractListModel>

#include <set>

namespace brainshift {

class SceneNodeModel : public QAbstractListModel {
  Q_OBJECT
public:
  enum Roles { NodeIdRole = Qt::UserRole + 1, NodeRoleRole, NodeKindRole };

  /// Shows nodes of `kinds` (all kinds when empty) whose role is `role` (any when empty).
  explicit SceneNodeModel(std::set<NodeKind> kinds = {}, QString role = {}, QObject* parent = nullptr);
  ~SceneNodeModel() override;

  /// Follows `scene` (or nothing when null). The scene must outlive the model or be unset first.
  void setScene(Scene* scene);
  Scene* scene() const { return scene_; }

  int rowCount(const QModelIndex& parent = QModelIndex()) const override;
  QVariant data(const QModelIndex& index, int role = Qt::DisplayRole) const override;
  QHash<int, QByteArray> roleNames() const override;

  /// The row of the node with this id, or -1.
  int rowOf(const QString& nodeId) const;
  QString nodeIdAt(int row) const;

private:
  bool accepts(const Node& node) const;
  void onSceneEvent(const SceneEvent& event);
  void rebuild();

  std::set<NodeKind> kinds_;
  QString role_;
  Scene* scene_ = nullptr;
  Scene::ObserverId observer_ = 0;
  std::vector<Node*> rows_;
};

} // namespace brainshift
