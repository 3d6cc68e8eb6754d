#include "EvaluationPanel.h"

#include <QFormLayout>
#include <QHeaderView>
#include <QLabel>
#include <QPushButton>
#include <QTableWidget>
#include <QVBoxLayout>

namespace brainshift {

EvaluationPanel::EvaluationPanel(Scene& scene, ModuleContext context, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , context_(std::move(context))
{
  transform_ = new NodeSelector({NodeKind::Transform}, {}, this);
  transform_->setObjectName("transformSelector");
  landmarks_ = new NodeSelector({NodeKind::Landmarks}, {}, this);
  landmarks_->setObjectName("landmarksSelector");
  evaluate_ = new QPushButton(tr("Evaluate"), this);
  evaluate_->setObjectName("evaluateButton");
  table_ = new QTableWidget(0, 2, this);
  table_->setObjectName("errorTable");
  table_->setHorizontalHeaderLabels({tr("Landmark"), tr("TRE (mm)")});
  table_->horizontalHeader()->setStretchLastSection(true);
  table_->setEditTriggers(QAbstractItemView::NoEditTriggers);
  table_->setSelectionBehavior(QAbstractItemView::SelectRows);
  table_->setSelectionMode(QAbstractItemView::SingleSelection);
  summary_ = new QLabel(this);
  summary_->setWordWrap(true);

  auto* form = new QFormLayout;
  form->addRow(tr("Transform (intraop_to_preop)"), transform_);
  form->addRow(tr("Landmark pairs"), landmarks_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addWidget(evaluate_);
  column->addWidget(summary_);
  column->addWidget(table_, 1);

  transform_->setScene(&scene_);
  landmarks_->setScene(&scene_);
  connect(evaluate_, &QPushButton::clicked, this, &EvaluationPanel::evaluate);
  connect(table_, &QTableWidget::cellClicked, this, [this](int row, int) { showPairOfRow(row); });
}

EvaluationPanel::~EvaluationPanel()
{
  transform_->setScene(nullptr);
  landmarks_->setScene(nullptr);
}

QString EvaluationPanel::summaryText() const
{
  return summary_->text();
}

bool EvaluationPanel::evaluate()
{
  table_->setRowCount(0);
  evaluatedPairs_.clear();
  auto transform = std::dynamic_pointer_cast<TransformNode>(transform_->currentNode());
  auto landmarks = std::dynamic_pointer_cast<LandmarksNode>(landmarks_->currentNode());
  if (!transform || !transform->transformFromParent() || !landmarks || landmarks->pairs().empty()) {
    summary_->setText(tr("Choose a transform and landmark pairs first."));
    return false;
  }
  RegistrationError error;
  try {
    error = evaluateTransform(*transform->transformFromParent(), landmarks->pairs());
  } catch (const std::exception& e) {
    summary_->setText(tr("Evaluation failed: %1").arg(QString::fromStdString(e.what())));
    return false;
  }
  evaluatedPairs_ = landmarks->pairs();
  table_->setRowCount(int(error.pairs.size()));
  for (int row = 0; row < int(error.pairs.size()); ++row) {
    table_->setItem(row, 0, new QTableWidgetItem(QString::fromStdString(error.pairs[row].first)));
    auto* value = new QTableWidgetItem(QString::number(error.pairs[row].second, 'f', 2));
    value->setData(Qt::UserRole, error.pairs[row].second);
    value->setTextAlignment(Qt::AlignRight | Qt::AlignVCenter);
    table_->setItem(row, 1, value);
  }
  const ErrorStatistics& s = error.overall;
  summary_->setText(tr("%1 pairs: mean %2 mm, median %3 mm, 95th percentile %4 mm, max %5 mm")
                      .arg(s.count)
                      .arg(s.meanMm, 0, 'f', 2)
                      .arg(s.medianMm, 0, 'f', 2)
                      .arg(s.p95Mm, 0, 'f', 2)
                      .arg(s.maxMm, 0, 'f', 2));
  return true;
}

void EvaluationPanel::showPairOfRow(int row)
{
  if (row < 0 || row >= int(evaluatedPairs_.size()) || !context_.showPoint) return;
  // The views show the intraoperative frame (the world): the pair's intraoperative point.
  const PhysicalPoint& p = evaluatedPairs_[std::size_t(row)].intraop;
  context_.showPoint({p[0], p[1], p[2]});
}

} // namespace brainshift
