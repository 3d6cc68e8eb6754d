// The prediction block matching starts from: the surface-driven solution interpolated in the mesh,
// with its gradient (nodalGradients, MeshPointLocator::interpolateWithGradient).
// - A linear field u = A x + b on a jittered cube of tetrahedra: every node's gradient is A, and at
//   points inside the gradient is A (each tetrahedron's is A exactly) and the displacement A x + b
//   (within 1e-3 mm: the locator's choice among the tetrahedra that hold a point, below).
// - A field that is not linear (u = (0.01 y^2, 0.02 x z, 0)): the interpolated gradient lies near
//   the analytic one, closer on a finer mesh.
// - Outside the mesh: no prediction; a gradient array of another size or a cell that is not a
//   linear tetrahedron: refused.
// - The configuration's block matching settings reach the matching's parameters.
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"
#include "ImageMatchConstraints.h"
#include "SyntheticData.h"

#include <vtkCellArray.h>
#include <vtkCellType.h>
#include <vtkNew.h>
#include <vtkPoints.h>

#include <cmath>
#include <iostream>
#include <random>

namespace {
using namespace brainshift;

vtkSmartPointer<vtkUnstructuredGrid> gridOf(const FiniteElementJob& job)
{
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble(); // as the mesher's
  for (std::size_t v = 0; v < job.nodeCount(); ++v) points->InsertNextPoint(&job.nodes[3 * v]);
  auto grid = vtkSmartPointer<vtkUnstructuredGrid>::New();
  grid->SetPoints(points);
  for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
    const vtkIdType ids[4] = {job.tetrahedra[4 * t], job.tetrahedra[4 * t + 1], job.tetrahedra[4 * t + 2], job.tetrahedra[4 * t + 3]};
    grid->InsertNextCell(VTK_TETRA, 4, ids);
  }
  return grid;
}

std::vector<double> nodalField(const FiniteElementJob& job, const std::function<std::array<double, 3>(const double*)>& field)
{
  std::vector<double> values;
  for (std::size_t v = 0; v < job.nodeCount(); ++v) {
    const std::array<double, 3> u = field(&job.nodes[3 * v]);
    values.insert(values.end(), u.begin(), u.end());
  }
  return values;
}

/// The largest difference of the interpolated gradient from `exact` over random points of the cube's
/// inner part, and of the displacement from `field` when `checkDisplacement`.
double largestGradientError(const MeshPointLocator& locator, const std::vector<double>& nodal, const std::vector<double>& gradients,
                            double side, const std::function<std::array<std::array<double, 3>, 3>(const double*)>& exact)
{
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> inside(0.2 * side, 0.8 * side);
  double largest = 0;
  for (int n = 0; n < 200; ++n) {
    const double x[3] = {inside(rng), inside(rng), inside(rng)};
    const auto predicted = locator.interpolateWithGradient(nodal, gradients, testing::point(x[0], x[1], x[2]));
    BS_CHECK(predicted && predicted->gradient);
    if (!predicted || !predicted->gradient) continue;
    const auto g = exact(x);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) largest = std::max(largest, std::abs((*predicted->gradient)[a][b] - g[a][b]));
  }
  return largest;
}
} // namespace

int ImageMatchConstraintsTest(int, char*[])
{
  return testing::runTest("ImageMatchConstraintsTest", [] {
    const double side = 40.0;
    const double A[3][3] = {{0.02, -0.01, 0.3}, {0.015, -0.05, 0.01}, {-0.2, 0.005, 0.04}};
    const double b[3] = {0.3, -0.2, 1.1};
    auto linear = [&](const double* x) {
      std::array<double, 3> u{};
      for (int r = 0; r < 3; ++r) u[std::size_t(r)] = b[r] + A[r][0] * x[0] + A[r][1] * x[1] + A[r][2] * x[2];
      return u;
    };
    const FiniteElementJob job = testing::cubeMesh(6, side, 0.25);
    const vtkSmartPointer<vtkUnstructuredGrid> mesh = gridOf(job);
    const std::vector<double> nodal = nodalField(job, linear);
    const std::vector<double> gradients = nodalGradients(mesh, nodal);
    BS_CHECK(gradients.size() == 9 * job.nodeCount());
    double nodeError = 0;
    for (std::size_t v = 0; v < job.nodeCount(); ++v)
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) nodeError = std::max(nodeError, std::abs(gradients[9 * v + std::size_t(3 * r + c)] - A[r][c]));
    const MeshPointLocator locator(mesh);
    double displacementError = 0;
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> anywhere(0.5, side - 0.5);
    for (int n = 0; n < 200; ++n) {
      const double x[3] = {anywhere(rng), anywhere(rng), anywhere(rng)};
      const auto predicted = locator.interpolateWithGradient(nodal, gradients, testing::point(x[0], x[1], x[2]));
      BS_CHECK(predicted.has_value());
      if (!predicted) continue;
      const auto u = linear(x);
      for (int a = 0; a < 3; ++a) displacementError = std::max(displacementError, std::abs(predicted->displacement[std::size_t(a)] - u[std::size_t(a)]));
    }
    const double linearGradientError =
      largestGradientError(locator, nodal, gradients, side, [&](const double*) {
        std::array<std::array<double, 3>, 3> g{};
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) g[std::size_t(r)][std::size_t(c)] = A[r][c];
        return g;
      });
    std::cout << "linear field: node gradients within " << nodeError << ", interpolated displacement within " << displacementError
              << " mm, gradient within " << linearGradientError << "\n";
    BS_CHECK_MSG(nodeError < 1e-10, nodeError);
    // Not to rounding: of the tetrahedra that hold a point the locator takes the lowest-numbered
    // (the same every run), and VTK's tetrahedron holds points up to 1e-3 outside it in parametric
    // terms; its weights are then clamped, as for a point a few micrometres inside.
    BS_CHECK_MSG(displacementError < 1e-3, displacementError);
    BS_CHECK_MSG(linearGradientError < 1e-10, linearGradientError);

    // A quadratic field: the recovered gradient approaches the analytic one as the mesh refines.
    auto quadratic = [](const double* x) { return std::array<double, 3>{0.01 * x[1] * x[1], 0.02 * x[0] * x[2], 0.0}; };
    auto quadraticGradient = [](const double* x) {
      return std::array<std::array<double, 3>, 3>{{{0, 0.02 * x[1], 0}, {0.02 * x[2], 0, 0.02 * x[0]}, {0, 0, 0}}};
    };
    std::vector<double> errors;
    for (int n : {4, 8}) {
      const FiniteElementJob refined = testing::cubeMesh(n, side, 0.2);
      const vtkSmartPointer<vtkUnstructuredGrid> refinedMesh = gridOf(refined);
      const std::vector<double> field = nodalField(refined, quadratic);
      const MeshPointLocator refinedLocator(refinedMesh);
      errors.push_back(largestGradientError(refinedLocator, field, nodalGradients(refinedMesh, field), side, quadraticGradient));
    }
    std::cout << "quadratic field: gradient within " << errors[0] << " (10 mm elements), " << errors[1] << " (5 mm)\n";
    BS_CHECK_MSG(errors[1] < 0.8 * errors[0] && errors[1] < 0.05, errors[0] << " -> " << errors[1]); // of gradients up to 0.8

    BS_CHECK(!locator.interpolateWithGradient(nodal, gradients, testing::point(-5, 20, 20)).has_value());
    BS_CHECK_THROWS(locator.interpolateWithGradient(nodal, std::vector<double>(gradients.size() - 9), testing::point(20, 20, 20)),
                    std::invalid_argument, "nine gradient values");
    BS_CHECK_THROWS(nodalGradients(mesh, std::vector<double>(nodal.size() - 3)), std::invalid_argument, "three values per node");
    vtkSmartPointer<vtkUnstructuredGrid> withTriangle = gridOf(job);
    const vtkIdType triangle[3] = {0, 1, 2};
    withTriangle->InsertNextCell(VTK_TRIANGLE, 3, triangle);
    BS_CHECK_THROWS(nodalGradients(withTriangle, nodal), std::invalid_argument, "not a linear tetrahedron");

    // The configuration's block matching reaches the matching: the deformed windows and the
    // images' smoothing as configured, a resected tumour's label excluded.
    Configuration configuration;
    configuration.blockMatching.smoothingMm = 1.5;
    configuration.blockMatching.deformedWindows = false;
    const BlockMatchingParameters forwarded = blockMatchingParametersFrom(configuration, true);
    BS_CHECK_NEAR(forwarded.smoothingMm, 1.5, 0);
    BS_CHECK(!forwarded.deformedWindows);
    BS_CHECK(forwarded.excludedLabels == std::vector<int>{4});
    const BlockMatchingParameters byDefault = blockMatchingParametersFrom(Configuration{}, false);
    BS_CHECK_NEAR(byDefault.smoothingMm, Configuration{}.blockMatching.smoothingMm, 0);
    BS_CHECK(byDefault.deformedWindows && byDefault.excludedLabels.empty());
  });
}
