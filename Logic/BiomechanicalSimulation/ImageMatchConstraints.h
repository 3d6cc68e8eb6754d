#pragma once
// The image's matches inside the brain (Logic/BlockMatching) as soft constraints of the finite
// element solve: each match's centre located in the preoperative mesh (its tetrahedron and
// barycentric weights), its displacement the target, its weight the match's confidence along the
// directions its structure pins down. Also where points fall in the mesh and what a solved mesh
// predicts there (the start of the matching).
#include "BlockMatching.h"
#include "Configuration.h"
#include "DisplacementUncertainty.h"
#include "FiniteElementJob.h"

#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

namespace brainshift {

/// Locates points in a tetrahedral mesh (preoperative frame). Not thread-safe.
class MeshPointLocator {
public:
  explicit MeshPointLocator(vtkUnstructuredGrid* mesh);
  ~MeshPointLocator();
  struct Location {
    std::int32_t tetrahedron = 0;
    std::array<double, 4> weights{}; ///< barycentric, in the tetrahedron's node order
  };
  std::optional<Location> locate(const PhysicalPoint& point) const;
  /// The nodal field (3 values per node) interpolated at the point; nullopt outside the mesh.
  std::optional<std::array<double, 3>> interpolate(const std::vector<double>& nodal, const PhysicalPoint& point) const;
  /// The same with the field's gradient there, interpolated from `nodalGradient` (nodalGradients;
  /// std::invalid_argument when it holds other than nine values per node).
  std::optional<PredictedDisplacement> interpolateWithGradient(const std::vector<double>& nodal, const std::vector<double>& nodalGradient,
                                                               const PhysicalPoint& point) const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The gradient of a nodal field (3 values per node) at each node (9 values, row by row: d field_a
/// / d x_b): the mean of its tetrahedra's (the field is linear in each), weighted by their
/// volumes, so that it varies smoothly from node to node; degenerate tetrahedra left out.
/// std::invalid_argument for a field of another size or a cell that is not a linear tetrahedron.
std::vector<double> nodalGradients(vtkUnstructuredGrid* mesh, const std::vector<double>& nodal);

/// W = stiffness * max(similarity, 0)^2 * structure (xx, xy, xz, yy, yz, zz).
std::array<double, 6> matchStiffness(const BlockMatch& match, double stiffnessNPerMm);

struct ImageMatchConstraints {
  std::vector<SoftConstraint> constraints;
  std::vector<std::size_t> matchOfConstraint; ///< index into the matches
};

/// One constraint per match whose centre lies in the mesh (the others are left out).
ImageMatchConstraints softConstraintsFromMatches(const MeshPointLocator& locator, const std::vector<BlockMatch>& matches,
                                                 double stiffnessNPerMm);

/// The block matching and rejection settings of the configuration ("block_matching"); a tumour
/// decided resected is excluded from the blocks (its tissue is gone from the scan).
BlockMatchingParameters blockMatchingParametersFrom(const Configuration& configuration, bool tumourResected);
SoftConstraintRejection softConstraintRejectionFrom(const Configuration& configuration);

/// What the image-driven second solve needs besides the mesh and the first solve.
struct ImageDrivenSolveInputs {
  const ScalarImage* preopImage = nullptr;
  const LabelImage* preopLabels = nullptr;
  const ScalarImage* intraopImage = nullptr;
  const LabelImage* intraopLabels = nullptr; ///< the scan's classification
  const SpatialTransform* rigidIntraopToPreop = nullptr;
  bool tumourResected = false;
  /// An earlier matching of this scan with the same tumour decision (a refine pass's solve): its
  /// matches held against `intraopLabels` (matchesStillInBrain) instead of matching again. Null:
  /// match anew.
  const BlockMatchingResult* earlierMatching = nullptr;
};

struct ImageDrivenSolve {
  BlockMatchingResult matching;
  ImageMatchConstraints constraints;
  FiniteElementResult result;          ///< the surface-driven solution when no block matched
  bool used = false;                   ///< a second solve ran
  double rmsMisfitSurfaceOnlyMm = 0;   ///< the matches against the surface-driven solution
  double meanNodeChangeMm = 0;         ///< the second solve against the first
  /// The kept matches (points) and every match with its misfit, for the confidence map.
  DisplacementEvidence evidence;
};

/// How many of its soft constraints a solve kept (the last round's; 0 without constraints).
std::size_t keptSoftConstraints(const FiniteElementResult& result);

/// Solves a job (with soft constraints) as the caller solves: one-shot or in a served worker.
using ConstrainedSolve = std::function<FiniteElementResult(const FiniteElementJob&)>;

/// After Clatz et al. (2005): blocks matched from the surface-driven solution `surfaceOnly` of
/// `job` on `mesh` (or the earlier matching's, still in the brain), then `job` solved again
/// through `solve` with the matches as soft constraints, the worst rejected in rounds.
/// std::invalid_argument when an input is missing.
ImageDrivenSolve solveWithImageMatches(vtkUnstructuredGrid* mesh, const FiniteElementJob& job, const FiniteElementResult& surfaceOnly,
                                       const ImageDrivenSolveInputs& inputs, const Configuration& configuration,
                                       const ConstrainedSolve& solve);

} // namespace brainshift
