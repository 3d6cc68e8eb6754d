// The tissue classification module as a Qt plugin for the host.
#include "ModulePlugin.h"
#include "TissueClassificationPanel.h"

#include <QObject>

namespace brainshift {

class TissueClassificationModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Tissue classification"); }
  int modulePosition() const override { return 30; }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new TissueClassificationPanel(scene, context, parent);
  }
};

} // namespace brainshift

#include "TissueClassificationModule.moc"
