// Convergence against an exact solution of linear elasticity without body force: u = grad(phi)
// with phi harmonic solves the Navier equations for any material. With it imposed on the
// boundary, the error of the linear tetrahedra falls as h^2. (phi is not a polynomial: on these
// lattices harmonic polynomial fields up to cubic displacements are reproduced exactly at the
// nodes, which would test nothing.)
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"

#include <iostream>

int FiniteElementConvergenceTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementConvergenceTest", [] {
    using namespace brainshift;
    const double side = 40.0;
    // phi = a L / k exp(k x) cos(k y) with x = position / L: u = a exp(k x) (cos k y, -sin k y, 0) mm.
    const testing::Field exact = [side](const double* p) {
      const double x = p[0] / side, y = p[1] / side, k = 2.0;
      return std::array<double, 3>{std::exp(k * x) * std::cos(k * y), -std::exp(k * x) * std::sin(k * y), 0.0};
    };
    std::vector<double> errors;
    for (int n : {8, 16, 32}) {
      FiniteElementJob job = testing::cubeMesh(n, side, 0.0);
      testing::imposeOnBoundary(job, side, exact);
      job.solverOptions = "-ksp_rtol 1e-12";
      const FiniteElementResult result = solveWithWorker(job, testing::workerOptions());
      // Root mean square nodal error over the interior.
      double sum = 0;
      std::size_t count = 0;
      for (std::size_t v = 0; v < job.nodeCount(); ++v) {
        const auto u = exact(&job.nodes[3 * v]);
        for (int d = 0; d < 3; ++d) sum += std::pow(result.displacements[3 * v + std::size_t(d)] - u[std::size_t(d)], 2);
        ++count;
      }
      errors.push_back(std::sqrt(sum / double(count)));
      std::cout << "h = " << side / n << " mm: RMS error " << errors.back() << " mm, " << result.iterations << " iterations\n";
    }
    // Second order, approached from below as the mesh leaves the pre-asymptotic range (measured:
    // 1.73 from 5 to 2.5 mm, 1.88 from 2.5 to 1.25 mm).
    std::vector<double> rates;
    for (std::size_t i = 1; i < errors.size(); ++i) {
      rates.push_back(std::log2(errors[i - 1] / errors[i]));
      std::cout << "observed order " << rates.back() << '\n';
      BS_CHECK_MSG(rates.back() > 1.6 && rates.back() < 2.3, rates.back());
    }
    BS_CHECK_MSG(rates.back() > 1.8, rates.back());
    BS_CHECK_MSG(errors.back() < 0.01, errors.back());
  });
}
