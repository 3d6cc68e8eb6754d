// The meshing module as a Qt plugin for the host.
#include "MeshingPanel.h"
#include "ModulePlugin.h"

#include <QObject>

namespace brainshift {

class MeshingModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Meshing"); }
  int modulePosition() const override { return 40; }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new MeshingPanel(scene, Configuration::loadOrDefaults(context.configurationFile), parent);
  }
};

} // namespace brainshift

#include "MeshingModule.moc"
