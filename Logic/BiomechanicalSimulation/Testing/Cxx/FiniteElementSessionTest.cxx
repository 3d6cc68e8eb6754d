// Prepared before surgery, solved during it: a session prepares once (partition, assembly,
// elimination, factorisation or multigrid setup) and answers new imposed values for the same boundary nodes; each
// answer equals a one-shot solve and reuses the one preparation (its speed is measured by
// Testing/Benchmarks/simulate, not here).
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"

#include "BrainShiftErrors.h"

#include <chrono>
#include <cstdlib>
#include <thread>
#include <iostream>
#include <unistd.h>

int FiniteElementSessionTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementSessionTest", [] {
    using namespace brainshift;
    const double side = 40.0;
    const testing::Field first = [side](const double* p) {
      return std::array<double, 3>{0.0, 0.0, -4.0 * std::sin(M_PI * p[0] / side) * std::sin(M_PI * p[1] / side) * p[2] / side};
    };
    const testing::Field second = [side](const double* p) {
      return std::array<double, 3>{1.5 * p[2] / side, -0.02 * p[0], -6.0 * std::sin(M_PI * p[0] / side) * p[2] / side};
    };
    FiniteElementJob job = testing::cubeMesh(16, side, 0.2);
    testing::imposeOnBoundary(job, side, first);
    job.solverOptions = "-ksp_rtol 1e-10";
    FiniteElementJob secondJob = job;
    secondJob.fixedDisplacements.clear();
    for (std::int32_t v : job.fixedNodes) {
      const auto u = second(&job.nodes[3 * std::size_t(v)]);
      secondJob.fixedDisplacements.insert(secondJob.fixedDisplacements.end(), u.begin(), u.end());
    }

    for (int ranks : {1, 2}) {
      FiniteElementSession session(job, testing::workerOptions(ranks));
      std::vector<FiniteElementResult> answers;
      for (const FiniteElementJob* values : {&job, &secondJob, &job}) {
        const auto start = std::chrono::steady_clock::now();
        const FiniteElementResult served = session.solve(values->fixedDisplacements);
        const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const FiniteElementResult once = solveWithWorker(*values, testing::workerOptions(ranks));
        double difference = 0;
        for (std::size_t i = 0; i < once.displacements.size(); ++i) {
          difference = std::max(difference, std::abs(served.displacements[i] - once.displacements[i]));
        }
        std::cout << ranks << " ranks: prepared in " << session.prepareSeconds() << " s (assembly " << served.assemblySeconds
                  << ", setup " << served.setupSeconds << "), solve " << served.solveSeconds << " s (" << wall
                  << " s as the caller sees it), " << served.iterations << " iterations, difference to one-shot " << difference
                  << " mm\n";
        BS_CHECK_MSG(difference < 1e-6, difference);
        BS_CHECK(served.convergedReason > 0);
        // The tuned default by measurement (Testing/Benchmarks/results/simulate): a served problem
        // of this size keeps a Cholesky factorisation (CHOLMOD is sequential, MUMPS on several
        // ranks), a one-shot solve takes CG with block Jacobi and incomplete Cholesky.
        BS_CHECK_MSG(served.solver == (ranks == 1 ? "cholesky+cholmod" : "cholesky+mumps"), served.solver);
        BS_CHECK_MSG(served.iterations == 1, served.iterations);
        BS_CHECK_MSG(once.solver == "cg+bjacobi/icc", once.solver);
        answers.push_back(served);
      }
      // One preparation for every solve: the same assembly and setup, the same answer to the same values.
      for (const FiniteElementResult& a : answers) {
        BS_CHECK(a.assemblySeconds == answers[0].assemblySeconds && a.setupSeconds == answers[0].setupSeconds);
      }
      double again = 0; // the same values again: the same answer (to rounding: MUMPS reorders its sums between solves)
      for (std::size_t i = 0; i < answers[0].displacements.size(); ++i) {
        again = std::max(again, std::abs(answers[2].displacements[i] - answers[0].displacements[i]));
      }
      std::cout << ranks << " ranks: the same values solved again differ by " << again << " mm\n";
      BS_CHECK_MSG(again < 1e-12, again);
      BS_CHECK(answers[2].iterations == answers[0].iterations);
      // A malformed request is refused and the session goes on.
      BS_CHECK_THROWS(session.solve({1.0, 2.0}), std::invalid_argument, "3 values per fixed node");
      BS_CHECK(session.solve(job.fixedDisplacements).convergedReason > 0);

      // Other fixed nodes on the same mesh (a later scan frees part of the surface): eliminated
      // anew in the same worker, the answer that of a fresh one-shot solve; then back again.
      FiniteElementJob fewer = secondJob;
      fewer.fixedNodes.clear();
      fewer.fixedDisplacements.clear();
      for (std::size_t f = 0; f < secondJob.fixedNodes.size(); ++f) {
        const double* p = &job.nodes[3 * std::size_t(secondJob.fixedNodes[f])];
        if (p[2] > 0.999 * side && p[0] < 0.5 * side) continue; // half of the top face left free
        fewer.fixedNodes.push_back(secondJob.fixedNodes[f]);
        fewer.fixedDisplacements.insert(fewer.fixedDisplacements.end(), &secondJob.fixedDisplacements[3 * f],
                                        &secondJob.fixedDisplacements[3 * f] + 3);
      }
      BS_CHECK(fewer.fixedNodes.size() < secondJob.fixedNodes.size());
      const FiniteElementResult refixed = session.solve(fewer.fixedNodes, fewer.fixedDisplacements);
      const FiniteElementResult fresh = solveWithWorker(fewer, testing::workerOptions(ranks));
      double refixDifference = 0;
      for (std::size_t i = 0; i < fresh.displacements.size(); ++i) {
        refixDifference = std::max(refixDifference, std::abs(refixed.displacements[i] - fresh.displacements[i]));
      }
      std::cout << ranks << " ranks: other fixed nodes (" << fewer.fixedNodes.size() << " of " << secondJob.fixedNodes.size()
                << "), set up again in " << refixed.setupSeconds << " s, difference to one-shot " << refixDifference << " mm\n";
      BS_CHECK_MSG(refixDifference < 1e-6, refixDifference);
      const FiniteElementResult back = session.solve(job.fixedNodes, job.fixedDisplacements);
      double backDifference = 0;
      for (std::size_t i = 0; i < back.displacements.size(); ++i) {
        backDifference = std::max(backDifference, std::abs(back.displacements[i] - answers[0].displacements[i]));
      }
      BS_CHECK_MSG(backDifference < 1e-9, backDifference);
      BS_CHECK_THROWS(session.solve({0, 0}, std::vector<double>(6, 0.0)), std::invalid_argument, "given twice");
      BS_CHECK_THROWS(session.solve({-1}, std::vector<double>(3, 0.0)), std::invalid_argument, "not a node");
    }

    // Options that choose the method replace the tuned default (CG + GAMG beneath them); others go over it.
    {
      FiniteElementJob chosen = job;
      chosen.solverOptions = "-pc_type gamg -ksp_rtol 1e-10";
      FiniteElementSession session(chosen, testing::workerOptions(1));
      const FiniteElementResult r = session.solve(job.fixedDisplacements);
      BS_CHECK_MSG(r.solver == "cg+gamg" && r.iterations > 1, r.solver << ", " << r.iterations);
      chosen.solverOptions = "-ksp_type gmres -pc_type bjacobi -sub_pc_type ilu -ksp_rtol 1e-10"; // ILU named: on the SPD matrix PETSc would take ICC
      const std::string paper = solveWithWorker(chosen, testing::workerOptions(1)).solver;
      BS_CHECK_MSG(paper == "gmres+bjacobi/ilu", paper); // the seed paper's solver
    }

    // A served worker that dies between scans is reported, and the caller survives (no SIGPIPE).
    // The kill names this session's own job file: other tests and stages serve workers too.
    FiniteElementRunOptions doomedOptions = testing::workerOptions(1);
    doomedOptions.workFolder = testing::temporaryFolder("FiniteElementSessionTest") / ("doomed-" + std::to_string(::getpid()));
    FiniteElementSession doomed(job, doomedOptions);
    const std::string kill = "pkill -KILL -f '[b]rainshift-fe-worker --serve " + (doomedOptions.workFolder / "").string() + "' >/dev/null 2>&1";
    BS_CHECK(std::system(kill.c_str()) == 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    BS_CHECK_THROWS(doomed.solve(job.fixedDisplacements), MethodError, "finite element worker");
  });
}
