#pragma once
// The tissue classification panel: binds TissueClassificationLogic to the scene. Inputs: the
// intraoperative volume, the preoperative labels and the rigid transform that aligns them.
// Prototypes: with an empty list the logic chooses them; after a run the list holds the ones it
// used, and while "Pick" is on every point picked in a slice view adds one of the chosen tissue
// (the radiologist's correction); a run with a list uses exactly the list. The result appears in
// the scene as the label map "intraop labels" (role intraop). Runs off the GUI thread
// (BackgroundRun.h: Cancel stops the classification within 65,536 voxels of its k-NN).
#include "Configuration.h"
#include "ModulePlugin.h"
#include "NodeSelector.h"
#include "StageRunControls.h"
#include "TissueClassificationLogic.h"

#include <QWidget>

class QComboBox;
class QLabel;
class QPushButton;
class QSpinBox;

namespace brainshift {

class TissueClassificationPanel : public QWidget {
  Q_OBJECT
public:
  TissueClassificationPanel(Scene& scene, const ModuleContext& context, QWidget* parent = nullptr);
  ~TissueClassificationPanel() override;

  NodeSelector* intraopSelector() const { return intraop_; }
  NodeSelector* preopLabelsSelector() const { return preopLabels_; }
  /// Optional, as on the command line: the tumour's look before surgery and where tissue was
  /// (takePreoperativeImage); offers the scene's volumes of the "preop" role.
  NodeSelector* preopImageSelector() const { return preopImage_; }
  NodeSelector* transformSelector() const { return transform_; }
  /// The tissue a pick adds (a label of TissueClassificationLogic's tissueName).
  QComboBox* pickTissueBox() const { return pickTissue_; }
  QPushButton* pickButton() const { return pick_; }
  QPushButton* runButton() const { return controls_->runButton(); }
  QPushButton* cancelButton() const { return controls_->cancelButton(); }
  QSpinBox* neighboursBox() const { return k_; }
  bool isRunning() const { return controls_->isRunning(); }
  QString statusText() const { return controls_->statusText(); }
  const std::vector<TissuePrototype>& prototypes() const { return prototypes_; }
  static QString resultNodeName() { return "intraop labels"; }

public slots:
  void run();
  void cancel() { controls_->cancel(); }
  /// Adds a prototype of the chosen tissue at `lps` (what a pick does while Pick is on).
  void addPrototype(const std::array<double, 3>& lps);
  void clearPrototypes();

signals:
  void runFinished(bool succeeded);
  void discardedRunFinished(bool stoppedEarly); ///< a cancelled run ended (stoppedEarly: on the cancel flag)

private:
  void finish(const TissueClassificationResult& result, double seconds);
  void lockInputs(bool locked);
  void showPrototypeCounts();

  Scene& scene_;
  TissueClassificationParameters defaults_; ///< the configuration's (ModuleContext::configurationFile); the panel sets k
  NodeSelector *intraop_, *preopLabels_, *preopImage_, *transform_;
  QComboBox* pickTissue_;
  QPushButton *pick_, *clear_;
  QSpinBox* k_;
  QLabel* prototypeCounts_;
  StageRunControls* controls_;
  std::vector<TissuePrototype> prototypes_;
  unsigned picks_ = 0;
};

} // namespace brainshift
