#include "NodeSelector.h"

namespace brainshift {

NodeSelector::NodeSelector(std::set<NodeKind> kinds, QString role, QWidget* parent)
  : QComboBox(parent)
  , model_(new SceneNodeModel(std::move(kinds), std::move(role), this))
{
  setModel(model_);
  // Long node names must not widen the panels: the selector shrinks and elides.
  setSizeAdjustPolicy(QComboBox::AdjustToMinimumContentsLengthWithIcon);
  setMinimumContentsLength(12);
  connect(this, qOverload<int>(&QComboBox::currentIndexChanged), this, [this](int) {
    const QString id = currentNodeId();
    if (id != lastEmitted_) {
      lastEmitted_ = id;
      emit currentNodeChanged(id);
    }
  });
}

void NodeSelector::setScene(Scene* scene)
{
  model_->setScene(scene);
  if (currentIndex() < 0 && model_->rowCount() > 0) setCurrentIndex(0);
}

QString NodeSelector::currentNodeId() const
{
  return model_->nodeIdAt(currentIndex());
}

bool NodeSelector::setCurrentNodeId(const QString& nodeId)
{
  const int row = model_->rowOf(nodeId);
  if (row < 0) return false;
  setCurrentIndex(row);
  return true;
}

std::shared_ptr<Node> NodeSelector::currentNode() const
{
  const QString id = currentNodeId();
  return id.isEmpty() || !model_->scene() ? nullptr : model_->scene()->node(id.toStdString());
}

} // namespace brainshift
