// The rigid registration module as a Qt plugin for the host.
#include "ModulePlugin.h"
#include "RigidRegistrationPanel.h"

#include <QObject>

namespace brainshift {

class RigidRegistrationModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Rigid registration"); }
  int modulePosition() const override { return 20; }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new RigidRegistrationPanel(scene, Configuration::loadOrDefaults(context.configurationFile), parent);
  }
};

} // namespace brainshift

#include "RigidRegistrationModule.moc"
