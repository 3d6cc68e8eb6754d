#include "LabelMapMesher.h"

#include "Configuration.h"
#include "TetrahedronGeometry.h"

#include "BoundaryNodeSnapping.h"
#include "CgalLabelMapMesher.h"
#include "GradedKuhnLattice.h"
#include "NumberText.h"

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkIdList.h>
#include <vtkIntArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>

#include <algorithm>
#include <cstring>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <array>
#include <cmath>
#include <sstream>
#include <unordered_map>

namespace brainshift {

namespace {
using namespace tetrahedron_geometry;

vtkSmartPointer<vtkUnstructuredGrid> toUnstructuredGrid(const TetrahedralMeshArrays& arrays)
{
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  points->SetNumberOfPoints(vtkIdType(arrays.points.size()));
  for (std::size_t v = 0; v < arrays.points.size(); ++v) points->SetPoint(vtkIdType(v), arrays.points[v].data());
  vtkNew<vtkCellArray> tetrahedra;
  vtkNew<vtkIntArray> labelArray;
  labelArray->SetName("Label");
  labelArray->SetNumberOfValues(vtkIdType(arrays.labels.size()));
  for (std::size_t t = 0; t < arrays.tetrahedra.size(); ++t) {
    const vtkIdType ids[4] = {vtkIdType(arrays.tetrahedra[t][0]), vtkIdType(arrays.tetrahedra[t][1]),
                              vtkIdType(arrays.tetrahedra[t][2]), vtkIdType(arrays.tetrahedra[t][3])};
    tetrahedra->InsertNextCell(4, ids);
    labelArray->SetValue(vtkIdType(t), arrays.labels[t]);
  }
  auto mesh = vtkSmartPointer<vtkUnstructuredGrid>::New();
  mesh->SetPoints(points);
  mesh->SetCells(VTK_TETRA, tetrahedra);
  mesh->GetCellData()->AddArray(labelArray);
  return mesh;
}


/// The six dihedral angles (degrees) of a tetrahedron.
std::array<double, 6> dihedralAngles(const Vec p[4])
{
  static const int edges[6][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}, {1, 2, 0, 3}, {1, 3, 0, 2}, {2, 3, 0, 1}};
  std::array<double, 6> angles{};
  for (int e = 0; e < 6; ++e) {
    const Vec& a = p[edges[e][0]];
    const Vec axis = sub(p[edges[e][1]], a);
    // Normals of the two faces meeting at the edge, each towards the opposite vertex's side.
    Vec n1 = cross(axis, sub(p[edges[e][2]], a)), n2 = cross(axis, sub(p[edges[e][3]], a));
    const double c = dot(n1, n2) / (norm(n1) * norm(n2));
    angles[std::size_t(e)] = std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / M_PI;
  }
  return angles;
}

/// 3 r_in / r_circ.
double radiusRatio(const Vec p[4])
{
  const double volume = std::abs(signedVolume(p));
  double area = 0;
  static const int faces[4][3] = {{0, 1, 2}, {0, 1, 3}, {0, 2, 3}, {1, 2, 3}};
  for (const auto& f : faces) area += 0.5 * norm(cross(sub(p[f[1]], p[f[0]]), sub(p[f[2]], p[f[0]])));
  const double inradius = 3.0 * volume / area;
  // Circumradius: |a^2 (b x c) + b^2 (c x a) + c^2 (a x b)| / (12 V).
  const Vec a = sub(p[1], p[0]), b = sub(p[2], p[0]), c = sub(p[3], p[0]);
  const Vec bc = cross(b, c), ca = cross(c, a), ab = cross(a, b);
  Vec s;
  for (int i = 0; i < 3; ++i) s[std::size_t(i)] = dot(a, a) * bc[std::size_t(i)] + dot(b, b) * ca[std::size_t(i)] + dot(c, c) * ab[std::size_t(i)];
  const double circumradius = norm(s) / (12.0 * volume);
  return volume > 0 ? 3.0 * inradius / circumradius : 0.0;
}
} // namespace

void MeshingParameters::validate(const LabelImage& image) const
{
  double finest = image.GetSpacing()[0];
  double extent = 0;
  for (unsigned i = 0; i < 3; ++i) {
    finest = std::min(finest, double(image.GetSpacing()[i]));
    extent = std::max(extent, image.GetSpacing()[i] * image.GetLargestPossibleRegion().GetSize()[i]);
  }
  if (!std::isfinite(resolutionMm) || resolutionMm < finest) {
    std::ostringstream m;
    m << "--mesh-resolution " << resolutionMm << " mm is finer than the label map's voxels (" << finest << " mm)";
    throw InputError(m.str());
  }
  if (resolutionMm > extent / 4.0) {
    std::ostringstream m;
    m << "--mesh-resolution " << resolutionMm << " mm is absurdly coarse for a label map " << extent << " mm across";
    throw InputError(m.str());
  }
  if (labels.empty()) throw InputError("meshing: no tissue labels to mesh");
  if (!std::isfinite(gradingRate) || gradingRate < 0 || gradingRate > 10) {
    std::ostringstream m;
    m << "mesh grading " << gradingRate << " is outside 0 (uniform) to 10 mm of element size per mm of distance";
    throw InputError(m.str());
  }
  if (coarseningLevels < 0 || coarseningLevels > 4) {
    throw InputError("mesh coarsening levels " + std::to_string(coarseningLevels) + " is outside 0 to 4");
  }
  if (regionOfInterest) {
    const Sphere& roi = *regionOfInterest;
    if (!std::isfinite(roi.radiusMm) || roi.radiusMm <= 0 || !std::isfinite(roi.centerLps[0]) || !std::isfinite(roi.centerLps[1]) ||
        !std::isfinite(roi.centerLps[2])) {
      std::ostringstream m;
      m << "mesh region of interest: centre (" << roi.centerLps[0] << ", " << roi.centerLps[1] << ", " << roi.centerLps[2]
        << ") mm, radius " << roi.radiusMm << " mm: need a finite centre and a positive radius";
      throw InputError(m.str());
    }
  }
}

namespace {
/// The fine lattice in the label map's continuous index space: cells of `step` voxels from `start`.
struct FineLattice {
  double start[3], step[3];
  std::array<int, 3> cells{};

  std::size_t cellIndex(long i, long j, long k) const
  {
    return std::size_t(i) + std::size_t(cells[0]) * (std::size_t(j) + std::size_t(cells[1]) * std::size_t(k));
  }
  std::size_t cellCount() const { return std::size_t(cells[0]) * std::size_t(cells[1]) * std::size_t(cells[2]); }
};

/// Whether the voxels a fine cell spans (its voxel centres, and at least the nearest one along
/// each axis) hold two classes: two chosen tissues, or one and the outside. Cells touching the
/// image's border from outside hold only "outside".
bool cellHoldsTwoClasses(const LabelImage& image, const std::set<int>& chosen, const FineLattice& grid, long i, long j, long k)
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  const LabelPixel* voxels = image.GetBufferPointer();
  const long cell[3] = {i, j, k};
  long from[3], to[3];
  bool outsideImage = false;
  for (int d = 0; d < 3; ++d) {
    const double a = grid.start[d] + double(cell[d]) * grid.step[d], b = a + grid.step[d];
    from[d] = std::max(0L, long(std::floor(a)));
    to[d] = std::min(long(size[unsigned(d)]) - 1, long(std::ceil(b)));
    if (from[d] > to[d]) outsideImage = true;
  }
  if (outsideImage) return false;
  int first = -1;
  for (long z = from[2]; z <= to[2]; ++z) {
    for (long y = from[1]; y <= to[1]; ++y) {
      const LabelPixel* row = voxels + size[0] * (std::size_t(y) + size[1] * std::size_t(z));
      for (long x = from[0]; x <= to[0]; ++x) {
        const int c = chosen.count(row[x]) ? int(row[x]) : 0;
        if (first < 0) first = c;
        else if (c != first) return true;
      }
    }
  }
  return false;
}

/// Zero distance for the cells whose centre lies in the sphere.
void markRegionOfInterest(const LabelImage& image, const MeshingParameters::Sphere& roi, const FineLattice& grid, std::vector<float>& distance)
{
  for (long k = 0; k < grid.cells[2]; ++k) {
    for (long j = 0; j < grid.cells[1]; ++j) {
      for (long i = 0; i < grid.cells[0]; ++i) {
        itk::ContinuousIndex<double, 3> c;
        c[0] = grid.start[0] + (double(i) + 0.5) * grid.step[0];
        c[1] = grid.start[1] + (double(j) + 0.5) * grid.step[1];
        c[2] = grid.start[2] + (double(k) + 0.5) * grid.step[2];
        PhysicalPoint p;
        image.TransformContinuousIndexToPhysicalPoint(c, p);
        double r2 = 0;
        for (int d = 0; d < 3; ++d) r2 += (p[d] - roi.centerLps[std::size_t(d)]) * (p[d] - roi.centerLps[std::size_t(d)]);
        if (r2 <= roi.radiusMm * roi.radiusMm) distance[grid.cellIndex(i, j, k)] = 0;
      }
    }
  }
}

/// One chamfer pass (3x3x3 neighbourhood, weights for cubes of edge h), forwards or backwards:
/// each cell takes the nearest of the 13 neighbours already visited in the pass's order.
void chamferPass(std::vector<float>& distance, const FineLattice& grid, float h, bool forwards)
{
  const float far = std::numeric_limits<float>::max();
  const float w[4] = {0.0f, h, h * float(std::sqrt(2.0)), h * float(std::sqrt(3.0))};
  const int sign = forwards ? 1 : -1;
  const auto& cells = grid.cells;
  for (long kk = 0; kk < cells[2]; ++kk) {
    const long k = forwards ? kk : cells[2] - 1 - kk;
    for (long jj = 0; jj < cells[1]; ++jj) {
      const long j = forwards ? jj : cells[1] - 1 - jj;
      for (long ii = 0; ii < cells[0]; ++ii) {
        const long i = forwards ? ii : cells[0] - 1 - ii;
        float best = distance[grid.cellIndex(i, j, k)];
        for (int dk = -1; dk <= 0; ++dk) {
          for (int dj = -1; dj <= 1; ++dj) {
            for (int di = -1; di <= 1; ++di) {
              if (dk == 0 && (dj > 0 || (dj == 0 && di >= 0))) continue;
              const long a = i + sign * di, b = j + sign * dj, c = k + sign * dk;
              if (a < 0 || b < 0 || c < 0 || a >= cells[0] || b >= cells[1] || c >= cells[2]) continue;
              const float there = distance[grid.cellIndex(a, b, c)];
              if (there < far) best = std::min(best, there + w[std::abs(di) + std::abs(dj) + std::abs(dk)]);
            }
          }
        }
        distance[grid.cellIndex(i, j, k)] = best;
      }
    }
  }
}

/// Distance (mm) from each cell of the fine lattice to the nearest cell where the mesh must be
/// fine: one whose voxels hold two classes (a tissue interface, or a tissue against the outside)
/// or whose centre lies in the region of interest. Chamfer distance (3x3x3, two passes).
std::vector<float> distanceToFeatures(const LabelImage& image, const MeshingParameters& parameters, const std::set<int>& chosen,
                                      const FineLattice& grid)
{
  std::vector<float> distance(grid.cellCount(), std::numeric_limits<float>::max());
  for (long k = 0; k < grid.cells[2]; ++k) {
    for (long j = 0; j < grid.cells[1]; ++j) {
      for (long i = 0; i < grid.cells[0]; ++i) {
        if (cellHoldsTwoClasses(image, chosen, grid, i, j, k)) distance[grid.cellIndex(i, j, k)] = 0;
      }
    }
  }
  if (parameters.regionOfInterest) markRegionOfInterest(image, *parameters.regionOfInterest, grid, distance);
  const float h = float(parameters.resolutionMm); // the cells are cubes of resolutionMm
  chamferPass(distance, grid, h, true);
  chamferPass(distance, grid, h, false);
  return distance;
}

/// The lattice tetrahedra near the meshed ones (sharing a node with one), the tetrahedra around
/// each node among them (compressed rows) and, for each, the neighbour across each face (-1: none).
struct NearTetrahedra {
  std::vector<int> tetrahedra;
  std::vector<int> start, around; ///< node v's: around[start[v] .. start[v + 1])
  std::vector<int> index;         ///< of each lattice tetrahedron in `tetrahedra` (-1: not near)
  std::vector<std::array<int, 4>> across;
};

/// Face f of a tetrahedron: its corners, outward order.
constexpr int FaceCorners[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

bool holdsNode(const KuhnLattice& lattice, int t, int v)
{
  const auto& q = lattice.tetrahedra[std::size_t(t)];
  return q[0] == v || q[1] == v || q[2] == v || q[3] == v;
}

void findFaceNeighbours(const KuhnLattice& lattice, NearTetrahedra& near)
{
  near.across.resize(near.tetrahedra.size());
  for (int t : near.tetrahedra) {
    const auto& q = lattice.tetrahedra[std::size_t(t)];
    std::array<int, 4> neighbours{-1, -1, -1, -1};
    for (int f = 0; f < 4; ++f) {
      const int a = q[std::size_t(FaceCorners[f][0])], b = q[std::size_t(FaceCorners[f][1])], c = q[std::size_t(FaceCorners[f][2])];
      for (int r = near.start[std::size_t(a)]; r < near.start[std::size_t(a) + 1]; ++r) {
        const int u = near.around[std::size_t(r)];
        if (u != t && holdsNode(lattice, u, b) && holdsNode(lattice, u, c)) {
          neighbours[std::size_t(f)] = u;
          break;
        }
      }
    }
    near.across[std::size_t(near.index[std::size_t(t)])] = neighbours;
  }
}

NearTetrahedra nearTetrahedraOf(const KuhnLattice& lattice, const std::vector<int>& tissueOf)
{
  const std::size_t n = lattice.tetrahedra.size();
  std::vector<char> nodeNearTissue(lattice.nodes.size(), 0);
  for (std::size_t t = 0; t < n; ++t) {
    if (tissueOf[t] < 0) continue;
    for (int v : lattice.tetrahedra[t]) nodeNearTissue[std::size_t(v)] = 1;
  }
  NearTetrahedra near;
  for (std::size_t t = 0; t < n; ++t) {
    const auto& q = lattice.tetrahedra[t];
    if (nodeNearTissue[std::size_t(q[0])] || nodeNearTissue[std::size_t(q[1])] || nodeNearTissue[std::size_t(q[2])] ||
        nodeNearTissue[std::size_t(q[3])]) {
      near.tetrahedra.push_back(int(t));
    }
  }
  near.start.assign(lattice.nodes.size() + 1, 0);
  near.around.resize(4 * near.tetrahedra.size());
  for (int t : near.tetrahedra) {
    for (int v : lattice.tetrahedra[std::size_t(t)]) near.start[std::size_t(v) + 1] += 1;
  }
  for (std::size_t v = 0; v < lattice.nodes.size(); ++v) near.start[v + 1] += near.start[v];
  std::vector<int> fill(near.start.begin(), near.start.end() - 1);
  for (int t : near.tetrahedra) {
    for (int v : lattice.tetrahedra[std::size_t(t)]) near.around[std::size_t(fill[std::size_t(v)]++)] = t;
  }
  near.index.assign(n, -1);
  for (std::size_t r = 0; r < near.tetrahedra.size(); ++r) near.index[std::size_t(near.tetrahedra[r])] = int(r);
  findFaceNeighbours(lattice, near);
  return near;
}

/// What the repair works on: the lattice, its tetrahedra near the tissues, each tetrahedron's
/// tissue (-1: not meshed; changed by the repair) and whether it has joined a tissue already.
struct TopologyRepair {
  const KuhnLattice& lattice;
  const NearTetrahedra& near;
  std::vector<int>& tissueOf;
  std::vector<char> joined;

  /// In `region`: a tissue, or -2 for the union of the chosen tissues.
  bool inRegion(int region, int t) const
  {
    if (t < 0) return false;
    const int l = tissueOf[std::size_t(t)];
    return region == -2 ? l >= 0 : l == region;
  }
};

/// The edges of the region's boundary with more than two boundary triangles on them, in a fixed
/// order (the repairs depend on it), as (smaller node << 32 | larger node).
std::vector<std::uint64_t> nonManifoldEdgesOf(int region, const TopologyRepair& repair)
{
  std::unordered_map<std::uint64_t, int> edgeCount;
  for (int t : repair.near.tetrahedra) {
    if (!repair.inRegion(region, t)) continue;
    const auto& q = repair.lattice.tetrahedra[std::size_t(t)];
    const auto& neighbours = repair.near.across[std::size_t(repair.near.index[std::size_t(t)])];
    for (int f = 0; f < 4; ++f) {
      if (repair.inRegion(region, neighbours[std::size_t(f)])) continue;
      for (int e = 0; e < 3; ++e) {
        const std::uint64_t u = std::uint64_t(q[std::size_t(FaceCorners[f][e])]), w = std::uint64_t(q[std::size_t(FaceCorners[f][(e + 1) % 3])]);
        edgeCount[(std::min(u, w) << 32) | std::max(u, w)] += 1;
      }
    }
  }
  std::vector<std::uint64_t> nonManifold;
  for (const auto& [key, count] : edgeCount) {
    if (count > 2) nonManifold.push_back(key);
  }
  std::sort(nonManifold.begin(), nonManifold.end());
  return nonManifold;
}

/// The tetrahedra around the edge that are not in the region join it (the union: its most common
/// tissue around the edge), each at most once; returns how many joined.
std::size_t joinAroundEdge(std::uint64_t key, int region, TopologyRepair& repair)
{
  const int a = int(key >> 32), b = int(key & 0xffffffffu);
  std::vector<int> ring;
  std::map<int, int> count;
  for (int r = repair.near.start[std::size_t(a)]; r < repair.near.start[std::size_t(a) + 1]; ++r) {
    const int t = repair.near.around[std::size_t(r)];
    if (!holdsNode(repair.lattice, t, b)) continue;
    ring.push_back(t);
    if (repair.inRegion(region, t)) count[repair.tissueOf[std::size_t(t)]] += 1;
  }
  int fill = region;
  if (region == -2) {
    int best = 0;
    for (const auto& [l, c] : count) {
      if (c > best) {
        best = c;
        fill = l;
      }
    }
  }
  std::size_t joinedNow = 0;
  for (int t : ring) {
    // A tetrahedron changes tissue once: two tissues must not trade it back and forth.
    if (!repair.inRegion(region, t) && !repair.joined[std::size_t(t)]) {
      repair.tissueOf[std::size_t(t)] = fill;
      repair.joined[std::size_t(t)] = 1;
      ++joinedNow;
    }
  }
  return joinedNow;
}

/// Topology repair: labelling by centroid can leave a region touching itself only along an edge
/// (a non-manifold edge: four boundary triangles on it). Around such an edge the tetrahedra that
/// separate the region's wedges join the region, until every boundary edge of the union of
/// tissues and of each tissue has exactly two triangles. `tissueOf` is -1 for the unmeshed.
std::size_t repairNonManifoldEdges(const KuhnLattice& lattice, std::vector<int>& tissueOf, const std::set<int>& chosen, Warnings& warnings)
{
  const NearTetrahedra near = nearTetrahedraOf(lattice, tissueOf);
  TopologyRepair repair{lattice, near, tissueOf, std::vector<char>(lattice.tetrahedra.size(), 0)};
  std::size_t repaired = 0;
  std::size_t remaining = 0; // non-manifold edges seen in the last pass
  for (int pass = 0; pass < 30; ++pass) {
    bool changed = false;
    remaining = 0;
    std::vector<int> regions{-2}; // -2: the union of the chosen tissues
    regions.insert(regions.end(), chosen.begin(), chosen.end());
    for (int region : regions) {
      const std::vector<std::uint64_t> nonManifold = nonManifoldEdgesOf(region, repair);
      remaining += nonManifold.size();
      for (std::uint64_t key : nonManifold) {
        const std::size_t joinedNow = joinAroundEdge(key, region, repair);
        repaired += joinedNow;
        changed = changed || joinedNow > 0;
      }
    }
    if (!changed) break;
  }
  if (remaining > 0) {
    warnings.push_back("mesh: " + std::to_string(remaining) + " tissue surface edges stay non-manifold after the topology repair");
  }
  return repaired;
}

/// The fine lattice in continuous index space: steps of h / spacing voxels, covering the index
/// box [lo, hi] with a margin.
FineLattice fineLatticeOver(const LabelImage& image, const MeshingParameters& parameters, const long lo[3], const long hi[3])
{
  FineLattice grid;
  for (int d = 0; d < 3; ++d) {
    grid.step[d] = parameters.resolutionMm / image.GetSpacing()[unsigned(d)];
    grid.start[d] = double(lo[d]) - 0.5 - 0.5 * grid.step[d];
    grid.cells[std::size_t(d)] = int(std::ceil((double(hi[d]) + 0.5 - grid.start[d]) / grid.step[d]));
  }
  return grid;
}

/// The Kuhn lattice on the fine cells, graded when asked: a tetrahedron of a cube of edge s (mm) is
/// bisected unless every point of it (within s of its centroid) is far enough from the features
/// for that size: s <= h + rate * distance.
KuhnLattice gradedLatticeOver(const LabelImage& image, const MeshingParameters& parameters, const std::set<int>& chosen,
                              const FineLattice& grid)
{
  const bool graded = parameters.gradingRate > 0 && parameters.coarseningLevels > 0;
  std::vector<float> distance;
  if (graded) distance = distanceToFeatures(image, parameters, chosen, grid);
  const double h = parameters.resolutionMm;
  const auto& cells = grid.cells;
  auto wantsFiner = [&](const std::array<double, 3>& centroid, double cubeEdge) {
    std::size_t index = 0, stride = 1;
    for (int d = 0; d < 3; ++d) {
      const int c = std::clamp(int(std::floor(centroid[std::size_t(d)])), 0, cells[std::size_t(d)] - 1);
      index += stride * std::size_t(c);
      stride *= std::size_t(cells[std::size_t(d)]);
    }
    const double s = cubeEdge * h;
    const double clearance = std::max(0.0, double(distance[index]) - s);
    return s > h + parameters.gradingRate * clearance + 1e-9;
  };
  return buildGradedKuhnLattice(cells, graded ? parameters.coarseningLevels : 0, wantsFiner);
}

/// Every lattice tetrahedron's tissue (-1: not meshed), by the voxel at its centroid.
std::vector<int> tissuesByCentroid(const LabelImage& image, const std::set<int>& chosen, const KuhnLattice& lattice,
                                   const FineLattice& grid)
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  const LabelPixel* voxels = image.GetBufferPointer();
  auto tissueAt = [&](const double c[3]) -> int {
    long idx[3];
    for (int d = 0; d < 3; ++d) {
      idx[d] = std::lround(c[d]);
      if (idx[d] < 0 || idx[d] >= long(size[unsigned(d)])) return 0;
    }
    return voxels[std::size_t(idx[0]) + size[0] * (std::size_t(idx[1]) + size[1] * std::size_t(idx[2]))];
  };
  std::vector<int> tissueOf(lattice.tetrahedra.size(), -1);
  for (std::size_t t = 0; t < lattice.tetrahedra.size(); ++t) {
    double centroid[3] = {0, 0, 0};
    for (int v : lattice.tetrahedra[t]) {
      for (int d = 0; d < 3; ++d) centroid[d] += (grid.start[d] + double(lattice.nodes[std::size_t(v)][std::size_t(d)]) * grid.step[d]) / 4.0;
    }
    const int tissue = tissueAt(centroid);
    if (chosen.count(tissue)) tissueOf[t] = tissue;
  }
  return tissueOf;
}

/// The meshed tetrahedra with their nodes (physical points, numbered in order of first use),
/// each positively oriented.
TetrahedralMeshArrays meshedTetrahedra(const LabelImage& image, const KuhnLattice& lattice, const std::vector<int>& tissueOf,
                                       const FineLattice& grid)
{
  TetrahedralMeshArrays arrays;
  std::vector<long long> newIndex(lattice.nodes.size(), -1);
  for (std::size_t t = 0; t < lattice.tetrahedra.size(); ++t) {
    const int tissue = tissueOf[t];
    if (tissue < 0) continue;
    std::array<long long, 4> ids{};
    Vec p[4];
    for (int v = 0; v < 4; ++v) {
      const int node = lattice.tetrahedra[t][std::size_t(v)];
      long long& id = newIndex[std::size_t(node)];
      if (id < 0) {
        id = (long long)arrays.points.size();
        itk::ContinuousIndex<double, 3> c;
        for (int d = 0; d < 3; ++d) c[unsigned(d)] = grid.start[d] + double(lattice.nodes[std::size_t(node)][std::size_t(d)]) * grid.step[d];
        PhysicalPoint x;
        image.TransformContinuousIndexToPhysicalPoint(c, x);
        arrays.points.push_back({x[0], x[1], x[2]});
      }
      ids[std::size_t(v)] = id;
      p[v] = arrays.points[std::size_t(id)];
    }
    if (signedVolume(p) < 0) std::swap(ids[2], ids[3]); // Maubach's order and the image's direction set the sign
    arrays.tetrahedra.push_back(ids);
    arrays.labels.push_back(tissue);
  }
  return arrays;
}

void snapOntoTissueBoundaries(TetrahedralMeshArrays& arrays, const LabelImage& image, const MeshingParameters& parameters,
                              const std::set<int>& chosen, Warnings& warnings)
{
  SnappingParameters snapping;
  snapping.minimumDihedralDegrees = parameters.minimumDihedralDegrees;
  const std::vector<int> tissues(chosen.begin(), chosen.end());
  const SnappingSummary s = snapInterfaceNodes(arrays, image, tissues, snapping);
  if (s.nodesPartlyMoved > s.interfaceNodes / 10) {
    warnings.push_back("mesh: " + std::to_string(s.nodesPartlyMoved) + " of " + std::to_string(s.interfaceNodes) +
                       " interface nodes stopped short of the tissue boundary to keep the elements' quality");
  }
}

/// The (graded) Kuhn lattice of the chosen tissues' index box [lo, hi], labelled, repaired and
/// snapped.
TetrahedralMeshArrays latticeMesh(const LabelImage& image, const MeshingParameters& parameters, const std::set<int>& chosen,
                                  const long lo[3], const long hi[3], Warnings& warnings)
{
  const FineLattice grid = fineLatticeOver(image, parameters, lo, hi);
  const KuhnLattice lattice = gradedLatticeOver(image, parameters, chosen, grid);
  throwIfCancelled(parameters.cancel, "meshing");
  std::vector<int> tissueOf = tissuesByCentroid(image, chosen, lattice, grid);
  throwIfCancelled(parameters.cancel, "meshing");
  const std::size_t repaired = repairNonManifoldEdges(lattice, tissueOf, chosen, warnings);
  throwIfCancelled(parameters.cancel, "meshing");
  if (repaired > 0) {
    warnings.push_back("mesh: " + std::to_string(repaired) +
                       " lattice tetrahedra joined their neighbours' tissue to keep every surface manifold");
  }
  TetrahedralMeshArrays arrays = meshedTetrahedra(image, lattice, tissueOf, grid);
  if (parameters.snapToBoundaries) snapOntoTissueBoundaries(arrays, image, parameters, chosen, warnings);
  return arrays;
}
/// Keeps the largest face-connected part of the mesh. Parts that are detached (a fragment of the
/// label map) or joined to it only at a node or along an edge (a lattice tetrahedron hanging at a
/// corner) would move, or turn about that node or edge, at no cost: the stiffness matrix would be
/// singular wherever such a part has no imposed node. They are dropped, with their nodes, and
/// counted in a warning.
void keepLargestFaceConnectedPart(TetrahedralMeshArrays& arrays, Warnings& warnings)
{
  const std::size_t n = arrays.tetrahedra.size();
  std::vector<std::size_t> parent(n);
  std::iota(parent.begin(), parent.end(), std::size_t(0));
  auto find = [&](std::size_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  // Tetrahedra around each node (compressed rows); two tetrahedra share a face when one of them,
  // found around the face's first node, holds the face's other two nodes as well.
  std::vector<std::size_t> start(arrays.points.size() + 1, 0), around(4 * n);
  for (const auto& t : arrays.tetrahedra) {
    for (long long v : t) start[std::size_t(v) + 1] += 1;
  }
  for (std::size_t v = 0; v < arrays.points.size(); ++v) start[v + 1] += start[v];
  {
    std::vector<std::size_t> fill(start.begin(), start.end() - 1);
    for (std::size_t t = 0; t < n; ++t) {
      for (long long v : arrays.tetrahedra[t]) around[fill[std::size_t(v)]++] = t;
    }
  }
  auto holds = [&](std::size_t t, long long v) {
    const auto& q = arrays.tetrahedra[t];
    return q[0] == v || q[1] == v || q[2] == v || q[3] == v;
  };
  static const int faces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  for (std::size_t t = 0; t < n; ++t) {
    const auto& q = arrays.tetrahedra[t];
    for (const auto& f : faces) {
      const long long a = q[std::size_t(f[0])], b = q[std::size_t(f[1])], c = q[std::size_t(f[2])];
      for (std::size_t k = start[std::size_t(a)]; k < start[std::size_t(a) + 1]; ++k) {
        const std::size_t u = around[k];
        if (u <= t || !holds(u, b) || !holds(u, c)) continue; // each pair once, from its first
        const std::size_t x = find(t), y = find(u);
        if (x != y) parent[std::max(x, y)] = std::min(x, y);
        break; // a face has at most one other tetrahedron
      }
    }
  }
  std::unordered_map<std::size_t, std::size_t> partSize;
  for (std::size_t t = 0; t < n; ++t) partSize[find(t)] += 1;
  if (partSize.size() <= 1) return;
  std::size_t largest = 0, largestSize = 0;
  for (const auto& [root, size] : partSize) {
    if (size > largestSize || (size == largestSize && root < largest)) {
      largest = root;
      largestSize = size;
    }
  }
  TetrahedralMeshArrays kept;
  std::vector<long long> newIndex(arrays.points.size(), -1);
  for (std::size_t t = 0; t < n; ++t) {
    if (find(t) != largest) continue;
    std::array<long long, 4> ids = arrays.tetrahedra[t];
    for (long long& v : ids) {
      if (newIndex[std::size_t(v)] < 0) {
        newIndex[std::size_t(v)] = (long long)kept.points.size();
        kept.points.push_back(arrays.points[std::size_t(v)]);
      }
      v = newIndex[std::size_t(v)];
    }
    kept.tetrahedra.push_back(ids);
    kept.labels.push_back(arrays.labels[t]);
  }
  warnings.push_back("mesh: " + std::to_string(n - largestSize) + " tetrahedra in " + std::to_string(partSize.size() - 1) +
                     " parts not joined to the mesh by a face (detached, or touching it at a node or along an edge) were dropped: "
                     "nothing would hold them in the elastic model");
  arrays = std::move(kept);
}

} // namespace

#ifndef BRAINSHIFT_HAVE_CGAL
bool cgalMeshingAvailable() { return false; }

TetrahedralMeshArrays meshLabelMapWithCgal(const LabelImage&, const MeshingParameters&)
{
  throw NotAvailableError("meshing: the CGAL backend is not available: BrainShift was built without CGAL");
}
#endif

MeshingParameters meshingParametersFrom(const Configuration& configuration)
{
  MeshingParameters parameters;
  parameters.resolutionMm = configuration.meshResolutionMm;
  parameters.labels = configuration.meshLabels;
  parameters.backend = configuration.meshBackend == "cgal" ? MeshingBackend::Cgal : MeshingBackend::Lattice;
  parameters.gradingRate = configuration.meshGrading;
  parameters.coarseningLevels = configuration.meshCoarseningLevels;
  if (configuration.meshRegionOfInterestRadiusMm > 0) {
    parameters.regionOfInterest = MeshingParameters::Sphere{configuration.meshRegionOfInterestCenterLps, configuration.meshRegionOfInterestRadiusMm};
  }
  return parameters;
}

LabelMapMesh meshLabelMap(const LabelImage& image, const MeshingParameters& parameters)
{
  parameters.validate(image);
  LabelMapMesh result;
  const auto size = image.GetLargestPossibleRegion().GetSize();
  const LabelPixel* voxels = image.GetBufferPointer();
  std::set<int> chosen(parameters.labels.begin(), parameters.labels.end());
  std::map<int, std::size_t> voxelCount;
  // The bounding box (index space) of the chosen tissues.
  long lo[3] = {long(size[0]), long(size[1]), long(size[2])}, hi[3] = {-1, -1, -1};
  for (std::size_t k = 0; k < size[2]; ++k) {
    for (std::size_t j = 0; j < size[1]; ++j) {
      for (std::size_t i = 0; i < size[0]; ++i) {
        const int l = voxels[i + size[0] * (j + size[1] * k)];
        if (!chosen.count(l)) continue;
        voxelCount[l] += 1;
        const long idx[3] = {long(i), long(j), long(k)};
        for (int d = 0; d < 3; ++d) {
          lo[d] = std::min(lo[d], idx[d]);
          hi[d] = std::max(hi[d], idx[d]);
        }
      }
    }
  }
  if (voxelCount.empty()) throw InputError("meshing: the label map holds none of the tissues to mesh");
  for (int l : chosen) {
    if (!voxelCount.count(l)) throw InputError("meshing: tissue label " + std::to_string(l) + " is not in the label map");
  }
  if (parameters.backend == MeshingBackend::Cgal && parameters.gradingRate > 0) {
    result.warnings.push_back("mesh: the CGAL backend meshes at one size; the grading applies to the lattice backend only");
  }
  TetrahedralMeshArrays arrays = parameters.backend == MeshingBackend::Cgal
                                     ? meshLabelMapWithCgal(image, parameters)
                                     : latticeMesh(image, parameters, chosen, lo, hi, result.warnings);
  throwIfCancelled(parameters.cancel, "meshing");
  keepLargestFaceConnectedPart(arrays, result.warnings);
  result.mesh = toUnstructuredGrid(arrays);
  result.quality = measureMeshQuality(result.mesh, &image);
  for (int l : chosen) {
    if (!result.quality.meshVolumeMl.count(l)) {
      throw InputError("meshing: tissue label " + std::to_string(l) + " (" + numberText(result.quality.voxelVolumeMl[l]) +
                       " ml) vanishes at " + numberText(parameters.resolutionMm) + " mm; choose a finer --mesh-resolution");
    }
    const double ratio = result.quality.meshVolumeMl[l] / result.quality.voxelVolumeMl[l];
    if (std::abs(ratio - 1.0) > 0.1) {
      std::ostringstream w;
      w << "mesh: tissue " << l << " has " << result.quality.meshVolumeMl[l] << " ml in the mesh for "
        << result.quality.voxelVolumeMl[l] << " ml of voxels (" << int(std::lround(100 * (ratio - 1))) << " %) at "
        << parameters.resolutionMm << " mm";
      result.warnings.push_back(w.str());
    }
  }
  return result;
}

MeshQuality measureMeshQuality(vtkUnstructuredGrid* mesh, const LabelImage* labels)
{
  MeshQuality q;
  q.nodes = std::size_t(mesh->GetNumberOfPoints());
  q.tetrahedra = std::size_t(mesh->GetNumberOfCells());
  q.minimumDihedralDegrees = 180;
  q.radiusRatioHistogram.assign(10, 0);
  vtkDataArray* label = mesh->GetCellData()->GetArray("Label");
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    mesh->GetCellPoints(c, ids);
    Vec p[4];
    for (int v = 0; v < 4; ++v) mesh->GetPoint(ids->GetId(v), p[v].data());
    const double volume = signedVolume(p);
    if (!(volume > 0)) {
      ++q.invertedOrFlat;
      continue;
    }
    for (double a : dihedralAngles(p)) {
      q.minimumDihedralDegrees = std::min(q.minimumDihedralDegrees, a);
      q.maximumDihedralDegrees = std::max(q.maximumDihedralDegrees, a);
    }
    q.radiusRatioHistogram[std::min<std::size_t>(9, std::size_t(radiusRatio(p) * 10))] += 1;
    if (label) q.meshVolumeMl[int(std::lround(label->GetComponent(c, 0)))] += volume / 1000.0;
  }
  if (labels) {
    const double voxelMl = labels->GetSpacing()[0] * labels->GetSpacing()[1] * labels->GetSpacing()[2] / 1000.0;
    const LabelPixel* v = labels->GetBufferPointer();
    for (std::size_t i = 0, n = labels->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
      if (q.meshVolumeMl.count(v[i]) || v[i] != 0) q.voxelVolumeMl[v[i]] += voxelMl;
    }
  }
  return q;
}

vtkSmartPointer<vtkPolyData> boundarySurface(vtkUnstructuredGrid* mesh, const std::set<int>& tissues)
{
  vtkDataArray* label = mesh->GetCellData()->GetArray("Label");
  if (!label) throw std::invalid_argument("the mesh has no cell array Label");
  // Faces of the chosen tetrahedra, keyed by their sorted nodes; a face seen once is boundary.
  struct Face {
    vtkIdType oriented[3];
    int count = 0;
  };
  std::map<std::array<vtkIdType, 3>, Face> faces;
  static const int local[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}}; // outward for positive tetrahedra
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    if (!tissues.count(int(std::lround(label->GetComponent(c, 0))))) continue;
    mesh->GetCellPoints(c, ids);
    for (const auto& f : local) {
      std::array<vtkIdType, 3> key{ids->GetId(f[0]), ids->GetId(f[1]), ids->GetId(f[2])};
      std::array<vtkIdType, 3> sorted = key;
      std::sort(sorted.begin(), sorted.end());
      Face& face = faces[sorted];
      if (face.count++ == 0) std::copy(key.begin(), key.end(), face.oriented);
    }
  }
  auto surface = vtkSmartPointer<vtkPolyData>::New();
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  vtkNew<vtkCellArray> triangles;
  vtkNew<vtkIntArray> nodeIds;
  nodeIds->SetName("MeshNodeId");
  std::map<vtkIdType, vtkIdType> surfacePointOf;
  for (const auto& [key, face] : faces) {
    if (face.count != 1) continue;
    vtkIdType triangle[3];
    for (int v = 0; v < 3; ++v) {
      auto [at, inserted] = surfacePointOf.emplace(face.oriented[v], points->GetNumberOfPoints());
      if (inserted) {
        points->InsertNextPoint(mesh->GetPoint(face.oriented[v]));
        nodeIds->InsertNextValue(int(face.oriented[v]));
      }
      triangle[v] = at->second;
    }
    triangles->InsertNextCell(3, triangle);
  }
  surface->SetPoints(points);
  surface->SetPolys(triangles);
  surface->GetPointData()->AddArray(nodeIds);
  return surface;
}

} // namespace brainshift
