// The fusion and review module as a Qt plugin for the host.
#include "FusionReviewPanel.h"
#include "ModulePlugin.h"

#include <QObject>

namespace brainshift {

class FusionReviewModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Fusion and review"); }
  int modulePosition() const override { return 60; }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new FusionReviewPanel(scene, context, parent);
  }
};

} // namespace brainshift

#include "FusionReviewModule.moc"
