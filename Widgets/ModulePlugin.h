#pragma once
// The interface a loadable module (Modules/<Stage>/) implements as a Qt plugin, and all that
// the host knows of a module: its title and a panel bound to the host's scene. Header-only, so
// modules depend on Widgets and never on the host executable.
#include <QString>
#include <QtPlugin>

class QWidget;

namespace brainshift {

class Scene;

class ModulePlugin {
public:
  virtual ~ModulePlugin() = default;
  /// What the module selector shows ("Rigid registration").
  virtual QString moduleTitle() const = 0;
  /// The module's panel, bound to `scene`. The host owns the scene and outlives the panel.
  virtual QWidget* createPanel(Scene& scene, QWidget* parent) = 0;
};

} // namespace brainshift

#define BrainShiftModulePlugin_iid "org.brainshift.ModulePlugin/1.0"
Q_DECLARE_INTERFACE(brainshift::ModulePlugin, BrainShiftModulePlugin_iid)
