#pragma once
// The interface a loadable module (Modules/<Stage>/) implements as a Qt plugin, and all that
// the host knows of a module: its title and a panel bound to the host's scene. Header-only, so
// modules depend on Widgets and never on the host executable.
#include <QString>
#include <QtPlugin>

#include <array>
#include <functional>
#include <string>

class QObject;
class QWidget;

namespace brainshift {

class Scene;

/// What the slice views show: node ids of the scene (empty: none) and how the comparison volume
/// is shown (SliceView.h's ComparisonMode: 0 off, 1 checkerboard, 2 difference, 3 flicker).
struct ViewLayers {
  std::string backgroundId, labelMapId, overlayId, comparisonId;
  int comparisonMode = 0;
  bool labelOutline = false;
};

/// What the host offers a panel besides the scene.
struct ModuleContext {
  /// Moves the views' cursor (and so the slices) to a point, LPS mm. May be empty (no views).
  std::function<void(const std::array<double, 3>& lps)> showPoint;
  /// Calls `onPick` with every point the user picks in a slice view (LPS mm), for as long as
  /// `receiver` lives. May be empty (no views).
  std::function<void(QObject* receiver, std::function<void(const std::array<double, 3>& lps)> onPick)> subscribeToPicks;
  /// Shows these layers in the slice views (the host's Data panel follows). May be empty (no views).
  std::function<void(const ViewLayers& layers)> showLayers;
  /// The configuration file the host was given (`brainshift-host --config`, checked at start), the
  /// one `register --config` reads: each stage panel takes its defaults from it through the same
  /// function as the command line (Configuration::loadOrDefaults). Empty: the product's defaults.
  std::string configurationFile;
};

class ModulePlugin {
public:
  virtual ~ModulePlugin() = default;
  /// What the module selector shows ("Rigid registration").
  virtual QString moduleTitle() const = 0;
  /// The module's panel, bound to `scene`. The host owns the scene and outlives the panel.
  virtual QWidget* createPanel(Scene& scene, const ModuleContext& context, QWidget* parent) = 0;
  /// Where the module stands in the selector, after the host's Data panel: the surgeon's update
  /// (10), then the stages in the update's order, each titled as its command (rigid 20, classify 30,
  /// mesh 40, surface and simulate 50), then review (60) and evaluation (70). Others follow, by title.
  virtual int modulePosition() const { return 1000; }
};

} // namespace brainshift

#define BrainShiftModulePlugin_iid "org.brainshift.ModulePlugin/1.4"
Q_DECLARE_INTERFACE(brainshift::ModulePlugin, BrainShiftModulePlugin_iid)
