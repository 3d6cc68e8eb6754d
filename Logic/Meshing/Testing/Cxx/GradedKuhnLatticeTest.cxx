// The graded Kuhn lattice: conforming (no node inside any element's edge: none hangs), every
// element one of Maubach's shapes (positive volume, dihedral angles >= 45 degrees), the elements
// tile the box exactly, fine where the size field asks and coarse where it lets.
#include "BrainShiftTestingSupport.h"
#include "GradedKuhnLattice.h"
#include "TetrahedronGeometry.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <set>

namespace {
using namespace brainshift;
using namespace brainshift::tetrahedron_geometry;

double minimumDihedralDegrees(const Vec p[4])
{
  static const int edges[6][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}, {1, 2, 0, 3}, {1, 3, 0, 2}, {2, 3, 0, 1}};
  double smallest = 180;
  for (const auto& e : edges) {
    const Vec axis = sub(p[e[1]], p[e[0]]);
    const Vec n1 = cross(axis, sub(p[e[2]], p[e[0]])), n2 = cross(axis, sub(p[e[3]], p[e[0]]));
    smallest = std::min(smallest, std::acos(std::clamp(dot(n1, n2) / (norm(n1) * norm(n2)), -1.0, 1.0)) * 180.0 / M_PI);
  }
  return smallest;
}

struct LatticeCheck {
  std::size_t hanging = 0;
  double volume = 0, minimumDihedral = 180;
  std::map<int, std::size_t> byDepth;
};

LatticeCheck check(const KuhnLattice& lattice)
{
  LatticeCheck c;
  std::set<std::array<int, 3>> nodes(lattice.nodes.begin(), lattice.nodes.end());
  BS_CHECK(nodes.size() == lattice.nodes.size()); // no duplicate nodes
  static const int edges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  for (std::size_t t = 0; t < lattice.tetrahedra.size(); ++t) {
    Vec p[4];
    for (int v = 0; v < 4; ++v) {
      const auto& q = lattice.nodes[std::size_t(lattice.tetrahedra[t][std::size_t(v)])];
      p[v] = {double(q[0]), double(q[1]), double(q[2])};
    }
    c.volume += std::abs(signedVolume(p));
    BS_CHECK(std::abs(signedVolume(p)) > 0);
    c.minimumDihedral = std::min(c.minimumDihedral, minimumDihedralDegrees(p));
    c.byDepth[lattice.depth[t]] += 1;
    // A node anywhere inside an edge hangs; bisection puts nodes at midpoints, so the edge's
    // lattice points are enough to look at.
    for (const auto& e : edges) {
      const auto& a = lattice.nodes[std::size_t(lattice.tetrahedra[t][std::size_t(e[0])])];
      const auto& b = lattice.nodes[std::size_t(lattice.tetrahedra[t][std::size_t(e[1])])];
      int steps = 0;
      for (int d = 0; d < 3; ++d) steps = std::max(steps, std::abs(b[std::size_t(d)] - a[std::size_t(d)]));
      for (int s = 1; s < steps; ++s) {
        std::array<int, 3> q{};
        bool onLattice = true;
        for (int d = 0; d < 3; ++d) {
          const int num = a[std::size_t(d)] * (steps - s) + b[std::size_t(d)] * s;
          onLattice = onLattice && num % steps == 0;
          q[std::size_t(d)] = num / steps;
        }
        if (onLattice && nodes.count(q)) ++c.hanging;
      }
    }
  }
  return c;
}
} // namespace

int GradedKuhnLatticeTest(int, char*[])
{
  return brainshift::testing::runTest("GradedKuhnLatticeTest", [] {
    const std::array<int, 3> cells{24, 20, 16};
    // Uniform: 6 tetrahedra per cell, every one a Kuhn tetrahedron (dihedral 45 to 90 degrees).
    const KuhnLattice uniform = buildGradedKuhnLattice(cells, 0, [](const auto&, double) { return true; });
    BS_CHECK(uniform.tetrahedra.size() == std::size_t(6 * 24 * 20 * 16));
    BS_CHECK(uniform.nodes.size() == std::size_t(25 * 21 * 17));
    const LatticeCheck u = check(uniform);
    BS_CHECK(u.hanging == 0);
    BS_CHECK_NEAR(u.volume, 24.0 * 20 * 16, 1e-6);
    BS_CHECK_NEAR(u.minimumDihedral, 45.0, 1e-9);

    // Refined everywhere from 4-cell cubes: the same tiling, all at the finest depth.
    const KuhnLattice everywhere = buildGradedKuhnLattice(cells, 2, [](const auto&, double) { return true; });
    const LatticeCheck e = check(everywhere);
    BS_CHECK(e.hanging == 0);
    BS_CHECK(everywhere.tetrahedra.size() == uniform.tetrahedra.size());
    BS_CHECK(everywhere.nodes.size() == uniform.nodes.size());
    BS_CHECK((e.byDepth.size() == 1 && e.byDepth.begin()->first == 6));

    // Graded: fine within 3 cells of the plane x = 2, coarser with the distance. The closure
    // that keeps it conforming spreads the refinement, but the far side stays coarse.
    auto nearPlane = [](const std::array<double, 3>& centroid, double cubeEdge) {
      return cubeEdge > 1 + std::max(0.0, std::abs(centroid[0] - 2.0) - cubeEdge - 3.0);
    };
    const KuhnLattice graded = buildGradedKuhnLattice(cells, 2, nearPlane);
    const LatticeCheck g = check(graded);
    std::cout << "graded: " << graded.nodes.size() << " nodes, " << graded.tetrahedra.size() << " tetrahedra (uniform "
              << uniform.tetrahedra.size() << "); by depth:";
    for (const auto& [depth, count] : g.byDepth) std::cout << ' ' << depth << ':' << count;
    std::cout << "; minimum dihedral " << g.minimumDihedral << " degrees\n";
    BS_CHECK_MSG(g.hanging == 0, g.hanging << " hanging nodes");
    BS_CHECK_NEAR(g.volume, 24.0 * 20 * 16, 1e-6);
    BS_CHECK_MSG(g.minimumDihedral >= 45.0 - 1e-9, g.minimumDihedral);
    BS_CHECK(g.byDepth.count(0) == 1 && g.byDepth.count(6) == 1); // both the coarsest and the finest
    BS_CHECK(graded.tetrahedra.size() < uniform.tetrahedra.size() / 2);
    for (std::size_t t = 0; t < graded.tetrahedra.size(); ++t) { // near the plane, only the finest
      double x = 0;
      for (int v : graded.tetrahedra[t]) x += 0.25 * graded.nodes[std::size_t(v)][0];
      if (std::abs(x - 2.0) < 3.0) BS_CHECK_MSG(graded.depth[t] == 6, "depth " << int(graded.depth[t]) << " at x " << x);
    }

    // Deterministic.
    const KuhnLattice again = buildGradedKuhnLattice(cells, 2, nearPlane);
    BS_CHECK(again.tetrahedra == graded.tetrahedra && again.nodes == graded.nodes);

    // A box that is not a whole number of coarse cubes is covered up to the next whole cube.
    const KuhnLattice odd = buildGradedKuhnLattice({5, 3, 2}, 2, [](const auto&, double) { return false; });
    BS_CHECK(odd.tetrahedra.size() == std::size_t(6 * 2 * 1 * 1));
    BS_CHECK_THROWS(buildGradedKuhnLattice({0, 3, 2}, 1, nearPlane), std::invalid_argument, "empty box");
  });
}
