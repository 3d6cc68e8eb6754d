#include "BiomechanicalModel.h"

#include "BrainShiftErrors.h"

#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkDataArray.h>
#include <vtkDoubleArray.h>
#include <vtkIdList.h>
#include <vtkPointData.h>

#include <cmath>
#include <map>
#include <sstream>

namespace brainshift {

FiniteElementJob finiteElementJobFromModel(vtkUnstructuredGrid* mesh, vtkPolyData* surface, const Configuration& configuration,
                                           const std::string& meshName, const std::string& surfaceName)
{
  if (!mesh || mesh->GetNumberOfPoints() == 0 || mesh->GetNumberOfCells() == 0) {
    throw InputError(meshName + ": the mesh has no tetrahedra");
  }
  vtkDataArray* labels = mesh->GetCellData()->GetArray("Label");
  if (!labels) throw InputError(meshName + ": no cell array \"Label\" (the tissue of each tetrahedron)");
  FiniteElementJob job;
  const vtkIdType points = mesh->GetNumberOfPoints();
  job.nodes.resize(std::size_t(3 * points));
  for (vtkIdType i = 0; i < points; ++i) mesh->GetPoint(i, &job.nodes[std::size_t(3 * i)]);
  std::map<int, std::int32_t> materialOfLabel;
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    if (mesh->GetCellType(c) != VTK_TETRA) {
      throw InputError(meshName + ": cell " + std::to_string(c) + " is not a linear tetrahedron (VTK type " +
                       std::to_string(mesh->GetCellType(c)) + ")");
    }
    mesh->GetCellPoints(c, ids);
    for (vtkIdType k = 0; k < 4; ++k) job.tetrahedra.push_back(std::int32_t(ids->GetId(k)));
    const int label = int(std::lround(labels->GetComponent(c, 0)));
    auto found = materialOfLabel.find(label);
    if (found == materialOfLabel.end()) {
      auto material = configuration.materials.find(label);
      if (material == configuration.materials.end()) {
        throw InputError(meshName + ": tissue label " + std::to_string(label) +
                         " has no material in the configuration (\"materials\": {\"" + std::to_string(label) + "\": ...})");
      }
      job.materials.push_back({material->second.youngsModulusPa * PascalToNewtonPerSquareMillimetre, material->second.poissonRatio});
      found = materialOfLabel.emplace(label, std::int32_t(job.materials.size() - 1)).first;
    }
    job.materialOfTetrahedron.push_back(found->second);
  }
  if (!surface || surface->GetNumberOfPoints() == 0) throw InputError(surfaceName + ": the surface has no points");
  vtkDataArray* nodeIds = surface->GetPointData()->GetArray("MeshNodeId");
  vtkDataArray* displacement = surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* imposed = surface->GetPointData()->GetArray("Imposed");
  if (!nodeIds || !displacement || displacement->GetNumberOfComponents() != 3) {
    throw InputError(surfaceName + ": point arrays \"MeshNodeId\" and \"Displacement\" (3 components) are required");
  }
  std::map<std::int32_t, std::array<double, 3>> fixed;
  for (vtkIdType p = 0; p < surface->GetNumberOfPoints(); ++p) {
    if (imposed && imposed->GetComponent(p, 0) == 0) continue; // a free node: no boundary condition
    const double id = nodeIds->GetComponent(p, 0);
    if (id < 0 || id >= double(points) || id != std::floor(id)) {
      throw InputError(surfaceName + ": point " + std::to_string(p) + " moves mesh node " + std::to_string(id) +
                       ", which " + meshName + " does not have");
    }
    std::array<double, 3> d{displacement->GetComponent(p, 0), displacement->GetComponent(p, 1), displacement->GetComponent(p, 2)};
    for (double v : d) {
      if (!std::isfinite(v)) throw InputError(surfaceName + ": point " + std::to_string(p) + " has a non-finite displacement");
    }
    auto [at, inserted] = fixed.emplace(std::int32_t(id), d);
    if (!inserted && (std::abs(at->second[0] - d[0]) > 1e-9 || std::abs(at->second[1] - d[1]) > 1e-9 || std::abs(at->second[2] - d[2]) > 1e-9)) {
      throw InputError(surfaceName + ": mesh node " + std::to_string(std::int32_t(id)) + " is given two different displacements");
    }
  }
  if (fixed.empty()) {
    throw InputError(surfaceName + ": no point is imposed (\"Imposed\" is 0 everywhere): the displacement is not determined");
  }
  for (const auto& [node, d] : fixed) {
    job.fixedNodes.push_back(node);
    job.fixedDisplacements.insert(job.fixedDisplacements.end(), d.begin(), d.end());
  }
  job.solverOptions = configuration.solverOptions;
  try {
    job.validate();
  } catch (const std::invalid_argument& e) {
    throw InputError(meshName + ": " + e.what());
  }
  return job;
}

void attachDisplacements(vtkUnstructuredGrid* mesh, const FiniteElementResult& result)
{
  vtkNew<vtkDoubleArray> displacement, magnitude;
  displacement->SetName("Displacement");
  displacement->SetNumberOfComponents(3);
  magnitude->SetName("DisplacementMagnitude");
  const vtkIdType n = mesh->GetNumberOfPoints();
  if (result.displacements.size() != std::size_t(3 * n)) {
    throw std::invalid_argument("the result has " + std::to_string(result.displacements.size() / 3) + " nodes, the mesh " +
                                std::to_string(n));
  }
  displacement->SetNumberOfTuples(n);
  magnitude->SetNumberOfTuples(n);
  for (vtkIdType i = 0; i < n; ++i) {
    const double* d = &result.displacements[std::size_t(3 * i)];
    displacement->SetTuple(i, d);
    magnitude->SetValue(i, std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
  }
  mesh->GetPointData()->AddArray(displacement);
  mesh->GetPointData()->AddArray(magnitude);
}

} // namespace brainshift
