#include "BoundaryNodeSnapping.h"
#include "TetrahedronGeometry.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

namespace brainshift {

namespace {
using namespace tetrahedron_geometry;

/// Positive volume and every dihedral angle within [theta, 180 - theta] (|cos| <= cos theta).
bool wellShaped(const Vec p[4], double cosineBound)
{
  if (!(dot(sub(p[1], p[0]), cross(sub(p[2], p[0]), sub(p[3], p[0]))) > 0)) return false;
  static const int edges[6][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}, {1, 2, 0, 3}, {1, 3, 0, 2}, {2, 3, 0, 1}};
  for (const auto& e : edges) {
    const Vec& a = p[e[0]];
    const Vec axis = sub(p[e[1]], a);
    const Vec n1 = cross(axis, sub(p[e[2]], a)), n2 = cross(axis, sub(p[e[3]], a));
    const double n = std::sqrt(dot(n1, n1) * dot(n2, n2));
    if (!(n > 0) || std::abs(dot(n1, n2)) > cosineBound * n) return false;
  }
  return true;
}

/// Each region's (tissue, or "outside") indicator on a box of voxels around the mesh, sampled
/// trilinearly at physical points: two regions' difference is zero on the voxel faces between them.
class RegionIndicators {
public:
  RegionIndicators(const LabelImage& image, const std::vector<int>& tissues, const std::vector<Vec>& points)
    : regions_(tissues.size() + 1)
  {
    const auto size = image.GetLargestPossibleRegion().GetSize();
    const auto& m = image.GetDirection();
    const auto& s = image.GetSpacing();
    // physical = origin + D S index; the inverse is S^-1 D^T (D orthonormal).
    for (int r = 0; r < 3; ++r) {
      origin_[r] = image.GetOrigin()[unsigned(r)];
      for (int c = 0; c < 3; ++c) toIndex_[r][c] = m[unsigned(c)][unsigned(r)] / s[unsigned(r)];
    }
    long lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    bool first = true;
    for (const Vec& p : points) {
      const Vec c = index(p);
      for (int d = 0; d < 3; ++d) {
        const long f = long(std::floor(c[d])), u = long(std::ceil(c[d]));
        lo[d] = first ? f : std::min(lo[d], f);
        hi[d] = first ? u : std::max(hi[d], u);
      }
      first = false;
    }
    for (int d = 0; d < 3; ++d) {
      lo_[d] = lo[d] - 3;
      dims_[d] = hi[d] + 3 - lo_[d] + 1;
    }
    const std::size_t n = std::size_t(dims_[0] * dims_[1] * dims_[2]);
    std::vector<std::uint8_t> region(n);
    const LabelPixel* voxels = image.GetBufferPointer();
    std::vector<int> regionOfLabel(65536, int(tissues.size()));
    for (std::size_t t = 0; t < tissues.size(); ++t) regionOfLabel[std::size_t(tissues[t])] = int(t);
    for (long k = 0; k < dims_[2]; ++k) {
      for (long j = 0; j < dims_[1]; ++j) {
        for (long i = 0; i < dims_[0]; ++i) {
          const long g[3] = {i + lo_[0], j + lo_[1], k + lo_[2]};
          int r = int(tissues.size());
          if (g[0] >= 0 && g[1] >= 0 && g[2] >= 0 && g[0] < long(size[0]) && g[1] < long(size[1]) && g[2] < long(size[2])) {
            r = regionOfLabel[voxels[std::size_t(g[0]) + size[0] * (std::size_t(g[1]) + size[1] * std::size_t(g[2]))]];
          }
          region[std::size_t(i + dims_[0] * (j + dims_[1] * k))] = std::uint8_t(r);
        }
      }
    }
    fields_.resize(regions_);
    for (std::size_t r = 0; r < regions_; ++r) {
      std::vector<float>& f = fields_[r];
      f.resize(n);
      for (std::size_t v = 0; v < n; ++v) f[v] = region[v] == r ? 1.0f : 0.0f;
    }
  }

  Vec index(const Vec& p) const
  {
    const Vec d = sub(p, origin_);
    return {dot(toIndex_[0], d), dot(toIndex_[1], d), dot(toIndex_[2], d)};
  }

  /// Region a's indicator minus region b's at a physical point.
  double difference(std::size_t a, std::size_t b, const Vec& p) const
  {
    const Vec c = index(p);
    double base[3], w[3];
    long i0[3];
    for (int d = 0; d < 3; ++d) {
      base[d] = c[d] - double(lo_[d]);
      i0[d] = long(std::floor(base[d]));
      w[d] = base[d] - double(i0[d]);
      if (i0[d] < 0 || i0[d] + 1 >= dims_[d]) { // beyond the box: outside
        const std::size_t outside = regions_ - 1;
        return (a == outside ? 1.0 : 0.0) - (b == outside ? 1.0 : 0.0);
      }
    }
    double value = 0;
    for (int corner = 0; corner < 8; ++corner) {
      const long di = corner & 1, dj = (corner >> 1) & 1, dk = (corner >> 2) & 1;
      const double weight = (di ? w[0] : 1 - w[0]) * (dj ? w[1] : 1 - w[1]) * (dk ? w[2] : 1 - w[2]);
      const std::size_t v = std::size_t((i0[0] + di) + dims_[0] * ((i0[1] + dj) + dims_[1] * (i0[2] + dk)));
      value += weight * (double(fields_[a][v]) - double(fields_[b][v]));
    }
    return value;
  }

private:
  std::size_t regions_;
  Vec origin_{};
  Vec toIndex_[3];
  long lo_[3]{}, dims_[3]{};
  std::vector<std::vector<float>> fields_;
};
/// The region (index into the tissues, or "outside" = the tissue count) of each tetrahedron, and
/// the regions each node touches as bits: those of its tetrahedra, and "outside" on the outer
/// boundary (faces of one tetrahedron only).
struct MeshRegions {
  std::size_t outside = 0;
  std::vector<std::size_t> ofTetrahedron;
  std::vector<std::uint32_t> ofNode;
};

void markOuterBoundaryNodes(const TetrahedralMeshArrays& mesh, MeshRegions& regions)
{
  std::vector<std::array<long long, 3>> faces;
  faces.reserve(4 * mesh.tetrahedra.size());
  for (const auto& tet : mesh.tetrahedra) {
    for (int skip = 0; skip < 4; ++skip) {
      std::array<long long, 3> f;
      for (int v = 0, n = 0; v < 4; ++v) {
        if (v != skip) f[std::size_t(n++)] = tet[std::size_t(v)];
      }
      std::sort(f.begin(), f.end());
      faces.push_back(f);
    }
  }
  std::sort(faces.begin(), faces.end());
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i;
    while (j < faces.size() && faces[j] == faces[i]) ++j;
    if (j - i == 1) {
      for (long long v : faces[i]) regions.ofNode[std::size_t(v)] |= 1u << regions.outside;
    }
    i = j;
  }
}

MeshRegions meshRegionsOf(const TetrahedralMeshArrays& mesh, const std::vector<int>& tissues)
{
  MeshRegions regions;
  regions.outside = tissues.size();
  regions.ofNode.assign(mesh.points.size(), 0);
  auto regionOf = [&](int label) {
    const auto at = std::find(tissues.begin(), tissues.end(), label);
    return at == tissues.end() ? regions.outside : std::size_t(at - tissues.begin());
  };
  regions.ofTetrahedron.resize(mesh.tetrahedra.size());
  for (std::size_t t = 0; t < mesh.tetrahedra.size(); ++t) {
    regions.ofTetrahedron[t] = regionOf(mesh.labels[t]);
    for (long long v : mesh.tetrahedra[t]) regions.ofNode[std::size_t(v)] |= 1u << regions.ofTetrahedron[t];
  }
  markOuterBoundaryNodes(mesh, regions);
  return regions;
}

/// The tetrahedra incident to each node (compressed rows: node v's are tetrahedra[begin[v] .. begin[v + 1])).
struct NodeStars {
  std::vector<std::size_t> begin, tetrahedra;
};

NodeStars nodeStarsOf(const TetrahedralMeshArrays& mesh)
{
  const std::size_t nodeCount = mesh.points.size();
  NodeStars stars;
  stars.begin.assign(nodeCount + 1, 0);
  for (const auto& tet : mesh.tetrahedra) {
    for (long long v : tet) stars.begin[std::size_t(v) + 1] += 1;
  }
  for (std::size_t v = 0; v < nodeCount; ++v) stars.begin[v + 1] += stars.begin[v];
  stars.tetrahedra.resize(stars.begin[nodeCount]);
  std::vector<std::size_t> fill(stars.begin.begin(), stars.begin.end() - 1);
  for (std::size_t t = 0; t < mesh.tetrahedra.size(); ++t) {
    for (long long v : mesh.tetrahedra[t]) stars.tetrahedra[fill[std::size_t(v)]++] = t;
  }
  return stars;
}

/// What the search for a node's interface crossing reads.
struct CrossingSearch {
  const TetrahedralMeshArrays& mesh;
  const MeshRegions& regions;
  const NodeStars& stars;
  const RegionIndicators& fields;
  double sampleMm;
  const SnappingParameters& parameters;
};

/// The node's neighbours (the other corners of its tetrahedra), sorted, once each.
std::vector<long long> neighboursOf(std::size_t v, const CrossingSearch& search)
{
  std::vector<long long> neighbours;
  for (std::size_t s = search.stars.begin[v]; s < search.stars.begin[v + 1]; ++s) {
    for (long long w : search.mesh.tetrahedra[search.stars.tetrahedra[s]]) {
      if (std::size_t(w) != v) neighbours.push_back(w);
    }
  }
  std::sort(neighbours.begin(), neighbours.end());
  neighbours.erase(std::unique(neighbours.begin(), neighbours.end()), neighbours.end());
  return neighbours;
}

/// Per region, the mean centroid of the node's incident tetrahedra in it ("outside": the mirror
/// image of all of them): a node inside A moves towards B's tetrahedra, never across A's.
std::vector<Vec> regionCentresAround(std::size_t v, const CrossingSearch& search)
{
  const std::size_t outside = search.regions.outside;
  const Vec x0 = search.mesh.points[v];
  std::vector<Vec> regionCentre(outside + 1, Vec{0, 0, 0});
  std::vector<double> regionWeight(outside + 1, 0);
  Vec allCentre{0, 0, 0};
  for (std::size_t s = search.stars.begin[v]; s < search.stars.begin[v + 1]; ++s) {
    const auto& tet = search.mesh.tetrahedra[search.stars.tetrahedra[s]];
    Vec c{0, 0, 0};
    for (long long w : tet) {
      for (int d = 0; d < 3; ++d) c[std::size_t(d)] += 0.25 * search.mesh.points[std::size_t(w)][std::size_t(d)];
    }
    const std::size_t r = search.regions.ofTetrahedron[search.stars.tetrahedra[s]];
    for (int d = 0; d < 3; ++d) {
      regionCentre[r][std::size_t(d)] += c[std::size_t(d)];
      allCentre[std::size_t(d)] += c[std::size_t(d)];
    }
    regionWeight[r] += 1;
  }
  const double starSize = double(search.stars.begin[v + 1] - search.stars.begin[v]);
  for (std::size_t r = 0; r <= outside; ++r) {
    for (int d = 0; d < 3; ++d) {
      regionCentre[r][std::size_t(d)] = r == outside ? 2 * x0[std::size_t(d)] - allCentre[std::size_t(d)] / starSize
                                                    : regionCentre[r][std::size_t(d)] / std::max(1.0, regionWeight[r]);
    }
  }
  return regionCentre;
}

/// The nearest crossing found so far of a node's interfaces, at `distance` from it.
struct Crossing {
  double distance = std::numeric_limits<double>::infinity();
  Vec point;
};

/// Along `edge` from x0 (up to the search fraction of it), the first sample where the difference of
/// regions a and b reaches zero (from g0's side): the interpolated crossing, if nearer than `best`.
void searchAlongEdge(std::size_t a, std::size_t b, const Vec& x0, double g0, const Vec& edge, const CrossingSearch& search,
                     Crossing& best)
{
  const SnappingParameters& parameters = search.parameters;
  const double reach = parameters.searchFraction * std::sqrt(dot(edge, edge));
  if (reach >= best.distance) return;
  const int samples = std::max(2, int(std::ceil(reach / search.sampleMm)));
  double previous = g0;
  for (int i = 1; i <= samples; ++i) {
    const double t = parameters.searchFraction * double(i) / samples;
    const Vec x{x0[0] + t * edge[0], x0[1] + t * edge[1], x0[2] + t * edge[2]};
    const double g = search.fields.difference(a, b, x);
    if (g0 > 0 ? g <= 0 : g >= 0) { // reaching zero counts, from either side
      const double t0 = parameters.searchFraction * double(i - 1) / samples;
      const double crossing = t0 + (t - t0) * previous / (previous - g); // previous != g: signs differ
      const double distance = crossing * std::sqrt(dot(edge, edge));
      if (distance < best.distance) {
        best.distance = distance;
        best.point = {x0[0] + crossing * edge[0], x0[1] + crossing * edge[1], x0[2] + crossing * edge[2]};
      }
      return;
    }
    previous = g;
  }
}

/// The target of an interface node: the nearest interface crossing along its incident edges (both
/// ways, towards the other region's tetrahedra), from its lattice position; infinite distance if none.
Crossing nearestInterfaceCrossing(std::size_t v, const CrossingSearch& search)
{
  const Vec x0 = search.mesh.points[v];
  std::vector<std::size_t> regions;
  for (std::size_t r = 0; r <= search.regions.outside; ++r) {
    if (search.regions.ofNode[v] & (1u << r)) regions.push_back(r);
  }
  const std::vector<long long> neighbours = neighboursOf(v, search);
  const std::vector<Vec> regionCentre = regionCentresAround(v, search);
  Crossing best;
  best.point = x0;
  for (std::size_t a = 0; a < regions.size(); ++a) {
    for (std::size_t b = a + 1; b < regions.size(); ++b) {
      const double g0 = search.fields.difference(regions[a], regions[b], x0);
      if (g0 == 0) {
        best.distance = 0;
        best.point = x0;
        continue;
      }
      // Inside A (g0 > 0) the way is towards B's tetrahedra, inside B towards A's.
      const Vec towards = g0 > 0 ? sub(regionCentre[regions[b]], regionCentre[regions[a]])
                                 : sub(regionCentre[regions[a]], regionCentre[regions[b]]);
      for (long long w : neighbours) {
        for (double sign : {1.0, -1.0}) {
          Vec edge = sub(search.mesh.points[std::size_t(w)], x0);
          for (double& e : edge) e *= sign;
          if (dot(edge, towards) <= 0) continue;
          searchAlongEdge(regions[a], regions[b], x0, g0, edge, search, best);
        }
      }
    }
  }
  return best;
}

/// Gauss-Seidel moves of the interface nodes towards their targets, each guarded by the quality of
/// the node's star (halving the step until it is well shaped); whether each node arrived.
std::vector<bool> moveTowardsTargets(TetrahedralMeshArrays& mesh, const NodeStars& stars, const std::vector<std::size_t>& interfaceNodes,
                                     const std::vector<Crossing>& target, const SnappingParameters& parameters)
{
  const double cosineBound = std::cos(parameters.minimumDihedralDegrees * M_PI / 180.0);
  auto starAccepts = [&](std::size_t v, const Vec& candidate) {
    for (std::size_t s = stars.begin[v]; s < stars.begin[v + 1]; ++s) {
      const auto& tet = mesh.tetrahedra[stars.tetrahedra[s]];
      Vec p[4];
      for (int c = 0; c < 4; ++c) p[c] = std::size_t(tet[std::size_t(c)]) == v ? candidate : mesh.points[std::size_t(tet[std::size_t(c)])];
      if (!wellShaped(p, cosineBound)) return false;
    }
    return true;
  };
  std::vector<bool> arrived(interfaceNodes.size(), false);
  for (int pass = 0; pass < parameters.passes; ++pass) {
    bool moved = false;
    for (std::size_t n = 0; n < interfaceNodes.size(); ++n) {
      if (!std::isfinite(target[n].distance) || arrived[n]) continue;
      const std::size_t v = interfaceNodes[n];
      const Vec step = sub(target[n].point, mesh.points[v]);
      double fraction = 1.0;
      for (int h = 0; h <= parameters.halvings; ++h, fraction *= 0.5) {
        const Vec candidate{mesh.points[v][0] + fraction * step[0], mesh.points[v][1] + fraction * step[1],
                            mesh.points[v][2] + fraction * step[2]};
        if (starAccepts(v, candidate)) {
          mesh.points[v] = candidate;
          moved = true;
          if (h == 0) arrived[n] = true;
          break;
        }
      }
    }
    if (!moved) break;
  }
  return arrived;
}
} // namespace

SnappingSummary snapInterfaceNodes(TetrahedralMeshArrays& mesh, const LabelImage& image, const std::vector<int>& tissues,
                                   const SnappingParameters& parameters)
{
  SnappingSummary summary;
  if (tissues.size() >= 31) throw std::invalid_argument("snapInterfaceNodes: at most 30 tissues");
  const MeshRegions regions = meshRegionsOf(mesh, tissues);
  const NodeStars stars = nodeStarsOf(mesh);
  std::vector<std::size_t> interfaceNodes;
  for (std::size_t v = 0; v < mesh.points.size(); ++v) {
    const std::uint32_t m = regions.ofNode[v];
    if (m & (m - 1)) interfaceNodes.push_back(v); // two regions or more
  }
  summary.interfaceNodes = interfaceNodes.size();
  if (interfaceNodes.empty()) return summary;

  const RegionIndicators fields(image, tissues, mesh.points);
  double finest = image.GetSpacing()[0];
  for (unsigned d = 1; d < 3; ++d) finest = std::min(finest, double(image.GetSpacing()[d]));
  const CrossingSearch search{mesh, regions, stars, fields, 0.25 * finest, parameters};

  // Targets: the nearest interface crossing along the incident edges, from the lattice positions
  // (all found before any node moves).
  std::vector<Crossing> target(interfaceNodes.size());
  for (std::size_t n = 0; n < interfaceNodes.size(); ++n) {
    target[n] = nearestInterfaceCrossing(interfaceNodes[n], search);
    if (!std::isfinite(target[n].distance)) ++summary.nodesWithoutCrossing;
  }
  const std::vector<bool> arrived = moveTowardsTargets(mesh, stars, interfaceNodes, target, parameters);
  for (std::size_t n = 0; n < interfaceNodes.size(); ++n) {
    if (!std::isfinite(target[n].distance)) continue;
    if (arrived[n]) {
      ++summary.nodesOnInterface;
    } else {
      ++summary.nodesPartlyMoved;
    }
  }
  return summary;
}

} // namespace brainshift
