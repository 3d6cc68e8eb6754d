#pragma once
// The image's matches inside the brain (Logic/BlockMatching) as soft constraints of the finite
// element solve: each match's centre located in the preoperative mesh (its tetrahedron and
// barycentric weights), its displacement the target, its weight the match's confidence along the
// directions its structure pins down. Also where points fall in the mesh and what a solved mesh
// predicts there (the start of the matching).
#include "BlockMatching.h"
#include "FiniteElementJob.h"

#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>

#include <array>
#include <cstdint>
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

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// W = stiffness * max(similarity, 0)^2 * structure (xx, xy, xz, yy, yz, zz).
std::array<double, 6> matchStiffness(const BlockMatch& match, double stiffnessNPerMm);

struct ImageMatchConstraints {
  std::vector<SoftConstraint> constraints;
  std::vector<std::size_t> matchOfConstraint; ///< index into the matches
};

/// One constraint per match whose centre lies in the mesh (the others are left out).
ImageMatchConstraints softConstraintsFromMatches(const MeshPointLocator& locator, const std::vector<BlockMatch>& matches,
                                                 double stiffnessNPerMm);

} // namespace brainshift
