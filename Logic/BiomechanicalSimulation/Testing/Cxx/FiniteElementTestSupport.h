#pragma once
// Test meshes and exact solutions for the finite element worker.
#include "FiniteElementSolver.h"

#include <array>
#include <cmath>
#include <functional>
#include <random>

namespace brainshift::testing {

using Field = std::function<std::array<double, 3>(const double*)>;

/// A cube of `side` mm cut into n^3 cells of 6 tetrahedra (Kuhn), interior nodes jittered by up to
/// `jitter` of a cell (seeded) so the mesh is not a regular lattice; all tetrahedra positively
/// oriented. Material 0 everywhere.
inline FiniteElementJob cubeMesh(int n, double side, double jitter = 0.15, std::uint64_t seed = 7)
{
  FiniteElementJob job;
  const double h = side / n;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> offset(-jitter * h, jitter * h);
  auto id = [n](int i, int j, int k) { return std::int32_t(i + (n + 1) * (j + (n + 1) * k)); };
  for (int k = 0; k <= n; ++k) {
    for (int j = 0; j <= n; ++j) {
      for (int i = 0; i <= n; ++i) {
        const bool interior = i > 0 && j > 0 && k > 0 && i < n && j < n && k < n;
        job.nodes.push_back(i * h + (interior ? offset(rng) : 0.0));
        job.nodes.push_back(j * h + (interior ? offset(rng) : 0.0));
        job.nodes.push_back(k * h + (interior ? offset(rng) : 0.0));
      }
    }
  }
  // Kuhn: the six paths from corner 000 to 111, one axis at a time.
  const int paths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        for (const auto& path : paths) {
          int c[3] = {i, j, k};
          std::int32_t tet[4];
          tet[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            c[path[s]] += 1;
            tet[s + 1] = id(c[0], c[1], c[2]);
          }
          // Orientation: positive volume.
          const double* p[4];
          for (int v = 0; v < 4; ++v) p[v] = &job.nodes[3 * std::size_t(tet[v])];
          double a[3], b[3], d[3];
          for (int x = 0; x < 3; ++x) {
            a[x] = p[1][x] - p[0][x];
            b[x] = p[2][x] - p[0][x];
            d[x] = p[3][x] - p[0][x];
          }
          const double det = a[0] * (b[1] * d[2] - b[2] * d[1]) - a[1] * (b[0] * d[2] - b[2] * d[0]) + a[2] * (b[0] * d[1] - b[1] * d[0]);
          if (det < 0) std::swap(tet[2], tet[3]);
          job.tetrahedra.insert(job.tetrahedra.end(), tet, tet + 4);
          job.materialOfTetrahedron.push_back(0);
        }
      }
    }
  }
  job.materials = {{3e-3, 0.45}};
  return job;
}

/// Imposes `field` on the nodes of the cube's faces.
inline void imposeOnBoundary(FiniteElementJob& job, double side, const Field& field)
{
  for (std::size_t v = 0; v < job.nodeCount(); ++v) {
    const double* x = &job.nodes[3 * v];
    bool boundary = false;
    for (int d = 0; d < 3; ++d) boundary = boundary || std::abs(x[d]) < 1e-9 || std::abs(x[d] - side) < 1e-9;
    if (!boundary) continue;
    job.fixedNodes.push_back(std::int32_t(v));
    const auto u = field(x);
    job.fixedDisplacements.insert(job.fixedDisplacements.end(), u.begin(), u.end());
  }
}

/// The largest nodal difference between the result and `field`.
inline double maximumNodalError(const FiniteElementJob& job, const FiniteElementResult& result, const Field& field)
{
  double worst = 0;
  for (std::size_t v = 0; v < job.nodeCount(); ++v) {
    const auto u = field(&job.nodes[3 * v]);
    for (int d = 0; d < 3; ++d) worst = std::max(worst, std::abs(result.displacements[3 * v + std::size_t(d)] - u[std::size_t(d)]));
  }
  return worst;
}

inline FiniteElementRunOptions workerOptions(int ranks = 1)
{
  FiniteElementRunOptions options;
  options.worker = BRAINSHIFT_FE_WORKER;
  options.ranks = ranks;
  options.timeoutSeconds = 120;
  return options;
}

} // namespace brainshift::testing
