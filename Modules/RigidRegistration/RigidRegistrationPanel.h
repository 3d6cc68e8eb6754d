#pragma once
// The rigid registration panel: binds RigidRegistrationLogic to the scene. The user picks the
// intraoperative (fixed) and preoperative (moving) volumes and, optionally, the preoperative
// labels that limit the metric; Run registers off the GUI thread; the result, the contract's
// `rigid intraop_to_preop`, appears in the scene as a transform node.
//
// Cancel stops the registration at its next optimizer iteration (the run's cancel flag,
// BackgroundRun.h); the panel is idle at once, and the cancelled run ends with nothing
// (discardedRunFinished). The logic reports no progress fraction, so the bar is a busy bar.
#include "Configuration.h"
#include "NodeSelector.h"
#include "RigidRegistrationLogic.h"
#include "StageRunControls.h"

#include <QWidget>

class QCheckBox;
class QProgressBar;
class QPushButton;

namespace brainshift {

class RigidRegistrationPanel : public QWidget {
  Q_OBJECT
public:
  /// Its parameters start from `configuration`'s (the pyramid's levels, the samples), as the command line's.
  explicit RigidRegistrationPanel(Scene& scene, const Configuration& configuration = Configuration{}, QWidget* parent = nullptr);
  ~RigidRegistrationPanel() override;

  NodeSelector* intraopSelector() const { return intraop_; }
  NodeSelector* preopSelector() const { return preop_; }
  NodeSelector* preopLabelsSelector() const { return preopLabels_; }
  QCheckBox* useLabelsCheckBox() const { return useLabels_; }
  QPushButton* runButton() const { return controls_->runButton(); }
  QPushButton* cancelButton() const { return controls_->cancelButton(); }
  QProgressBar* progressBar() const { return controls_->progressBar(); }

  /// The logic's parameters (defaults unless set; tests use a quicker schedule).
  void setParameters(const RigidRegistrationParameters& parameters) { parameters_ = parameters; }
  bool isRunning() const { return controls_->isRunning(); }
  QString statusText() const { return controls_->statusText(); }
  /// The name of the transform node a successful run adds (or updates).
  static QString resultNodeName() { return "rigid intraop_to_preop"; }

public slots:
  /// Starts a run; refused (with a status message) while running or without two volumes.
  void run();
  /// Cancels the running run: idle at once, the registration stops at its next iteration.
  void cancel() { controls_->cancel(); }

signals:
  /// A run ended: true when its transform is in the scene, false on failure (the status says why).
  void runFinished(bool succeeded);
  /// The worker of a cancelled run ended; nothing of it reached the scene.
  void discardedRunFinished(bool stoppedEarly); ///< a cancelled run ended (stoppedEarly: on the cancel flag)

private:
  void finish(const RigidRegistrationResult& result, double seconds);
  void lockInputs(bool locked);
  void chooseByRole(const Node& node);

  Scene& scene_;
  RigidRegistrationParameters parameters_;
  NodeSelector *intraop_, *preop_, *preopLabels_;
  QCheckBox* useLabels_;
  StageRunControls* controls_;
  Scene::ObserverId sceneObserver_ = 0;
};

} // namespace brainshift
