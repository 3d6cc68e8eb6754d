#include "ThreeDView.h"

#include <vtkActor.h>
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

namespace brainshift {

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
  vtkNew<vtkInteractorStyleTrackballCamera> style;
  interactor()->SetInteractorStyle(style);
  setMinimumSize(120, 120);
}

ThreeDView::~ThreeDView()
{
  renderer_->Delete();
  scalarBar_->Delete();
}

void ThreeDView::setModels(std::vector<std::shared_ptr<ModelNode>> models)
{
  models_ = std::move(models);
  renderer_->RemoveAllViewProps();
  renderer_->AddViewProp(scalarBar_);
  scalarBar_->VisibilityOff();
  for (const auto& model : models_) {
    if (!model || !model->mesh()) continue;
    vtkNew<vtkDataSetMapper> mapper;
    mapper->SetInputData(model->mesh());
    vtkNew<vtkActor> actor;
    actor->SetMapper(mapper);
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
  resetCamera();
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
