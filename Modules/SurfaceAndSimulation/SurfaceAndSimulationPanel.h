#pragma once
// The surface and simulation panel: binds the active surface (ActiveSurfaceLogic) and the finite
// element solve (FiniteElementSolver, the MPI worker) to the scene, and, as the command line's
// `simulate` does by default, the image's block matches inside the brain as soft constraints of a
// second solve (ImageMatchConstraints.h; both solves on one worker). Inputs: the mesh, the
// preoperative and intraoperative labels, the intraoperative volume, the rigid transform and, for
// block matching, the preoperative volume. Results: the model "brain surface" (coloured by
// DisplacementMagnitude, under the rigid transform: the contract's model frame) and the mesh's
// point arrays Displacement and DisplacementMagnitude.
//
// Progress and Cancel: the surface stage and the block matching report no fraction; the surface
// stops at its next iteration, the block matching runs to its end (Cancel takes effect before it
// and at the solve after it); the solve reports its stages and fractions, and Cancel stops the
// worker's ranks (the solver terminates them). One flag, the run's (BackgroundRun.h), cancels all.
#include "Configuration.h"
#include "NodeSelector.h"
#include "StageRunControls.h"

#include <QWidget>

#include <filesystem>
#include <memory>
#include <mutex>
#include <string>

class QCheckBox;
class QProgressBar;
class QPushButton;
class QSpinBox;
class QTimer;

namespace brainshift {

struct ActiveSurfaceResult;
struct FiniteElementResult;

class SurfaceAndSimulationPanel : public QWidget {
  Q_OBJECT
public:
  /// The surface's and the solve's parameters and the ranks are `configuration`'s, as the command line's.
  explicit SurfaceAndSimulationPanel(Scene& scene, const Configuration& configuration = Configuration{}, QWidget* parent = nullptr);
  ~SurfaceAndSimulationPanel() override;

  NodeSelector* meshSelector() const { return mesh_; }
  NodeSelector* preopLabelsSelector() const { return preopLabels_; }
  NodeSelector* intraopLabelsSelector() const { return intraopLabels_; }
  NodeSelector* intraopSelector() const { return intraop_; }
  NodeSelector* transformSelector() const { return transform_; }
  NodeSelector* preopSelector() const { return preop_; }
  /// On by default as the configuration's `block_matching.enabled`; needs the preoperative volume.
  QCheckBox* blockMatchingBox() const { return blockMatching_; }
  QSpinBox* ranksBox() const { return ranks_; }
  QPushButton* runButton() const { return controls_->runButton(); }
  QPushButton* cancelButton() const { return controls_->cancelButton(); }
  QProgressBar* progressBar() const { return controls_->progressBar(); }
  bool isRunning() const { return controls_->isRunning(); }
  QString statusText() const { return controls_->statusText(); }
  static QString surfaceNodeName() { return "brain surface"; }
  /// The finite element worker executable (default: the one beside the running program).
  void setWorker(const std::filesystem::path& worker) { worker_ = worker; }

public slots:
  void run();
  void cancel() { controls_->cancel(); }

signals:
  /// The stage now running: "surface", then the solver's ("partition", "assembly", "setup",
  /// "solve"), and with block matching "block matching" and the second solve's ("setup", "solve").
  void stageStarted(const QString& stage);
  void runFinished(bool succeeded);
  void discardedRunFinished(bool stoppedEarly); ///< a cancelled run ended (stoppedEarly: on the cancel flag)

private:
  /// What the worker thread last reported; the panel reads it on a timer (the worker never
  /// touches a widget).
  struct ProgressBoard {
    std::mutex mutex;
    std::string stage;
    double fraction = 0;
  };
  void showStage(const QString& stage, double fraction);
  void readProgressBoard();
  void lockInputs(bool locked);

  Scene& scene_;
  const Configuration configuration_;
  NodeSelector *mesh_, *preopLabels_, *intraopLabels_, *intraop_, *transform_, *preop_;
  QCheckBox* blockMatching_;
  QSpinBox* ranks_;
  StageRunControls* controls_;
  std::shared_ptr<ProgressBoard> board_;               ///< the running run's
  QTimer* boardReader_;
  QString lastStage_;
  std::filesystem::path worker_;
};

} // namespace brainshift
