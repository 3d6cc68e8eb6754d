#pragma once
// The biomechanical model of a case as files meet it: the tetrahedral mesh (mesh.vtu, cell array
// "Label", preoperative frame, mm) and the brain surface's displacements (brain_surface.vtp,
// point arrays "MeshNodeId", "Displacement", "Imposed"), turned into a finite element job, and
// the solved displacements put back on the mesh as the point array "Displacement".
#include "Configuration.h"
#include "FiniteElementJob.h"

#include <vtkPolyData.h>
#include <vtkUnstructuredGrid.h>

#include <string>

namespace brainshift {

/// Young's modulus in the configuration is in Pa; the solver works in N/mm^2 (MPa).
constexpr double PascalToNewtonPerSquareMillimetre = 1e-6;

/// InputError naming `meshName` or `surfaceName` for what is wrong in them: cells that are not
/// tetrahedra, no "Label", a label without a material, inverted or flat tetrahedra, surface
/// points without a mesh node, a node imposed twice with different values, no imposed node.
FiniteElementJob finiteElementJobFromModel(vtkUnstructuredGrid* mesh, vtkPolyData* surface, const Configuration& configuration,
                                           const std::string& meshName, const std::string& surfaceName);

/// Sets (replaces) the point arrays "Displacement" (mm) and "DisplacementMagnitude" of the mesh.
void attachDisplacements(vtkUnstructuredGrid* mesh, const FiniteElementResult& result);

} // namespace brainshift
