#pragma once
// The evaluation panel: binds LandmarkEvaluation to the scene. The user picks a transform
// (intraop_to_preop) and landmark pairs; Evaluate lists each pair's target registration error
// (mm) and the summary; clicking a row shows the pair's intraoperative point in the views.
// Evaluation takes milliseconds, so it runs on the GUI thread.
#include "LandmarkEvaluation.h"
#include "ModulePlugin.h"
#include "NodeSelector.h"

#include <QWidget>

class QLabel;
class QPushButton;
class QTableWidget;

namespace brainshift {

class EvaluationPanel : public QWidget {
  Q_OBJECT
public:
  EvaluationPanel(Scene& scene, ModuleContext context, QWidget* parent = nullptr);
  ~EvaluationPanel() override;

  NodeSelector* transformSelector() const { return transform_; }
  NodeSelector* landmarksSelector() const { return landmarks_; }
  QPushButton* evaluateButton() const { return evaluate_; }
  /// One row per pair: name, error (mm), in the landmark file's order.
  QTableWidget* table() const { return table_; }
  QString summaryText() const;

public slots:
  /// Fills the table; false (with the reason in the summary) without a transform or landmarks.
  bool evaluate();

private:
  void showPairOfRow(int row);

  Scene& scene_;
  ModuleContext context_;
  NodeSelector *transform_, *landmarks_;
  QPushButton* evaluate_;
  QTableWidget* table_;
  QLabel* summary_;
  std::vector<LandmarkPair> evaluatedPairs_;
};

} // namespace brainshift
