#pragma once
// A combo box that picks one node of the scene (of some kinds, optionally one role): the input
// selectors of the module panels. It keeps its choice while the scene changes around it.
#include "SceneNodeModel.h"

#include <QComboBox>

namespace brainshift {

class NodeSelector : public QComboBox {
  Q_OBJECT
public:
  explicit NodeSelector(std::set<NodeKind> kinds, QString role = {}, QWidget* parent = nullptr);

  void setScene(Scene* scene);
  /// The chosen node's id, or empty when the scene has none to offer.
  QString currentNodeId() const;
  /// Chooses the node; false (and no change) if the selector does not offer it.
  bool setCurrentNodeId(const QString& nodeId);
  std::shared_ptr<Node> currentNode() const;

signals:
  void currentNodeChanged(const QString& nodeId);

private:
  SceneNodeModel* model_;
  QString lastEmitted_;
};

} // namespace brainshift
