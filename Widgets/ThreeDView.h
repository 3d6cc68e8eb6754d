#pragma once
// The 3D view: models (the brain surface, meshes) in LPS mm, a surface coloured by its
// `DisplacementMagnitude` point array with a colour bar in mm (see ImageConversion.h for the
// coordinate convention). The view's frame is the scene's world frame (the intraoperative one);
// a model placed under transforms (the contract's surfaces live in the preoperative frame, under
// `rigid intraop_to_preop`) is shown through them (childToWorldMatrix). Optional: arrows from each
// surface point's initial to its final position (its `Displacement`), and the three slice planes
// through the cursor.
#include "ModelNode.h"
#include "Scene.h"

#include <QStringList>
#include <QVTKOpenGLNativeWidget.h>
#include <vtkSmartPointer.h>

#include <array>
#include <functional>
#include <memory>
#include <vector>

class vtkActor;
class vtkMatrix4x4;
class vtkRenderer;
class vtkScalarBarActor;

namespace brainshift {

class ThreeDView : public QVTKOpenGLNativeWidget {
  Q_OBJECT
public:
  explicit ThreeDView(QWidget* parent = nullptr);
  ~ThreeDView() override;

  /// Where a model's points go in the view: a 4x4 from its frame to the world (null: as they are).
  using ModelPlacement = std::function<vtkSmartPointer<vtkMatrix4x4>(const ModelNode&)>;

  /// Shows these models (replacing the ones shown), each placed by `placement`. A model whose
  /// display has scalar visibility is coloured by its active scalar array (DisplacementMagnitude
  /// by default) and gets the bar.
  void setModels(std::vector<std::shared_ptr<ModelNode>> models, ModelPlacement placement = {});
  const std::vector<std::shared_ptr<ModelNode>>& models() const { return models_; }
  /// The actor of the i-th model drawn (tests read its bounds), or null.
  vtkActor* modelActor(std::size_t i) const;
  /// Why models were not drawn (a transform above them missing or not linear), from the last setModels.
  const QStringList& problems() const { return problems_; }

  /// Arrows from the initial to the final position of the points of every coloured model with a
  /// 3-component `Displacement` array (at most 2,000 per model, every k-th point).
  void setDisplacementArrowsVisible(bool visible);
  bool displacementArrowsVisible() const { return arrowsVisible_; }
  /// How many arrows are drawn now (0 while hidden).
  std::size_t displacementArrowCount() const;

  /// The axial, sagittal and coronal planes through `cursor` (LPS mm), across `bounds`
  /// (xmin, xmax, ymin, ymax, zmin, zmax): the slice views' planes in 3D.
  void setSlicePlanes(const PhysicalPoint& cursor, const std::array<double, 6>& bounds);
  void setSlicePlanesVisible(bool visible);
  bool slicePlanesVisible() const { return planesVisible_; }
  /// The drawn plane of axis 0 (sagittal, x), 1 (coronal, y) or 2 (axial, z) (tests read its bounds).
  vtkActor* slicePlaneActor(int axis) const { return planes_[std::size_t(axis)]; }
  /// The colour bar, shown when a model is coloured; its title is "Displacement (mm)".
  vtkScalarBarActor* scalarBar() const { return scalarBar_; }
  /// Looks at the models from the patient's front (anterior, -P), superior up.
  void resetCamera();

private:
  void updateArrows();

  std::vector<std::shared_ptr<ModelNode>> models_;
  std::vector<vtkSmartPointer<vtkActor>> modelActors_, arrowActors_;
  std::vector<std::shared_ptr<ModelNode>> modelOfActor_; ///< the model each drawn actor shows
  QStringList problems_;
  vtkRenderer* renderer_;
  vtkScalarBarActor* scalarBar_;
  std::array<vtkActor*, 3> planes_{};
  bool arrowsVisible_ = false, planesVisible_ = false;
  std::size_t arrowCount_ = 0;
};

/// The array a coloured model is coloured by: its display's choice, else DisplacementMagnitude.
std::string colouringArrayOf(const ModelNode& model);

/// The matrix that takes `node`'s points from its frame to the scene's world frame, through the
/// transforms it is placed under (each transform node's transformFromParent maps its parent frame
/// to its child frame, so the way up is its inverse). Null when a transform on the way is not
/// linear (a displacement field), or missing: such a model is not drawn (ThreeDView::problems).
vtkSmartPointer<vtkMatrix4x4> childToWorldMatrix(const Scene& scene, const Node& node);

} // namespace brainshift
