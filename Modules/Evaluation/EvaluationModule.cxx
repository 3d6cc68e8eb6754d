// The evaluation module as a Qt plugin for the host.
#include "EvaluationPanel.h"
#include "ModulePlugin.h"

#include <QObject>

namespace brainshift {

class EvaluationModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Evaluation"); }
  int modulePosition() const override { return 70; }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new EvaluationPanel(scene, context, parent);
  }
};

} // namespace brainshift

#include "EvaluationModule.moc"
