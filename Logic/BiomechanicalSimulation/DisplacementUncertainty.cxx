#include "DisplacementUncertainty.h"

#include "Configuration.h"

#include <vtkIdList.h>
#include <vtkNew.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkStaticPointLocator.h>

#include <cmath>
#include <stdexcept>

namespace brainshift {
namespace {
vtkNew<vtkPolyData> pointSet(const std::vector<std::array<double, 3>>& points)
{
  vtkNew<vtkPoints> vtkPointsOf;
  for (const auto& p : points) vtkPointsOf->InsertNextPoint(p.data());
  vtkNew<vtkPolyData> set;
  set->SetPoints(vtkPointsOf);
  return set;
}
} // namespace

std::vector<double> nodalDisplacementUncertainty(const std::vector<double>& nodes, const std::vector<double>& displacements,
                                                 const DisplacementEvidence& evidence, const DisplacementUncertaintyModel& model)
{
  if (displacements.size() != nodes.size()) throw std::invalid_argument("one displacement per node is expected");
  if (evidence.misfitPoints.size() != evidence.misfitsMm.size()) throw std::invalid_argument("one misfit per match is expected");
  const std::size_t n = nodes.size() / 3;
  std::vector<double> sigma(n, model.floorMm);
  auto evidenceSet = pointSet(evidence.points);
  vtkNew<vtkStaticPointLocator> nearest;
  if (!evidence.points.empty()) {
    nearest->SetDataSet(evidenceSet);
    nearest->BuildLocator();
  }
  auto misfitSet = pointSet(evidence.misfitPoints);
  vtkNew<vtkStaticPointLocator> around;
  if (!evidence.misfitPoints.empty()) {
    around->SetDataSet(misfitSet);
    around->BuildLocator();
  }
  vtkNew<vtkIdList> within;
  const double spread = model.misfitReachMm / 2;
  for (std::size_t i = 0; i < n; ++i) {
    double x[3] = {nodes[3 * i], nodes[3 * i + 1], nodes[3 * i + 2]};
    double distance = 0;
    if (!evidence.points.empty()) {
      const double* e = evidenceSet->GetPoint(nearest->FindClosestPoint(x));
      distance = std::sqrt((x[0] - e[0]) * (x[0] - e[0]) + (x[1] - e[1]) * (x[1] - e[1]) + (x[2] - e[2]) * (x[2] - e[2]));
    }
    double misfitSquared = 0;
    if (!evidence.misfitPoints.empty()) {
      around->FindPointsWithinRadius(model.misfitReachMm, x, within);
      double weights = 0, sum = 0;
      for (vtkIdType k = 0; k < within->GetNumberOfIds(); ++k) {
        const vtkIdType id = within->GetId(k);
        const double* p = misfitSet->GetPoint(id);
        const double r2 = (x[0] - p[0]) * (x[0] - p[0]) + (x[1] - p[1]) * (x[1] - p[1]) + (x[2] - p[2]) * (x[2] - p[2]);
        const double w = std::exp(-r2 / (2 * spread * spread));
        weights += w;
        sum += w * evidence.misfitsMm[std::size_t(id)] * evidence.misfitsMm[std::size_t(id)];
      }
      if (weights > 0) misfitSquared = sum / weights;
    }
    const double growth = model.growthPerMm * distance;
    const double* u = &displacements[3 * i];
    const double moved = model.displacementShare * std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    sigma[i] = std::sqrt(model.floorMm * model.floorMm + growth * growth + misfitSquared + moved * moved);
  }
  return sigma;
}

DisplacementUncertaintyModel displacementUncertaintyModelFrom(const Configuration& configuration)
{
  DisplacementUncertaintyModel model;
  model.floorMm = configuration.uncertainty.floorMm;
  model.growthPerMm = configuration.uncertainty.growthPerMm;
  model.misfitReachMm = configuration.uncertainty.misfitReachMm;
  model.displacementShare = configuration.uncertainty.displacementShare;
  return model;
}

} // namespace brainshift
