#include "ThreeDView.h"

#include "TransformIO.h"
#include "TransformNode.h"

#include <vtkActor.h>
#include <vtkArrowSource.h>
#include <vtkCellArray.h>
#include <vtkDoubleArray.h>
#include <vtkGlyph3D.h>
#include <vtkMatrix4x4.h>
#include <vtkPlaneSource.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkCamera.h>
#include <vtkDataArray.h>
#include <vtkDataSetMapper.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkLookupTable.h>
#include <vtkPointData.h>
#include <vtkProperty.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkScalarBarActor.h>
#include <vtkTextProperty.h>

#include <algorithm>
#include <cmath>
#include <set>

namespace brainshift {

vtkSmartPointer<vtkMatrix4x4> childToWorldMatrix(const Scene& scene, const Node& node)
{
  auto toWorld = vtkSmartPointer<vtkMatrix4x4>::New(); // identity
  std::set<std::string> visited; // a cycle would be a broken scene: stop rather than loop
  for (std::string id = node.parentTransformId(); !id.empty();) {
    if (!visited.insert(id).second) return nullptr; // a cycle: a broken scene
    auto transform = std::dynamic_pointer_cast<TransformNode>(scene.node(id));
    if (!transform) return nullptr; // a missing transform: where the model belongs is unknown
    const SpatialTransform* fromParent = transform->transformFromParent();
    if (fromParent) {
      if (!isLinearTransform(fromParent)) return nullptr;
      const AffineParameters a = affineParametersOf(fromParent);
      vtkNew<vtkMatrix4x4> parentToChild;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) parentToChild->SetElement(r, c, a.matrix[r][c]);
        parentToChild->SetElement(r, 3, a.translation[r]);
      }
      vtkNew<vtkMatrix4x4> childToParent;
      vtkMatrix4x4::Invert(parentToChild, childToParent);
      vtkMatrix4x4::Multiply4x4(childToParent, toWorld, toWorld); // this level after the ones below
    }
    id = transform->parentTransformId();
  }
  return toWorld;
}

std::string colouringArrayOf(const ModelNode& model)
{
  return model.display().activeScalarName.empty() ? "DisplacementMagnitude" : model.display().activeScalarName;
}

ThreeDView::ThreeDView(QWidget* parent)
  : QVTKOpenGLNativeWidget(parent)
{
  vtkNew<vtkGenericOpenGLRenderWindow> window;
  setRenderWindow(window);
  renderer_ = vtkRenderer::New();
  renderer_->SetBackground(0.1, 0.1, 0.15);
  window->AddRenderer(renderer_);
  scalarBar_ = vtkScalarBarActor::New();
  scalarBar_->SetTitle("Displacement (mm)");
  scalarBar_->SetNumberOfLabels(5);
  scalarBar_->SetLabelFormat("%.1f");
  scalarBar_->SetOrientationToHorizontal(); // room for the title at every view size
  scalarBar_->SetPosition(0.1, 0.02);
  scalarBar_->SetWidth(0.8);
  scalarBar_->SetHeight(0.17);
  scalarBar_->GetTitleTextProperty()->SetFontSize(11);
  scalarBar_->UnconstrainedFontSizeOn();
  scalarBar_->VisibilityOff();
  renderer_->AddViewProp(scalarBar_);
  // The slice planes, coloured as the slice views' frames are in 3D Slicer: sagittal yellow,
  // coronal green, axial red; translucent, hidden until asked for.
  const double colours[3][3] = {{0.93, 0.84, 0.26}, {0.43, 0.69, 0.34}, {0.95, 0.42, 0.36}};
  for (int axis = 0; axis < 3; ++axis) {
    planes_[std::size_t(axis)] = vtkActor::New();
    planes_[std::size_t(axis)]->GetProperty()->SetColor(colours[axis][0], colours[axis][1], colours[axis][2]);
    planes_[std::size_t(axis)]->GetProperty()->SetOpacity(0.25);
    planes_[std::size_t(axis)]->VisibilityOff();
    planes_[std::size_t(axis)]->PickableOff();
    renderer_->AddViewProp(planes_[std::size_t(axis)]);
  }
  vtkNew<vtkInteractorStyleTrackballCamera> style;
  interactor()->SetInteractorStyle(style);
  setMinimumSize(120, 120);
}

ThreeDView::~ThreeDView()
{
  renderer_->Delete();
  scalarBar_->Delete();
  for (vtkActor* plane : planes_) plane->Delete();
}

vtkActor* ThreeDView::modelActor(std::size_t i) const
{
  return i < modelActors_.size() ? modelActors_[i].GetPointer() : nullptr;
}

void ThreeDView::setModels(std::vector<std::shared_ptr<ModelNode>> models, ModelPlacement placement)
{
  models_ = std::move(models);
  modelActors_.clear();
  modelOfActor_.clear();
  problems_.clear();
  renderer_->RemoveAllViewProps();
  renderer_->AddViewProp(scalarBar_);
  for (vtkActor* plane : planes_) renderer_->AddViewProp(plane);
  scalarBar_->VisibilityOff();
  for (const auto& model : models_) {
    if (!model || !model->mesh()) continue;
    vtkNew<vtkDataSetMapper> mapper;
    mapper->SetInputData(model->mesh());
    auto actor = vtkSmartPointer<vtkActor>::New();
    actor->SetMapper(mapper);
    if (placement) {
      vtkSmartPointer<vtkMatrix4x4> toWorld = placement(*model);
      if (!toWorld) { // drawn in its own frame it would sit in the wrong place: not drawn, said
        problems_.push_back(QString::fromStdString("the model '" + model->name() +
                                                   "' is not shown: a transform it is placed under is missing or not linear"));
        continue;
      }
      actor->SetUserMatrix(toWorld);
    }
    modelActors_.push_back(actor);
    modelOfActor_.push_back(model);
    const ModelDisplay& display = model->display();
    actor->GetProperty()->SetColor(display.color[0], display.color[1], display.color[2]);
    actor->GetProperty()->SetOpacity(display.opacity);
    const std::string arrayName = colouringArrayOf(*model);
    vtkDataArray* values = model->mesh()->GetPointData()->GetArray(arrayName.c_str());
    if (display.scalarVisibility && values) {
      double range[2];
      values->GetRange(range, values->GetNumberOfComponents() == 1 ? 0 : -1);
      if (display.scalarRange) {
        range[0] = (*display.scalarRange)[0];
        range[1] = (*display.scalarRange)[1];
      }
      vtkNew<vtkLookupTable> colors; // ColdToHotRainbow: no displacement blue, the largest red
      colors->SetHueRange(0.667, 0.0);
      colors->SetTableRange(range);
      colors->Build();
      mapper->SetLookupTable(colors);
      mapper->SetScalarModeToUsePointFieldData();
      mapper->SelectColorArray(arrayName.c_str());
      mapper->SetScalarRange(range);
      mapper->ScalarVisibilityOn();
      scalarBar_->SetLookupTable(colors);
      scalarBar_->VisibilityOn();
    } else {
      mapper->ScalarVisibilityOff();
    }
    renderer_->AddViewProp(actor);
  }
  updateArrows();
  resetCamera();
  renderWindow()->Render();
}

void ThreeDView::setDisplacementArrowsVisible(bool visible)
{
  arrowsVisible_ = visible;
  updateArrows();
  renderWindow()->Render();
}

std::size_t ThreeDView::displacementArrowCount() const
{
  return arrowCount_;
}

void ThreeDView::updateArrows()
{
  for (const auto& actor : arrowActors_) renderer_->RemoveViewProp(actor);
  arrowActors_.clear();
  arrowCount_ = 0;
  if (!arrowsVisible_) return;
  for (std::size_t m = 0; m < modelActors_.size(); ++m) {
    const ModelNode& model = *modelOfActor_[m];
    vtkDataArray* displacement = model.mesh()->GetPointData()->GetArray("Displacement");
    if (!model.display().scalarVisibility || !displacement || displacement->GetNumberOfComponents() != 3) continue;
    // At most about 2,000 arrows, every k-th point: a readable field, not a carpet.
    const vtkIdType n = model.mesh()->GetNumberOfPoints();
    const vtkIdType stride = std::max<vtkIdType>(1, (n + 1999) / 2000);
    vtkNew<vtkPoints> starts;
    vtkNew<vtkDoubleArray> vectors;
    vectors->SetNumberOfComponents(3);
    vectors->SetName("Displacement");
    for (vtkIdType i = 0; i < n; i += stride) {
      double p[3], d[3];
      model.mesh()->GetPoint(i, p);
      displacement->GetTuple(i, d);
      if (!(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) > 0.05)) continue; // a point that did not move
      starts->InsertNextPoint(p[0] - d[0], p[1] - d[1], p[2] - d[2]); // the point is the final position
      vectors->InsertNextTuple(d);
    }
    vtkNew<vtkPolyData> origins;
    origins->SetPoints(starts);
    origins->GetPointData()->SetVectors(vectors);
    vtkNew<vtkArrowSource> arrow;
    arrow->SetTipLength(0.3);
    arrow->SetTipRadius(0.12);
    arrow->SetShaftRadius(0.04);
    vtkNew<vtkGlyph3D> glyphs; // unit arrows along x, scaled to |d| and turned to d
    glyphs->SetInputData(origins);
    glyphs->SetSourceConnection(arrow->GetOutputPort());
    glyphs->SetVectorModeToUseVector();
    glyphs->SetScaleModeToScaleByVector();
    glyphs->SetScaleFactor(1.0);
    glyphs->OrientOn();
    glyphs->Update();
    vtkNew<vtkPolyDataMapper> mapper;
    mapper->SetInputConnection(glyphs->GetOutputPort());
    mapper->ScalarVisibilityOff();
    auto actor = vtkSmartPointer<vtkActor>::New();
    actor->SetMapper(mapper);
    actor->GetProperty()->SetColor(1.0, 1.0, 1.0);
    actor->SetUserMatrix(modelActors_[m]->GetUserMatrix()); // the model's frame
    arrowCount_ += std::size_t(origins->GetNumberOfPoints());
    renderer_->AddViewProp(actor);
    arrowActors_.push_back(actor);
  }
}

void ThreeDView::setSlicePlanes(const PhysicalPoint& cursor, const std::array<double, 6>& bounds)
{
  for (int axis = 0; axis < 3; ++axis) {
    // The plane normal to `axis` through the cursor, spanning the bounds of the other two axes.
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    double origin[3], pointU[3], pointV[3];
    for (int d = 0; d < 3; ++d) origin[d] = pointU[d] = pointV[d] = bounds[std::size_t(2 * d)];
    origin[axis] = pointU[axis] = pointV[axis] = cursor[unsigned(axis)];
    pointU[u] = bounds[std::size_t(2 * u + 1)];
    pointV[v] = bounds[std::size_t(2 * v + 1)];
    vtkNew<vtkPlaneSource> plane;
    plane->SetOrigin(origin);
    plane->SetPoint1(pointU);
    plane->SetPoint2(pointV);
    plane->Update();
    vtkNew<vtkPolyDataMapper> mapper;
    mapper->SetInputConnection(plane->GetOutputPort());
    planes_[std::size_t(axis)]->SetMapper(mapper);
    planes_[std::size_t(axis)]->SetVisibility(planesVisible_);
  }
  renderWindow()->Render();
}

void ThreeDView::setSlicePlanesVisible(bool visible)
{
  planesVisible_ = visible;
  for (vtkActor* plane : planes_) plane->SetVisibility(visible && plane->GetMapper() != nullptr);
  renderWindow()->Render();
}

void ThreeDView::resetCamera()
{
  vtkCamera* camera = renderer_->GetActiveCamera();
  camera->SetFocalPoint(0.0, 0.0, 0.0);
  camera->SetPosition(0.0, -1.0, 0.0); // anterior of the focal point (LPS: -P)
  camera->SetViewUp(0.0, 0.0, 1.0);    // superior
  renderer_->ResetCamera();
}

} // namespace brainshift
