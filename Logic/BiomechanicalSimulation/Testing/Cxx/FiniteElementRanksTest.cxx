// One, two and four ranks (oversubscribed on two cores) give the same answer to the solver's
// tolerance, with the work balanced by the partitioner; the same job on the same ranks twice, the
// same partition and the same displacements (to the last bit on two ranks).
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
    for (std::size_t run = 1; run < 3; ++run) { // 2 and 4 ranks again
      const FiniteElementResult again = solveWithWorker(job, testing::workerOptions(results[run].ranks));
      BS_CHECK(again.partitioner == results[run].partitioner && again.tetrahedraPerRank == results[run].tetrahedraPerRank);
      BS_CHECK_MSG(again.iterations == results[run].iterations, again.iterations << " against " << results[run].iterations);
      // Bit for bit on two ranks (the default); on more, the assembly adds each rank's contributions
      // to another rank's rows in the order they arrive, so only to the rounding of those sums.
      double difference = 0;
      for (std::size_t i = 0; i < again.displacements.size(); ++i) {
        difference = std::max(difference, std::abs(again.displacements[i] - results[run].displacements[i]));
      }
      std::cout << results[run].ranks << " ranks again: largest difference " << difference << " mm\n";
      if (results[run].ranks == 2) BS_CHECK_MSG(again.displacements == results[run].displacements, difference);
      BS_CHECK_MSG(difference < 1e-9, difference);
    }
  });
}
