#include "LabelMapMesher.h"
#include "TetrahedronGeometry.h"

#include "BoundaryNodeSnapping.h"
#include "CgalLabelMapMesher.h"

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkIdList.h>
#include <vtkIntArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>

#include <algorithm>
#include <cstring>
#include <cstdint>
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
}

namespace {
/// The Kuhn lattice of the chosen tissues' index box [lo, hi], labelled, repaired and snapped.
TetrahedralMeshArrays latticeMesh(const LabelImage& image, const MeshingParameters& parameters, const std::set<int>& chosen,
                                  const long lo[3], const long hi[3], Warnings& warnings)
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  const LabelPixel* voxels = image.GetBufferPointer();
  // Lattice in continuous index space: steps of h / spacing voxels, covering the box with a margin.
  double step[3];
  long cells[3];
  double start[3];
  for (int d = 0; d < 3; ++d) {
    step[d] = parameters.resolutionMm / image.GetSpacing()[unsigned(d)];
    start[d] = double(lo[d]) - 0.5 - 0.5 * step[d];
    cells[d] = long(std::ceil((double(hi[d]) + 0.5 - start[d]) / step[d]));
  }
  auto tissueAt = [&](const double c[3]) -> int {
    long idx[3];
    for (int d = 0; d < 3; ++d) {
      idx[d] = std::lround(c[d]);
      if (idx[d] < 0 || idx[d] >= long(size[unsigned(d)])) return 0;
    }
    return voxels[std::size_t(idx[0]) + size[0] * (std::size_t(idx[1]) + size[1] * std::size_t(idx[2]))];
  };
  std::unordered_map<long long, vtkIdType> nodeOf;
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  auto node = [&](long i, long j, long k) {
    const long long key = (long long)i + (long long)(cells[0] + 1) * ((long long)j + (long long)(cells[1] + 1) * k);
    auto [at, inserted] = nodeOf.emplace(key, points->GetNumberOfPoints());
    if (inserted) {
      itk::ContinuousIndex<double, 3> c;
      c[0] = start[0] + double(i) * step[0];
      c[1] = start[1] + double(j) * step[1];
      c[2] = start[2] + double(k) * step[2];
      PhysicalPoint p;
      image.TransformContinuousIndexToPhysicalPoint(c, p);
      points->InsertNextPoint(p[0], p[1], p[2]);
    }
    return at->second;
  };
  // Every lattice tetrahedron's tissue (-1: not meshed), by its centroid.
  const int paths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  const long long cellCount = (long long)cells[0] * cells[1] * cells[2];
  std::vector<int> tissueOf(std::size_t(cellCount * 6), -1);
  auto cornersOf = [&](long long tet, long corner[4][3]) {
    const long long cell = tet / 6;
    const int p = int(tet % 6);
    long c[3] = {long(cell % cells[0]), long((cell / cells[0]) % cells[1]), long(cell / ((long long)cells[0] * cells[1]))};
    std::copy(c, c + 3, corner[0]);
    for (int s = 0; s < 3; ++s) {
      c[paths[p][s]] += 1;
      std::copy(c, c + 3, corner[s + 1]);
    }
  };
  auto nodeKey = [&](const long q[3]) { return (long long)q[0] + (long long)(cells[0] + 1) * ((long long)q[1] + (long long)(cells[1] + 1) * q[2]); };
  // The lattice tetrahedron sharing the face opposite corner `f` of tetrahedron `t` (-1 beyond the
  // lattice). Path (a, b, c): across corner 0 lies path (b, c, a) of the cell + e_a, across corner
  // 3 path (c, a, b) of the cell - e_c, across corners 1 and 2 the paths (b, a, c) and (a, c, b)
  // of the same cell.
  int pathIndex[3][3][3] = {};
  for (int p = 0; p < 6; ++p) pathIndex[paths[p][0]][paths[p][1]][paths[p][2]] = p;
  auto neighbourAcross = [&](long long t, int f) -> long long {
    const long long cell = t / 6;
    const int* path = paths[t % 6];
    const int a = path[0], b = path[1], c = path[2];
    long q[3] = {long(cell % cells[0]), long((cell / cells[0]) % cells[1]), long(cell / ((long long)cells[0] * cells[1]))};
    int p = 0;
    if (f == 0) {
      q[a] += 1;
      p = pathIndex[b][c][a];
    } else if (f == 1) {
      p = pathIndex[b][a][c];
    } else if (f == 2) {
      p = pathIndex[a][c][b];
    } else {
      q[c] -= 1;
      p = pathIndex[c][a][b];
    }
    for (int d = 0; d < 3; ++d) {
      if (q[d] < 0 || q[d] >= cells[d]) return -1;
    }
    return ((long long)q[0] + (long long)cells[0] * ((long long)q[1] + (long long)cells[1] * q[2])) * 6 + p;
  };
  for (long long t = 0; t < cellCount * 6; ++t) {
    long corner[4][3];
    cornersOf(t, corner);
    double centroid[3] = {0, 0, 0};
    for (const auto& q : corner) {
      for (int d = 0; d < 3; ++d) centroid[d] += (start[d] + double(q[d]) * step[d]) / 4.0;
    }
    const int tissue = tissueAt(centroid);
    if (chosen.count(tissue)) tissueOf[std::size_t(t)] = tissue;
  }

  // Topology repair: labelling by centroid can leave a region touching itself only along an edge
  // (a non-manifold edge: four boundary triangles on it). Around such an edge the lattice
  // tetrahedra that separate the region's wedges join the region, until every boundary edge of
  // the union of tissues and of each tissue has exactly two triangles.
  static const int faceCorners[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  std::size_t repaired = 0;
  for (int pass = 0; pass < 30; ++pass) {
    bool changed = false;
    std::vector<int> regions{-2}; // -2: the union of the chosen tissues
    regions.insert(regions.end(), chosen.begin(), chosen.end());
    for (int region : regions) {
      auto inRegion = [&](long long t) {
        const int l = tissueOf[std::size_t(t)];
        return region == -2 ? l >= 0 : l == region;
      };
      // A face of a tetrahedron in the region is on the region's boundary when the lattice
      // tetrahedron across it is not in the region; edges of three or more such faces are
      // non-manifold. Edges are keyed by their two node keys in one 64-bit integer.
      std::unordered_map<std::uint64_t, int> edgeCount;
      for (long long t = 0; t < cellCount * 6; ++t) {
        if (!inRegion(t)) continue;
        long corner[4][3];
        bool cornersKnown = false;
        for (int f = 0; f < 4; ++f) {
          const long long across = neighbourAcross(t, f);
          if (across >= 0 && inRegion(across)) continue;
          if (!cornersKnown) {
            cornersOf(t, corner);
            cornersKnown = true;
          }
          for (int e = 0; e < 3; ++e) {
            const long long u = nodeKey(corner[faceCorners[f][e]]), w = nodeKey(corner[faceCorners[f][(e + 1) % 3]]);
            edgeCount[(std::uint64_t(std::min(u, w)) << 32) | std::uint64_t(std::max(u, w))] += 1;
          }
        }
      }
      std::vector<std::uint64_t> nonManifold;
      for (const auto& [key, count] : edgeCount) {
        if (count > 2) nonManifold.push_back(key);
      }
      std::sort(nonManifold.begin(), nonManifold.end()); // a fixed order: the repairs depend on it
      for (std::uint64_t key : nonManifold) {
        const std::pair<long long, long long> edge{(long long)(key >> 32), (long long)(key & 0xffffffffu)};
        // The lattice tetrahedra around the edge, in the cells that hold both of its ends.
        auto decode = [&](long long k, long q[3]) {
          q[0] = long(k % (cells[0] + 1));
          q[1] = long((k / (cells[0] + 1)) % (cells[1] + 1));
          q[2] = long(k / ((long long)(cells[0] + 1) * (cells[1] + 1)));
        };
        long a[3], b[3];
        decode(edge.first, a);
        decode(edge.second, b);
        std::vector<long long> ring;
        std::map<int, int> around;
        long range[3][2];
        for (int d = 0; d < 3; ++d) {
          range[d][0] = a[d] == b[d] ? a[d] - 1 : std::min(a[d], b[d]);
          range[d][1] = std::min(a[d], b[d]);
        }
        for (long k = range[2][0]; k <= range[2][1]; ++k) {
          for (long j = range[1][0]; j <= range[1][1]; ++j) {
            for (long i = range[0][0]; i <= range[0][1]; ++i) {
              if (i < 0 || j < 0 || k < 0 || i >= cells[0] || j >= cells[1] || k >= cells[2]) continue;
              for (int p = 0; p < 6; ++p) {
                const long long t = ((long long)i + (long long)cells[0] * ((long long)j + (long long)cells[1] * k)) * 6 + p;
                long corner[4][3];
                cornersOf(t, corner);
                bool hasA = false, hasB = false;
                for (const auto& q : corner) {
                  hasA = hasA || (q[0] == a[0] && q[1] == a[1] && q[2] == a[2]);
                  hasB = hasB || (q[0] == b[0] && q[1] == b[1] && q[2] == b[2]);
                }
                if (!hasA || !hasB) continue;
                ring.push_back(t);
                if (inRegion(t)) around[tissueOf[std::size_t(t)]] += 1;
              }
            }
          }
        }
        int fill = region;
        if (region == -2) { // the most common tissue around the edge
          int best = 0;
          for (const auto& [l, n] : around) {
            if (n > best) {
              best = n;
              fill = l;
            }
          }
        }
        for (long long t : ring) {
          if (!inRegion(t)) {
            tissueOf[std::size_t(t)] = fill;
            ++repaired;
            changed = true;
          }
        }
      }
    }
    if (!changed) break;
    if (pass == 29) {
      warnings.push_back("mesh: the topology repair did not settle in 30 passes; some surfaces may stay non-manifold");
    }
  }
  if (repaired > 0) {
    warnings.push_back("mesh: " + std::to_string(repaired) +
                              " lattice tetrahedra joined their neighbours' tissue to keep every surface manifold");
  }

  TetrahedralMeshArrays arrays;
  for (long long t = 0; t < cellCount * 6; ++t) {
    const int tissue = tissueOf[std::size_t(t)];
    if (tissue < 0) continue;
    long corner[4][3];
    cornersOf(t, corner);
    std::array<long long, 4> ids;
    Vec p[4];
    for (int v = 0; v < 4; ++v) {
      ids[std::size_t(v)] = node(corner[v][0], corner[v][1], corner[v][2]);
      points->GetPoint(ids[std::size_t(v)], p[v].data());
    }
    if (signedVolume(p) < 0) std::swap(ids[2], ids[3]); // the image's direction may mirror the lattice
    arrays.tetrahedra.push_back(ids);
    arrays.labels.push_back(tissue);
  }
  arrays.points.resize(std::size_t(points->GetNumberOfPoints()));
  for (vtkIdType v = 0; v < points->GetNumberOfPoints(); ++v) points->GetPoint(v, arrays.points[std::size_t(v)].data());
  if (parameters.snapToBoundaries) {
    SnappingParameters snapping;
    snapping.minimumDihedralDegrees = parameters.minimumDihedralDegrees;
    const std::vector<int> tissues(chosen.begin(), chosen.end());
    const SnappingSummary s = snapInterfaceNodes(arrays, image, tissues, snapping);
      if (s.nodesPartlyMoved > s.interfaceNodes / 10) {
      warnings.push_back("mesh: " + std::to_string(s.nodesPartlyMoved) + " of " + std::to_string(s.interfaceNodes) +
                                " interface nodes stopped short of the tissue boundary to keep the elements' quality");
    }
  }
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
  TetrahedralMeshArrays arrays = parameters.backend == MeshingBackend::Cgal
                                     ? meshLabelMapWithCgal(image, parameters)
                                     : latticeMesh(image, parameters, chosen, lo, hi, result.warnings);
  keepLargestFaceConnectedPart(arrays, result.warnings);
  result.mesh = toUnstructuredGrid(arrays);
  result.quality = measureMeshQuality(result.mesh, &image);
  for (int l : chosen) {
    if (!result.quality.meshVolumeMl.count(l)) {
      throw InputError("meshing: tissue label " + std::to_string(l) + " (" + std::to_string(result.quality.voxelVolumeMl[l]) +
                       " ml) vanishes at " + std::to_string(parameters.resolutionMm) + " mm; choose a finer --mesh-resolution");
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
