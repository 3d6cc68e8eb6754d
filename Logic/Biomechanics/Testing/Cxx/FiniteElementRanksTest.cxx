// One, two and four ranks (oversubscribed on two cores) give the same answer to the solver's
// tolerance, with the work balanced by the partitioner.
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"

#include <iostream>

int FiniteElementRanksTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementRanksTest", [] {
    using namespace brainshift;
    const double side = 40.0;
    const testing::Field sag = [side](const double* p) {
      const double x = p[0] / side, y = p[1] / side, z = p[2] / side;
      return std::array<double, 3>{0.0, 0.0, -3.0 * std::sin(M_PI * x) * std::sin(M_PI * y) * z};
    };
    FiniteElementJob job = testing::cubeMesh(10, side, 0.2);
    testing::imposeOnBoundary(job, side, sag);
    job.solverOptions = "-ksp_rtol 1e-10";
    std::vector<FiniteElementResult> results;
    for (int ranks : {1, 2, 4}) {
      results.push_back(solveWithWorker(job, testing::workerOptions(ranks)));
      const FiniteElementResult& r = results.back();
      std::cout << ranks << " ranks: " << r.iterations << " iterations, partitioner " << r.partitioner << ", tetrahedra per rank";
      for (auto t : r.tetrahedraPerRank) std::cout << ' ' << t;
      std::cout << ", assembly " << r.assemblySeconds << " s, setup " << r.setupSeconds << " s, solve " << r.solveSeconds << " s\n";
      BS_CHECK(r.ranks == ranks);
      BS_CHECK(r.tetrahedraPerRank.size() == std::size_t(ranks));
      // Balanced: no rank assembles more than 1.5 times its share.
      const double share = double(job.tetrahedronCount()) / ranks;
      for (auto t : r.tetrahedraPerRank) BS_CHECK_MSG(double(t) < 1.5 * share, t << " of " << job.tetrahedronCount());
    }
    double worst = 0;
    for (std::size_t r = 1; r < results.size(); ++r) {
      for (std::size_t i = 0; i < results[0].displacements.size(); ++i) {
        worst = std::max(worst, std::abs(results[r].displacements[i] - results[0].displacements[i]));
      }
    }
    std::cout << "largest difference between rank counts: " << worst << " mm\n";
    BS_CHECK_MSG(worst < 1e-6, worst);
  });
}
