#pragma once
// The meshing panel: binds LabelMapMesher to the scene. The user picks the preoperative label
// map, the tissues and the resolution; Run meshes off the GUI thread (BackgroundRun.h: Cancel
// stops the mesher between its phases); the mesh appears in the scene as the model
// "mesh" (cell array Label, LPS mm, the preoperative frame), placed under the rigid transform when
// the scene has one, as ../../../shared/CONTRACT.md's model frame says.
#include "Configuration.h"
#include "LabelMapMesher.h"
#include "NodeSelector.h"
#include "StageRunControls.h"

#include <QWidget>

class QDoubleSpinBox;
class QLineEdit;
class QPushButton;

namespace brainshift {

class MeshingPanel : public QWidget {
  Q_OBJECT
public:
  /// Its defaults (resolution, tissues, backend, grading) are `configuration`'s, as the command line's.
  explicit MeshingPanel(Scene& scene, const Configuration& configuration = Configuration{}, QWidget* parent = nullptr);
  ~MeshingPanel() override;

  NodeSelector* labelsSelector() const { return labels_; }
  QDoubleSpinBox* resolutionBox() const { return resolution_; }
  /// The tissues, labels separated by commas or spaces ("2, 3, 4").
  QLineEdit* tissuesEdit() const { return tissues_; }
  QPushButton* runButton() const { return controls_->runButton(); }
  QPushButton* cancelButton() const { return controls_->cancelButton(); }
  bool isRunning() const { return controls_->isRunning(); }
  QString statusText() const { return controls_->statusText(); }
  static QString resultNodeName() { return "mesh"; }

public slots:
  void run();
  void cancel() { controls_->cancel(); }

signals:
  void runFinished(bool succeeded);
  void discardedRunFinished(bool stoppedEarly); ///< a cancelled run ended (stoppedEarly: on the cancel flag)

private:
  void finish(const LabelMapMesh& result, double seconds);
  void lockInputs(bool locked);

  Scene& scene_;
  MeshingParameters defaults_; ///< the configuration's; the panel sets the resolution and tissues
  NodeSelector* labels_;
  QDoubleSpinBox* resolution_;
  QLineEdit* tissues_;
  StageRunControls* controls_;
};

} // namespace brainshift
