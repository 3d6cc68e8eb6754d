#pragma once
// The 3D view: models (the brain surface, meshes) in LPS mm, a surface coloured by its
// `DisplacementMagnitude` point array with a colour bar in mm (see ImageConversion.h for the
// coordinate convention). Models are shown in their own frame (the preoperative frame for the
// contract's surfaces); the view does not apply parent transforms.
#include "ModelNode.h"

#include <QVTKOpenGLNativeWidget.h>

#include <memory>
#include <vector>

class vtkRenderer;
class vtkScalarBarActor;

namespace brainshift {

class ThreeDView : public QVTKOpenGLNativeWidget {
  Q_OBJECT
public:
  explicit ThreeDView(QWidget* parent = nullptr);
  ~ThreeDView() override;

  /// Shows these models (replacing the ones shown). A model whose display has scalar visibility
  /// is coloured by its active scalar array (DisplacementMagnitude by default) and gets the bar.
  void setModels(std::vector<std::shared_ptr<ModelNode>> models);
  const std::vector<std::shared_ptr<ModelNode>>& models() const { return models_; }
  /// The colour bar, shown when a model is coloured; its title is "Displacement (mm)".
  vtkScalarBarActor* scalarBar() const { return scalarBar_; }
  /// Looks at the models from the patient's front (anterior, -P), superior up.
  void resetCamera();

private:
  std::vector<std::shared_ptr<ModelNode>> models_;
  vtkRenderer* renderer_;
  vtkScalarBarActor* scalarBar_;
};

/// The array a coloured model is coloured by: its display's choice, else DisplacementMagnitude.
std::string colouringArrayOf(const ModelNode& model);

} // namespace brainshift
