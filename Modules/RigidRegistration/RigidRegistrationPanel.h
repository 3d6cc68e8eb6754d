#pragma once
// The rigid registration panel: binds RigidRegistrationLogic to the scene. The user picks the
// intraoperative (fixed) and preoperative (moving) volumes and, optionally, the preoperative
// labels that limit the metric; Run registers off the GUI thread; the result, the contract's
// `rigid intraop_to_preop`, appears in the scene as a transform node.
//
// Cancel stops the registration at its next optimizer iteration (the run's cancel flag,
// BackgroundRun.h); the panel is idle at once, and the cancelled run ends with nothing
// (discardedRunFinished). The logic reports no progress fraction, so the bar is a busy bar.
#include "BackgroundRun.h"
#include "NodeSelector.h"
#include "RigidRegistrationLogic.h"

#include <QWidget>

class QCheckBox;
class QLabel;
class QProgressBar;
class QPushButton;

namespace brainshift {

class RigidRegistrationPanel : public QWidget {
  Q_OBJECT
public:
  explicit RigidRegistrationPanel(Scene& scene, QWidget* parent = nullptr);
  ~RigidRegistrationPanel() override;

  NodeSelector* intraopSelector() const { return intraop_; }
  NodeSelector* preopSelector() const { return preop_; }
  NodeSelector* preopLabelsSelector() const { return preopLabels_; }
  QCheckBox* useLabelsCheckBox() const { return useLabels_; }
  QPushButton* runButton() const { return run_; }
  QPushButton* cancelButton() const { return cancel_; }
  QProgressBar* progressBar() const { return progress_; }

  /// The logic's parameters (defaults unless set; tests use a quicker schedule).
  void setParameters(const RigidRegistrationParameters& parameters) { parameters_ = parameters; }
  bool isRunning() const { return work_->isRunning(); }
  QString statusText() const;
  /// The name of the transform node a successful run adds (or updates).
  static QString resultNodeName() { return "rigid intraop_to_preop"; }

public slots:
  /// Starts a run; refused (with a status message) while running or without two volumes.
  void run();
  /// Abandons the running run: idle at once, its result is discarded.
  void cancel();

signals:
  /// A run ended: true when its transform is in the scene, false on failure (the status says why).
  void runFinished(bool succeeded);
  /// The worker of a cancelled run ended; nothing of it reached the scene.
  void discardedRunFinished(bool stoppedEarly); ///< a cancelled run ended (stoppedEarly: on the cancel flag)

private:
  void finish(const RigidRegistrationResult& result, double seconds);
  void setRunning(bool running);
  void setStatus(const QString& text);
  void chooseByRole(const Node& node);

  Scene& scene_;
  RigidRegistrationParameters parameters_;
  NodeSelector *intraop_, *preop_, *preopLabels_;
  QCheckBox* useLabels_;
  QPushButton *run_, *cancel_;
  QProgressBar* progress_;
  QLabel* status_;
  Scene::ObserverId sceneObserver_ = 0;
  BackgroundRun* work_;
};

} // namespace brainshift
