// A module whose panel cannot be made (its constructor throws): the host must report it and
// start without it. Built for HostModuleDiscoveryTest only, outside the modules folder.
#include "ModulePlugin.h"

#include <QObject>

#include <stdexcept>

namespace brainshift {

class ThrowingTestModule : public QObject, public ModulePlugin {
  Q_OBJECT
  Q_PLUGIN_METADATA(IID BrainShiftModulePlugin_iid)
  Q_INTERFACES(brainshift::ModulePlugin)
public:
  QString moduleTitle() const override { return "Throwing test module"; }
  QWidget* createPanel(Scene&, const ModuleContext&, QWidget*) override
  {
    throw std::runtime_error("the test module's panel throws on purpose");
  }
};

} // namespace brainshift

#include "ThrowingTestModule.moc"
