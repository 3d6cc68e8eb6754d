#pragma once
// Scalar volumes (MRI, fMRI statistics, MRA) and label maps.
#include "ImageTypes.h"
#include "Node.h"

#include <memory>
#include <optional>

namespace brainshift {

/// How a volume is shown. Colour tables are named as Slicer names them ("Grey", "Labels",
/// "ColdToHotRainbow", ...).
struct VolumeDisplay {
  std::string colorTable = "Grey";
  std::optional<double> window;       ///< unset: automatic window/level
  std::optional<double> level;
  /// Overlays: shown where lowerThreshold <= |value| <= upperThreshold, hidden elsewhere.
  std::optional<double> lowerThreshold;
  std::optional<double> upperThreshold;
  double opacity = 1.0;

  /// A statistical map (fMRI t-values) over an anatomy: a hot/cold colour scale, |t| < 3 hidden.
  static VolumeDisplay statisticalMap()
  {
    VolumeDisplay d;
    d.colorTable = "ColdToHotRainbow";
    d.window = 16.0;
    d.level = 0.0;
    d.lowerThreshold = 3.0;
    d.upperThreshold = 100.0;
    return d;
  }
  /// An error estimate in mm over the scan: green (below 1 mm) through red (3 mm and more),
  /// half transparent.
  static VolumeDisplay errorEstimateMm()
  {
    VolumeDisplay d;
    d.colorTable = "ColdToHotRainbow";
    d.window = 3.0;
    d.level = 1.5;
    d.opacity = 0.5;
    return d;
  }
};

class ScalarVolumeNode : public Node {
public:
  static std::shared_ptr<ScalarVolumeNode> create(const std::string& name, ScalarImage::Pointer image = nullptr);
  NodeKind kind() const override { return NodeKind::ScalarVolume; }
  const char* slicerClassName() const override { return "vtkMRMLScalarVolumeNode"; }

  ScalarImage* image() const { return image_.GetPointer(); }
  void setImage(ScalarImage::Pointer image);

  const VolumeDisplay& display() const { return display_; }
  void setDisplay(const VolumeDisplay& display);

private:
  ScalarImage::Pointer image_;
  VolumeDisplay display_;
};

class LabelMapVolumeNode : public Node {
public:
  static std::shared_ptr<LabelMapVolumeNode> create(const std::string& name, LabelImage::Pointer image = nullptr);
  NodeKind kind() const override { return NodeKind::LabelMapVolume; }
  const char* slicerClassName() const override { return "vtkMRMLLabelMapVolumeNode"; }

  LabelImage* image() const { return image_.GetPointer(); }
  void setImage(LabelImage::Pointer image);

  const VolumeDisplay& display() const { return display_; }
  void setDisplay(const VolumeDisplay& display);

private:
  LabelImage::Pointer image_;
  VolumeDisplay display_{"Labels", {}, {}, {}, {}, 1.0};
};

} // namespace brainshift
