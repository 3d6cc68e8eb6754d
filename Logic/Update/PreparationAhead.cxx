#include "PreparationAhead.h"

#include "UpdatePipeline.h"

#include <itkImageDuplicator.h>

#include <chrono>

namespace brainshift {

std::shared_ptr<PreparationAhead> PreparationAhead::startFor(RunContext& context)
{
  if (context.session() || !context.options().previous.empty()) return nullptr; // prepared, or reused from a scan
  const LabelImage* labels = context.preopLabelsIfGiven();
  if (!labels) return nullptr; // the mesh stage says what is missing
  auto duplicator = itk::ImageDuplicator<LabelImage>::New();
  duplicator->SetInputImage(labels);
  duplicator->Update();
  ActiveSurfaceInputNames names;
  names.mesh = context.output("mesh.vtu").string();
  names.preopLabels = context.options().preopLabels.string();
  MeshingParameters meshing = meshingParametersFrom(context.configuration());
  ActiveSurfaceParameters surface = activeSurfaceParametersFrom(context.configuration());
  return std::shared_ptr<PreparationAhead>(new PreparationAhead(duplicator->GetOutput(), meshing, surface, names));
}

PreparationAhead::PreparationAhead(LabelImage::Pointer labels, MeshingParameters meshing, ActiveSurfaceParameters surface,
                                   ActiveSurfaceInputNames names)
  : labels_(std::move(labels))
  , meshing_(std::move(meshing))
  , surface_(std::move(surface))
  , names_(std::move(names))
  , meshDone_(meshMade_.get_future().share())
  , boundaryDone_(boundaryFound_.get_future().share())
{
  meshing_.cancel = &abandon_;
  surface_.cancel = &abandon_;
  thread_ = std::thread([this] { work(); });
}

PreparationAhead::~PreparationAhead()
{
  abandon_ = true;
  if (thread_.joinable()) thread_.join();
}

void PreparationAhead::work()
{
  const auto start = std::chrono::steady_clock::now();
  try {
    mesh_ = meshLabelMap(*labels_, meshing_);
    meshSeconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    meshForStage_ = mesh_;
    meshForStage_.mesh = vtkSmartPointer<vtkUnstructuredGrid>::New();
    meshForStage_.mesh->DeepCopy(mesh_.mesh);
    meshMade_.set_value();
  } catch (...) {
    meshMade_.set_exception(std::current_exception());
    boundaryFound_.set_exception(std::current_exception());
    return;
  }
  try {
    boundary_ = preoperativeBrainBoundary(mesh_.mesh, *labels_, surface_, names_);
    boundaryFound_.set_value();
  } catch (...) {
    boundaryFound_.set_exception(std::current_exception());
  }
}

void PreparationAhead::waitFor(std::shared_future<void>& done, std::atomic<bool>& abandon, CancelFlag cancel)
{
  if (cancel && *cancel) abandon = true;
  while (done.wait_for(std::chrono::milliseconds(20)) != std::future_status::ready) {
    if (cancel && *cancel) abandon = true; // the thread stops at its next check and throws CancelledError
  }
  done.get(); // rethrows the thread's failure
}

const LabelMapMesh& PreparationAhead::mesh(CancelFlag cancel)
{
  waitFor(meshDone_, abandon_, cancel);
  return meshForStage_;
}

const PreoperativeBrainBoundary& PreparationAhead::boundary(CancelFlag cancel)
{
  waitFor(boundaryDone_, abandon_, cancel);
  return boundary_;
}

} // namespace brainshift
