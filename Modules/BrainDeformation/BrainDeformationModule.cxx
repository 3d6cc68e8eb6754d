// The brain deformation module as a Qt plugin for the host.
#include "BrainDeformationPanel.h"
#include "ModulePlugin.h"

#include <QObject>

namespace brainshift {

class BrainDeformationModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Brain deformation"); }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new BrainDeformationPanel(scene, Configuration::loadOrDefaults(context.configurationFile), parent);
  }
};

} // namespace brainshift

#include "BrainDeformationModule.moc"
