#include "ImageMatchConstraints.h"

#include <vtkGenericCell.h>
#include <vtkNew.h>
#include <vtkStaticCellLocator.h>

#include <algorithm>

namespace brainshift {

struct MeshPointLocator::Impl {
  vtkSmartPointer<vtkUnstructuredGrid> mesh;
  vtkNew<vtkStaticCellLocator> locator;
  vtkNew<vtkGenericCell> cell;
};

MeshPointLocator::MeshPointLocator(vtkUnstructuredGrid* mesh)
  : impl_(std::make_unique<Impl>())
{
  impl_->mesh = mesh;
  impl_->locator->SetDataSet(mesh);
  impl_->locator->BuildLocator();
}

MeshPointLocator::~MeshPointLocator() = default;

std::optional<MeshPointLocator::Location> MeshPointLocator::locate(const PhysicalPoint& point) const
{
  double x[3] = {point[0], point[1], point[2]}, pcoords[3], weights[8];
  const vtkIdType id = impl_->locator->FindCell(x, 1e-6, impl_->cell, pcoords, weights);
  if (id < 0) return std::nullopt;
  Location location;
  location.tetrahedron = std::int32_t(id);
  double sum = 0;
  for (int k = 0; k < 4; ++k) {
    location.weights[std::size_t(k)] = std::clamp(weights[k], 0.0, 1.0);
    sum += location.weights[std::size_t(k)];
  }
  for (double& w : location.weights) w /= sum;
  return location;
}

std::optional<std::array<double, 3>> MeshPointLocator::interpolate(const std::vector<double>& nodal, const PhysicalPoint& point) const
{
  const auto location = locate(point);
  if (!location) return std::nullopt;
  const vtkIdType* ids = nullptr;
  vtkIdType count = 0;
  impl_->mesh->GetCellPoints(location->tetrahedron, count, ids);
  std::array<double, 3> value{0, 0, 0};
  for (vtkIdType k = 0; k < count && k < 4; ++k) {
    for (int d = 0; d < 3; ++d) value[std::size_t(d)] += location->weights[std::size_t(k)] * nodal[3 * std::size_t(ids[k]) + std::size_t(d)];
  }
  return value;
}

std::array<double, 6> matchStiffness(const BlockMatch& match, double stiffnessNPerMm)
{
  const double confidence = std::max(match.similarity, 0.0);
  std::array<double, 6> W{};
  for (std::size_t i = 0; i < 6; ++i) W[i] = stiffnessNPerMm * confidence * confidence * match.structure[i];
  return W;
}

ImageMatchConstraints softConstraintsFromMatches(const MeshPointLocator& locator, const std::vector<BlockMatch>& matches,
                                                 double stiffnessNPerMm)
{
  ImageMatchConstraints result;
  for (std::size_t m = 0; m < matches.size(); ++m) {
    const auto location = locator.locate(matches[m].centre);
    if (!location) continue;
    SoftConstraint c;
    c.tetrahedron = location->tetrahedron;
    c.weights = location->weights;
    c.target = matches[m].displacement;
    c.stiffness = matchStiffness(matches[m], stiffnessNPerMm);
    result.constraints.push_back(c);
    result.matchOfConstraint.push_back(m);
  }
  return result;
}

} // namespace brainshift
