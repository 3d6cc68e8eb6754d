#pragma once
// The CGAL Mesh_3 backend of meshLabelMap (MeshingParameters::backend == Cgal): Delaunay
// refinement of the labelled image, its templates kept in CgalLabelMapMesher.cxx. Compiled only
// when CGAL is found (BRAINSHIFT_HAVE_CGAL); otherwise it throws NotAvailableError.
#include "BoundaryNodeSnapping.h"
#include "LabelMapMesher.h"

namespace brainshift {

/// Whether this build has the CGAL backend.
bool cgalMeshingAvailable();

/// The chosen tissues of `labels` meshed by CGAL: LPS mm, positive tetrahedra, each labelled with
/// its tissue. Deterministic (fixed random seed, sequential).
TetrahedralMeshArrays meshLabelMapWithCgal(const LabelImage& labels, const MeshingParameters& parameters);

} // namespace brainshift
