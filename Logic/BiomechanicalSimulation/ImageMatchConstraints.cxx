#include "ImageMatchConstraints.h"

#include <vtkGenericCell.h>
#include <vtkIdList.h>
#include <vtkNew.h>
#include <vtkStaticCellLocator.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace brainshift {

struct MeshPointLocator::Impl {
  vtkSmartPointer<vtkUnstructuredGrid> mesh;
  vtkNew<vtkStaticCellLocator> locator;
  vtkNew<vtkGenericCell> cell;
  vtkNew<vtkIdList> candidates;
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
  constexpr double Tolerance = 1e-6;
  double x[3] = {point[0], point[1], point[2]}, pcoords[3], weights[8];
  vtkIdType id = impl_->locator->FindCell(x, Tolerance, impl_->cell, pcoords, weights);
  if (id < 0) return std::nullopt;
  // A point on a face or an edge lies in several tetrahedra, and which one the static locator finds
  // first depends on how its threads binned the cells: the same run gave matches 1e-16 mm apart and
  // solutions 1e-11 mm apart. The lowest id among those that hold the point, the same every run.
  const double bounds[6] = {x[0] - Tolerance, x[0] + Tolerance, x[1] - Tolerance, x[1] + Tolerance, x[2] - Tolerance, x[2] + Tolerance};
  impl_->candidates->Reset();
  impl_->locator->FindCellsWithinBounds(const_cast<double*>(bounds), impl_->candidates);
  vtkIdType lowest = id;
  for (vtkIdType c = 0; c < impl_->candidates->GetNumberOfIds(); ++c) {
    const vtkIdType candidate = impl_->candidates->GetId(c);
    if (candidate >= lowest) continue;
    double closest[3], candidatePcoords[3], candidateWeights[8], distance2 = 0;
    int subId = 0;
    impl_->mesh->GetCell(candidate, impl_->cell);
    if (impl_->cell->EvaluatePosition(x, closest, subId, candidatePcoords, distance2, candidateWeights) == 1 &&
        distance2 <= Tolerance * Tolerance) {
      lowest = candidate;
      std::copy(candidateWeights, candidateWeights + 4, weights);
    }
  }
  id = lowest;
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

std::optional<PredictedDisplacement> MeshPointLocator::interpolateWithGradient(const std::vector<double>& nodal,
                                                                               const std::vector<double>& nodalGradient,
                                                                               const PhysicalPoint& point) const
{
  if (nodalGradient.size() != 3 * nodal.size()) {
    throw std::invalid_argument("interpolateWithGradient: nine gradient values per node (nodalGradients) are needed");
  }
  const auto location = locate(point);
  if (!location) return std::nullopt;
  const vtkIdType* ids = nullptr;
  vtkIdType count = 0;
  impl_->mesh->GetCellPoints(location->tetrahedron, count, ids);
  PredictedDisplacement result;
  std::array<std::array<double, 3>, 3> gradient{};
  for (vtkIdType k = 0; k < count && k < 4; ++k) {
    const double w = location->weights[std::size_t(k)];
    for (std::size_t a = 0; a < 3; ++a) {
      result.displacement[a] += w * nodal[3 * std::size_t(ids[k]) + a];
      for (std::size_t b = 0; b < 3; ++b) gradient[a][b] += w * nodalGradient[9 * std::size_t(ids[k]) + 3 * a + b];
    }
  }
  result.gradient = gradient;
  return result;
}

std::vector<double> nodalGradients(vtkUnstructuredGrid* mesh, const std::vector<double>& nodal)
{
  const vtkIdType nodes = mesh->GetNumberOfPoints();
  if (nodal.size() != 3 * std::size_t(nodes)) throw std::invalid_argument("nodal gradients: three values per node are needed");
  std::vector<double> sums(9 * std::size_t(nodes), 0.0), volumes(std::size_t(nodes), 0.0);
  const vtkIdType* ids = nullptr;
  vtkIdType count = 0;
  for (vtkIdType cell = 0; cell < mesh->GetNumberOfCells(); ++cell) {
    mesh->GetCellPoints(cell, count, ids);
    if (count != 4) throw std::invalid_argument("nodal gradients: cell " + std::to_string(cell) + " is not a linear tetrahedron");
    // Linear in the tetrahedron: G E = F, E's columns its edges from its first node, F's the
    // field's differences along them.
    double x[4][3], E[3][3], F[3][3];
    for (int k = 0; k < 4; ++k) mesh->GetPoint(ids[k], x[k]);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        E[r][c] = x[c + 1][r] - x[0][r];
        F[r][c] = nodal[3 * std::size_t(ids[c + 1]) + std::size_t(r)] - nodal[3 * std::size_t(ids[0]) + std::size_t(r)];
      }
    const double det = E[0][0] * (E[1][1] * E[2][2] - E[1][2] * E[2][1]) - E[0][1] * (E[1][0] * E[2][2] - E[1][2] * E[2][0]) +
                       E[0][2] * (E[1][0] * E[2][1] - E[1][1] * E[2][0]);
    const double volume = std::abs(det) / 6.0;
    if (!(volume > 1e-9)) continue; // degenerate (mm^3)
    double inverse[3][3];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        const int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3, c2 = (r + 2) % 3;
        inverse[r][c] = (E[r1][c1] * E[r2][c2] - E[r1][c2] * E[r2][c1]) / det; // the cofactors, transposed
      }
    double G[9] = {};
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        for (int m = 0; m < 3; ++m) G[3 * r + c] += F[r][m] * inverse[m][c];
    for (int k = 0; k < 4; ++k) {
      const std::size_t node = std::size_t(ids[k]);
      for (int g = 0; g < 9; ++g) sums[9 * node + std::size_t(g)] += volume * G[g];
      volumes[node] += volume;
    }
  }
  for (std::size_t node = 0; node < std::size_t(nodes); ++node) {
    if (volumes[node] > 0) {
      for (int g = 0; g < 9; ++g) sums[9 * node + std::size_t(g)] /= volumes[node];
    }
  }
  return sums;
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

BlockMatchingParameters blockMatchingParametersFrom(const Configuration& configuration, bool tumourResected)
{
  const Configuration::BlockMatching& c = configuration.blockMatching;
  BlockMatchingParameters p;
  p.blockHalfSizeMm = c.blockHalfSizeMm;
  p.blockSpacingMm = c.blockSpacingMm;
  p.selectedShare = c.selectedShare;
  p.selectionCellMm = c.selectionCellMm;
  p.maximumBlocks = std::size_t(c.maximumBlocks);
  p.searchRadiusMm = c.searchRadiusMm;
  p.minimumSimilarity = c.minimumSimilarity;
  p.deformedWindows = c.deformedWindows;
  p.smoothingMm = c.smoothingMm;
  if (tumourResected) p.excludedLabels = {4};
  return p;
}

SoftConstraintRejection softConstraintRejectionFrom(const Configuration& configuration)
{
  const Configuration::BlockMatching& c = configuration.blockMatching;
  return {int(c.rejectionRounds), c.rejectionFraction, c.outlierFactor, c.rejectionFloorMm};
}

namespace {
double largestDisplacement(const std::vector<double>& displacements)
{
  double largest = 0;
  for (std::size_t i = 0; i + 2 < displacements.size(); i += 3) {
    largest = std::max(largest, std::sqrt(displacements[i] * displacements[i] + displacements[i + 1] * displacements[i + 1] +
                                          displacements[i + 2] * displacements[i + 2]));
  }
  return largest;
}

double rmsMisfit(const FiniteElementJob& job, const std::vector<SoftConstraint>& constraints, const std::vector<double>& displacements)
{
  if (constraints.empty()) return 0;
  double sum = 0;
  for (const SoftConstraint& c : constraints) {
    const std::array<double, 3> r = softConstraintResidual(job, c, displacements);
    sum += r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
  }
  return std::sqrt(sum / double(constraints.size()));
}

double meanChange(const std::vector<double>& a, const std::vector<double>& b)
{
  double sum = 0;
  for (std::size_t i = 0; i + 2 < a.size(); i += 3) {
    sum += std::sqrt((a[i] - b[i]) * (a[i] - b[i]) + (a[i + 1] - b[i + 1]) * (a[i + 1] - b[i + 1]) + (a[i + 2] - b[i + 2]) * (a[i + 2] - b[i + 2]));
  }
  return sum / double(std::max<std::size_t>(1, a.size() / 3));
}
} // namespace

std::size_t keptSoftConstraints(const FiniteElementResult& result)
{
  std::size_t kept = 0;
  for (std::uint8_t k : result.softConstraintKept) kept += k;
  return kept;
}

ImageDrivenSolve solveWithImageMatches(vtkUnstructuredGrid* mesh, const FiniteElementJob& job, const FiniteElementResult& surfaceOnly,
                                       const ImageDrivenSolveInputs& in, const Configuration& configuration,
                                       const ConstrainedSolve& solve)
{
  if (!mesh || !in.preopImage || !in.preopLabels || !in.intraopImage || !in.intraopLabels || !in.rigidIntraopToPreop || !solve) {
    throw std::invalid_argument("image-driven solve: the mesh, both images, both label maps, the rigid transform and a solver are needed");
  }
  ImageDrivenSolve out;
  out.result = surfaceOnly;
  const MeshPointLocator locator(mesh);
  // The gradients only for a matching anew (a refine pass holds the earlier matches instead).
  const bool deformed = configuration.blockMatching.deformedWindows && !in.earlierMatching;
  const std::vector<double> gradients = deformed ? nodalGradients(mesh, surfaceOnly.displacements) : std::vector<double>{};
  const DisplacementPrediction prediction = [&](const PhysicalPoint& x) -> std::optional<PredictedDisplacement> {
    if (gradients.empty()) {
      const auto displacement = locator.interpolate(surfaceOnly.displacements, x);
      return displacement ? std::optional<PredictedDisplacement>(PredictedDisplacement{*displacement, std::nullopt}) : std::nullopt;
    }
    return locator.interpolateWithGradient(surfaceOnly.displacements, gradients, x);
  };
  BlockMatchingParameters parameters = blockMatchingParametersFrom(configuration, in.tumourResected);
  parameters.largestPredictedMm = std::min(largestDisplacement(surfaceOnly.displacements), 200.0);
  out.matching = in.earlierMatching
                   ? matchesStillInBrain(*in.earlierMatching, *in.preopImage, *in.intraopLabels, *in.rigidIntraopToPreop, parameters)
                   : matchBlocks(*in.preopImage, *in.preopLabels, *in.intraopImage, *in.intraopLabels, *in.rigidIntraopToPreop,
                                 prediction, parameters);
  out.constraints = softConstraintsFromMatches(locator, out.matching.matches, configuration.blockMatching.stiffnessNPerMm);
  if (out.constraints.constraints.empty()) return out;
  FiniteElementJob constrained = job;
  constrained.softConstraints = out.constraints.constraints;
  constrained.rejection = softConstraintRejectionFrom(configuration);
  out.result = solve(constrained);
  out.used = true;
  out.rmsMisfitSurfaceOnlyMm = rmsMisfit(job, out.constraints.constraints, surfaceOnly.displacements);
  out.meanNodeChangeMm = meanChange(out.result.displacements, surfaceOnly.displacements);
  for (std::size_t c = 0; c < out.constraints.constraints.size() && c < out.result.softConstraintMisfitMm.size(); ++c) {
    const PhysicalPoint& x = out.matching.matches[out.constraints.matchOfConstraint[c]].centre;
    const std::array<double, 3> point{x[0], x[1], x[2]};
    if (out.result.softConstraintKept[c]) out.evidence.points.push_back(point);
    out.evidence.misfitPoints.push_back(point);
    out.evidence.misfitsMm.push_back(out.result.softConstraintMisfitMm[c]);
  }
  return out;
}

} // namespace brainshift
