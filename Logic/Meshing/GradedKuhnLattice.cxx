#include "GradedKuhnLattice.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace brainshift {

namespace {
/// The lattice under construction, with its node ids by fine-lattice point: a dense table, so a
/// midpoint is found without hashing.
class LatticeBuilder {
public:
  explicit LatticeBuilder(const std::array<int, 3>& gridPoints)
    : gridPoints_(gridPoints)
    , idAt_(std::size_t(gridPoints[0]) * std::size_t(gridPoints[1]) * std::size_t(gridPoints[2]), -1)
  {
  }

  KuhnLattice lattice;

  /// The node at a fine-lattice point, added if new.
  int node(const std::array<int, 3>& q)
  {
    int& id = idAt_[pointIndex(q)];
    if (id < 0) {
      id = int(lattice.nodes.size());
      lattice.nodes.push_back(q);
    }
    return id;
  }

  /// The midpoint of nodes a and b, if it is a fine-lattice point.
  bool midpointOf(int a, int b, std::array<int, 3>& m) const
  {
    const auto& p = lattice.nodes[std::size_t(a)];
    const auto& q = lattice.nodes[std::size_t(b)];
    for (int d = 0; d < 3; ++d) {
      const int s = p[std::size_t(d)] + q[std::size_t(d)];
      if (s % 2 != 0) return false;
      m[std::size_t(d)] = s / 2;
    }
    return true;
  }

  /// Whether a node lies at the midpoint of one of the tetrahedron's edges.
  bool hasHangingNode(const std::array<int, 4>& t) const
  {
    static const int edges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
    std::array<int, 3> m{};
    for (const auto& e : edges) {
      if (midpointOf(t[std::size_t(e[0])], t[std::size_t(e[1])], m) && idAt_[pointIndex(m)] >= 0) return true;
    }
    return false;
  }

private:
  std::size_t pointIndex(const std::array<int, 3>& q) const
  {
    return std::size_t(q[0]) + std::size_t(gridPoints_[0]) * (std::size_t(q[1]) + std::size_t(gridPoints_[1]) * std::size_t(q[2]));
  }

  std::array<int, 3> gridPoints_;
  std::vector<int> idAt_;
};

/// The coarse Kuhn tetrahedra: x0 the cube's corner, then one unit step along each axis in the
/// order of one of the six permutations; x0-x3 is the cube's diagonal, Maubach's first
/// refinement edge (tag 3).
void addCoarseKuhnTetrahedra(LatticeBuilder& builder, const std::array<int, 3>& coarseCells, int coarseEdge)
{
  static const int paths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < coarseCells[2]; ++k) {
    for (int j = 0; j < coarseCells[1]; ++j) {
      for (int i = 0; i < coarseCells[0]; ++i) {
        for (const auto& path : paths) {
          std::array<int, 3> q{i * coarseEdge, j * coarseEdge, k * coarseEdge};
          std::array<int, 4> t{};
          t[0] = builder.node(q);
          for (int s = 0; s < 3; ++s) {
            q[std::size_t(path[s])] += coarseEdge;
            t[std::size_t(s + 1)] = builder.node(q);
          }
          builder.lattice.tetrahedra.push_back(t);
          builder.lattice.depth.push_back(0);
        }
      }
    }
  }
}

/// Maubach's bisection of tetrahedron t: with tag k (3, 2, 1, 3, ... by depth) bisect x0-xk at z;
/// the children are (x0, .., x(k-1), z, x(k+1), ..), in t's place, and (x1, .., xk, z, x(k+1), ..),
/// appended. Their sizes are yet to be asked.
void bisect(LatticeBuilder& builder, std::size_t t, std::vector<unsigned char>& sizeAsked)
{
  KuhnLattice& lattice = builder.lattice;
  const int depth = lattice.depth[t];
  const std::array<int, 4> x = lattice.tetrahedra[t];
  const int k = 3 - depth % 3;
  std::array<int, 3> m{};
  builder.midpointOf(x[0], x[std::size_t(k)], m); // on the lattice: depth < finestDepth
  const int z = builder.node(m);
  std::array<int, 4> first = x, second = x;
  first[std::size_t(k)] = z;
  for (int s = 0; s < k; ++s) second[std::size_t(s)] = x[std::size_t(s + 1)];
  second[std::size_t(k)] = z;
  lattice.tetrahedra[t] = first;
  lattice.depth[t] = (unsigned char)(depth + 1);
  sizeAsked[t] = 0;
  lattice.tetrahedra.push_back(second);
  lattice.depth.push_back((unsigned char)(depth + 1));
  sizeAsked.push_back(0);
}

/// Whether tetrahedron t is to be bisected: it wants to be finer (asked once per tetrahedron), or
/// a node hangs on one of its edges.
bool needsBisection(const LatticeBuilder& builder, std::size_t t, int coarseEdge, std::vector<unsigned char>& sizeAsked,
                    const std::function<bool(const std::array<double, 3>&, double)>& wantsFiner)
{
  const KuhnLattice& lattice = builder.lattice;
  const int depth = lattice.depth[t];
  const std::array<int, 4> x = lattice.tetrahedra[t];
  bool split = false;
  if (!sizeAsked[t]) {
    sizeAsked[t] = 1;
    std::array<double, 3> centroid{};
    for (int v : x) {
      for (int d = 0; d < 3; ++d) centroid[std::size_t(d)] += 0.25 * lattice.nodes[std::size_t(v)][std::size_t(d)];
    }
    split = wantsFiner(centroid, coarseEdge * std::exp2(-depth / 3.0));
  }
  if (!split) split = builder.hasHangingNode(x);
  return split;
}
} // namespace

KuhnLattice buildGradedKuhnLattice(const std::array<int, 3>& fineCells, int levels,
                                   const std::function<bool(const std::array<double, 3>&, double)>& wantsFiner)
{
  if (levels < 0 || levels > 6) throw std::invalid_argument("graded Kuhn lattice: levels must be within 0 to 6");
  const int coarseEdge = 1 << levels;
  std::array<int, 3> coarseCells{}, gridPoints{};
  for (int d = 0; d < 3; ++d) {
    if (fineCells[std::size_t(d)] < 1) throw std::invalid_argument("graded Kuhn lattice: an empty box");
    coarseCells[std::size_t(d)] = (fineCells[std::size_t(d)] + coarseEdge - 1) / coarseEdge;
    gridPoints[std::size_t(d)] = coarseCells[std::size_t(d)] * coarseEdge + 1;
  }
  const std::size_t pointCount = std::size_t(gridPoints[0]) * std::size_t(gridPoints[1]) * std::size_t(gridPoints[2]);
  if (pointCount > (std::size_t(1) << 31)) {
    throw std::invalid_argument("graded Kuhn lattice: " + std::to_string(pointCount) + " lattice points are too many");
  }
  LatticeBuilder builder(gridPoints);
  addCoarseKuhnTetrahedra(builder, coarseCells, coarseEdge);
  if (levels == 0) return std::move(builder.lattice);

  const int finestDepth = 3 * levels;
  std::vector<unsigned char> sizeAsked(builder.lattice.tetrahedra.size(), 0);
  bool changed = true;
  while (changed) {
    changed = false;
    const std::size_t count = builder.lattice.tetrahedra.size();
    for (std::size_t t = 0; t < count; ++t) {
      if (builder.lattice.depth[t] >= finestDepth) continue; // its edges' midpoints are off the lattice: nothing can hang
      if (!needsBisection(builder, t, coarseEdge, sizeAsked, wantsFiner)) continue;
      bisect(builder, t, sizeAsked);
      changed = true;
    }
  }
  return std::move(builder.lattice);
}

} // namespace brainshift
