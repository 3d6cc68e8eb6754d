// The intraoperative update module as a Qt plugin for the host.
#include "IntraoperativeUpdatePanel.h"
#include "ModulePlugin.h"

#include <QObject>

namespace brainshift {

class IntraoperativeUpdateModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return tr("Intraoperative update"); }
  int modulePosition() const override { return 10; }
  QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) override
  {
    return new IntraoperativeUpdatePanel(scene, context, parent);
  }
};

} // namespace brainshift

#include "IntraoperativeUpdateModule.moc"
