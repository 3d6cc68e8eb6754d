// The surface and simulation module as a Qt plugin for the host.
#include "SurfaceAndSimulationPanel.h"
#include "ModulePlugin.h"

#include <QObject>

namespace brainshift {

class SurfaceAndSimulationModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Surface and simulation"); }
  int modulePosition() const override { return 50; }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new SurfaceAndSimulationPanel(scene, Configuration::loadOrDefaults(context.configurationFile), parent);
  }
};

} // namespace brainshift

#include "SurfaceAndSimulationModule.moc"
