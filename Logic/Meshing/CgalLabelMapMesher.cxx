#include "CgalLabelMapMesher.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Image_3.h>
#include <CGAL/Labeled_mesh_domain_3.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Random.h>
#include <CGAL/Mesh_3/initialize_triangulation_from_labeled_image.h>
#include <CGAL/make_mesh_3.h>
#include <CGAL/refine_mesh_3.h>

#include <algorithm>
#include <iostream>
#include <sstream>
#include <cstring>
#include <map>
#include <set>
#include <unordered_map>

namespace brainshift {

namespace {
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Domain = CGAL::Labeled_mesh_domain_3<Kernel>;
using Triangulation = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using Complex = CGAL::Mesh_complex_3_in_triangulation_3<Triangulation>;
using Criteria = CGAL::Mesh_criteria_3<Triangulation>;
/// The chosen tissues' index box in the label map; values are 1 + the tissue's place in the list.
struct TissueBox {
  long lo[3], hi[3];
};

TissueBox tissueBoxOf(const LabelImage& image, const std::vector<unsigned char>& valueOf)
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  const LabelPixel* voxels = image.GetBufferPointer();
  TissueBox box{{long(size[0]), long(size[1]), long(size[2])}, {-1, -1, -1}};
  for (std::size_t k = 0; k < size[2]; ++k) {
    for (std::size_t j = 0; j < size[1]; ++j) {
      for (std::size_t i = 0; i < size[0]; ++i) {
        if (!valueOf[voxels[i + size[0] * (j + size[1] * k)]]) continue;
        const long idx[3] = {long(i), long(j), long(k)};
        for (int d = 0; d < 3; ++d) {
          box.lo[d] = std::min(box.lo[d], idx[d]);
          box.hi[d] = std::max(box.hi[d], idx[d]);
        }
      }
    }
  }
  if (box.hi[0] < 0) throw InputError("meshing: the label map holds none of the tissues to mesh");
  return box;
}

/// The box (grown by two voxels of background; `lo` moved accordingly) as CGAL's 8-bit image of
/// tissue values, every other label background (0).
CGAL::Image_3 tissueImageOf(const LabelImage& image, const std::vector<unsigned char>& valueOf, long lo[3], const long hi[3])
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  const LabelPixel* voxels = image.GetBufferPointer();
  std::size_t dims[3];
  for (int d = 0; d < 3; ++d) {
    lo[d] -= 2;
    dims[d] = std::size_t(hi[d] + 2 - lo[d] + 1);
  }
  const auto spacing = image.GetSpacing();
  _image* raw = ::_createImage(dims[0], dims[1], dims[2], 1, spacing[0], spacing[1], spacing[2], 1, WK_FIXED, SGN_UNSIGNED);
  auto* data = static_cast<unsigned char*>(raw->data);
  for (std::size_t k = 0; k < dims[2]; ++k) {
    for (std::size_t j = 0; j < dims[1]; ++j) {
      for (std::size_t i = 0; i < dims[0]; ++i) {
        const long g[3] = {long(i) + lo[0], long(j) + lo[1], long(k) + lo[2]};
        unsigned char v = 0;
        if (g[0] >= 0 && g[1] >= 0 && g[2] >= 0 && g[0] < long(size[0]) && g[1] < long(size[1]) && g[2] < long(size[2])) {
          v = valueOf[voxels[std::size_t(g[0]) + size[0] * (std::size_t(g[1]) + size[1] * std::size_t(g[2]))]];
        }
        data[i + dims[0] * (j + dims[1] * k)] = v;
      }
    }
  }
  raw->tx = raw->ty = raw->tz = 0;
  return CGAL::Image_3(raw); // owns the buffer
}

/// CGAL Mesh_3 on the tissue image into `complex`: facets and cells of about h mm.
void refineTissueMesh(const CGAL::Image_3& cgalImage, double h, double finest, Complex& complex)
{
  // Determinism: CGAL draws from its default generator (perturbation, initial points) and from
  // the domain's; both are seeded.
  CGAL::get_default_random() = CGAL::Random(2000);
  CGAL::Random domainRandom(2000);
  namespace p = CGAL::parameters;
  const Domain domain = Domain::create_labeled_image_mesh_domain(p::image = cgalImage, p::relative_error_bound = 1e-6,
                                                                  p::p_rng = &domainRandom);
  // The surface may stray a quarter of the resolution from the boundary (half a voxel at least):
  // the lattice's snapping stays within about that, and finer tolerances refine every sulcus.
  const Criteria criteria(p::facet_angle = 25, p::facet_size = h, p::facet_distance = std::max(0.5 * finest, 0.25 * h),
                          p::cell_radius_edge_ratio = 3, p::cell_size = h);
  // Perturbation and sliver exudation without time limits (a time limit would make the result
  // depend on the machine's speed), both drawing from the seeded generator. No manifold(): with
  // several tissues and no protected junction curves it refines without end; a few junction edges
  // of a tissue's own surface may stay non-manifold (the union's surface is closed).
  // Seeded from every connected component of every tissue (CGAL's labelled-image initialisation):
  // the default initialisation shoots random rays and misses thin tissues such as the ventricles.
  {
    // It reports its progress on std::cout; the command line's output is ours.
    std::ostringstream quiet;
    std::streambuf* console = std::cout.rdbuf(quiet.rdbuf());
    initialize_triangulation_from_labeled_image(complex, domain, cgalImage, criteria, static_cast<unsigned char>(0));
    std::cout.rdbuf(console);
  }
  CGAL::refine_mesh_3(complex, domain, criteria, p::perturb(p::time_limit = 0, p::sliver_bound = 10), p::exude(p::time_limit = 0, p::sliver_bound = 10));
}

/// The complex's tissue cells, back in LPS (CGAL's point x is the continuous index x / spacing + lo
/// of the ITK image), each positively oriented.
TetrahedralMeshArrays tetrahedraOfComplex(const Complex& complex, const LabelImage& image, const long lo[3],
                                          const std::vector<int>& tissues)
{
  const auto spacing = image.GetSpacing();
  TetrahedralMeshArrays mesh;
  std::map<Triangulation::Vertex_handle, long long> nodeOf;
  auto node = [&](Triangulation::Vertex_handle v) {
    auto [at, inserted] = nodeOf.emplace(v, (long long)mesh.points.size());
    if (inserted) {
      const auto& q = v->point();
      itk::ContinuousIndex<double, 3> c;
      c[0] = CGAL::to_double(q.x()) / spacing[0] + double(lo[0]);
      c[1] = CGAL::to_double(q.y()) / spacing[1] + double(lo[1]);
      c[2] = CGAL::to_double(q.z()) / spacing[2] + double(lo[2]);
      PhysicalPoint x;
      image.TransformContinuousIndexToPhysicalPoint(c, x);
      mesh.points.push_back({x[0], x[1], x[2]});
    }
    return at->second;
  };
  for (auto cell = complex.cells_in_complex_begin(); cell != complex.cells_in_complex_end(); ++cell) {
    const int value = int(complex.subdomain_index(cell));
    if (value < 1 || value > int(tissues.size())) continue;
    std::array<long long, 4> ids;
    for (int v = 0; v < 4; ++v) ids[std::size_t(v)] = node(cell->vertex(v));
    const auto& a = mesh.points[std::size_t(ids[0])];
    const auto& b = mesh.points[std::size_t(ids[1])];
    const auto& c = mesh.points[std::size_t(ids[2])];
    const auto& d = mesh.points[std::size_t(ids[3])];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]},
                 z[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
    const double volume = u[0] * (w[1] * z[2] - w[2] * z[1]) - u[1] * (w[0] * z[2] - w[2] * z[0]) + u[2] * (w[0] * z[1] - w[1] * z[0]);
    if (volume < 0) std::swap(ids[2], ids[3]);
    mesh.tetrahedra.push_back(ids);
    mesh.labels.push_back(tissues[std::size_t(value - 1)]);
  }
  return mesh;
}
} // namespace

bool cgalMeshingAvailable() { return true; }

TetrahedralMeshArrays meshLabelMapWithCgal(const LabelImage& image, const MeshingParameters& parameters)
{
  // The chosen tissues' box (with two voxels of background around it) as an 8-bit image whose
  // values are 1 + the tissue's place in the list; every other label is background (0).
  const std::vector<int> tissues = [&] {
    std::set<int> s(parameters.labels.begin(), parameters.labels.end());
    return std::vector<int>(s.begin(), s.end());
  }();
  if (tissues.size() > 254) throw InputError("meshing: the CGAL backend meshes at most 254 tissues");
  std::vector<unsigned char> valueOf(65536, 0);
  for (std::size_t t = 0; t < tissues.size(); ++t) valueOf[std::size_t(tissues[t])] = (unsigned char)(t + 1);
  TissueBox box = tissueBoxOf(image, valueOf);
  const CGAL::Image_3 cgalImage = tissueImageOf(image, valueOf, box.lo, box.hi);
  const auto spacing = image.GetSpacing();
  Complex complex;
  refineTissueMesh(cgalImage, parameters.resolutionMm, std::min({double(spacing[0]), double(spacing[1]), double(spacing[2])}), complex);
  return tetrahedraOfComplex(complex, image, box.lo, tissues);
}

} // namespace brainshift
