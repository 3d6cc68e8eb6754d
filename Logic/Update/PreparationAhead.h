#pragma once
// A first scan's mesh and preoperative brain boundary, made on a thread of their own while the
// rigid registration and the classification run. Both need the preoperative labels alone, and the
// rigid registration keeps one core (its metric sums its samples in one order, for the same result
// every run): the other core meshes and fits the preoperative boundary meanwhile. The mesh and
// surface stages then take them as a later scan takes the previous scan's (the same functions,
// the same figures; only their time moves). A watch session prepares them before surgery instead.
#include "ActiveSurfaceLogic.h"
#include "BrainShiftErrors.h"
#include "LabelMapMesher.h"

#include <atomic>
#include <exception>
#include <future>
#include <memory>
#include <thread>

namespace brainshift {

class RunContext;

class PreparationAhead {
public:
  /// Started for a run of the whole pipeline that would mesh and fit the preoperative boundary
  /// itself (no watch session, no previous scan, preoperative labels given); null otherwise. The
  /// thread works on its own copy of the labels: ITK's pipeline sets an input's requested region,
  /// so no image is shared between threads.
  static std::shared_ptr<PreparationAhead> startFor(RunContext& context);
  /// Abandons the work (a run that failed before the mesh stage) and waits for the thread.
  ~PreparationAhead();
  PreparationAhead(const PreparationAhead&) = delete;
  PreparationAhead& operator=(const PreparationAhead&) = delete;

  /// Waits for the mesh (the run's `cancel` reaches the thread meanwhile); what failed there is
  /// thrown here, as the stage would have thrown it.
  const LabelMapMesh& mesh(CancelFlag cancel);
  /// Waits for the preoperative boundary on that mesh likewise.
  const PreoperativeBrainBoundary& boundary(CancelFlag cancel);
  /// The thread's seconds for each (not the wait's).
  double meshSeconds() const { return meshSeconds_; }

private:
  PreparationAhead(LabelImage::Pointer labels, MeshingParameters meshing, ActiveSurfaceParameters surface, ActiveSurfaceInputNames names);
  void work();
  static void waitFor(std::shared_future<void>& done, std::atomic<bool>& abandon, CancelFlag cancel);

  std::atomic<bool> abandon_{false};
  LabelImage::Pointer labels_;
  MeshingParameters meshing_;
  ActiveSurfaceParameters surface_;
  ActiveSurfaceInputNames names_;
  LabelMapMesh mesh_;          ///< the thread's, which it fits the boundary on
  LabelMapMesh meshForStage_;  ///< a deep copy, the mesh stage's alone (VTK's accessors are not thread-safe)
  double meshSeconds_ = 0;
  PreoperativeBrainBoundary boundary_;
  std::promise<void> meshMade_, boundaryFound_;
  std::shared_future<void> meshDone_, boundaryDone_;
  std::thread thread_; ///< last: started once everything it uses exists
};

} // namespace brainshift
