// Heterogeneous materials and near incompressibility: a bar of three layers (brain, a soft
// ventricle-like layer, a stiff tumour-like layer) compressed in uniaxial strain has an exact
// piecewise-linear solution: the strain of each layer is inversely proportional to its P-wave
// modulus E (1 - nu) / ((1 + nu)(1 - 2 nu)). Reproduced to solver precision, for nu up to 0.49;
// the iteration counts are reported.
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"

#include <iostream>

int FiniteElementHeterogeneousTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementHeterogeneousTest", [] {
    using namespace brainshift;
    const double side = 30.0;
    const int n = 9; // layers at x = 10 and 20 mm fall on cell faces
    for (double nu : {0.3, 0.45, 0.49}) {
      FiniteElementJob job = testing::cubeMesh(n, side, 0.0);
      job.materials = {{3e-3, nu}, {1e-4, nu}, {1e-2, nu}};
      for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
        double cx = 0;
        for (int k = 0; k < 4; ++k) cx += job.nodes[3 * std::size_t(job.tetrahedra[4 * t + std::size_t(k)])] / 4.0;
        job.materialOfTetrahedron[t] = cx < 10.0 ? 0 : cx < 20.0 ? 1 : 2;
      }
      auto pModulus = [&](int m) {
        const double E = job.materials[std::size_t(m)].youngsModulus;
        return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu));
      };
      // Total shortening 3 mm; equal stress in every layer: strain_i = s / M_i.
      const double compliance = 10.0 / pModulus(0) + 10.0 / pModulus(1) + 10.0 / pModulus(2);
      const double stress = -3.0 / compliance;
      const double e0 = stress / pModulus(0), e1 = stress / pModulus(1), e2 = stress / pModulus(2);
      const testing::Field exact = [=](const double* p) {
        const double x = p[0];
        const double ux = x < 10 ? e0 * x : x < 20 ? 10 * e0 + e1 * (x - 10) : 10 * e0 + 10 * e1 + e2 * (x - 20);
        return std::array<double, 3>{ux, 0.0, 0.0};
      };
      testing::imposeOnBoundary(job, side, exact);
      job.solverOptions = "-ksp_rtol 1e-12";
      const FiniteElementResult result = solveWithWorker(job, testing::workerOptions());
      const double error = testing::maximumNodalError(job, result, exact);
      std::cout << "nu " << nu << ": " << result.iterations << " iterations (" << result.solver << "), max error " << error << " mm\n";
      BS_CHECK_MSG(error < 1e-7, "nu " << nu << ": " << error);
    }
  });
}
