#pragma once
// An independent finite element truth for the built-in case: the preoperative brain (labels 2, 3, 4)
// meshed by CGAL Mesh_3 (not BrainShift's lattice), made quadratic (C3D10: a node at the middle of
// every edge, shared by the elements around it), given literature materials that are deliberately not
// BrainShift's defaults, and solved by CalculiX (ccx, Debian package calculix-ccx) as a linear static
// problem with:
//  - the skull base fixed: the surface nodes in the lowest skullBaseFraction of the brain's height
//    (LPS z, superior up);
//  - the craniotomy cap under prescribed sinking: the surface nodes within openingRadiusMm of the
//    craniotomy axis on its outer side (outward normal with a positive component along the axis, less
//    than openingRadiusMm below the centre) move by u = -shift exp(-r^2 / 2 sigma^2) axis;
//  - every other surface node sliding along the skull: u . n = 0 with n the node's outward normal
//    (a CalculiX *EQUATION per node).
// The resampling field w on the deformed configuration is then the inverse of the forward map
// X -> X + u(X) (u interpolated by the quadratic shape functions), extended outside the deformed brain.
// Units in the deck: mm, mN, kPa.
#include "ImageTypes.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

namespace brainshift {

struct FiniteElementTruthParameters {
  std::array<double, 3> craniotomyCentre{}; // LPS mm, on the preoperative brain surface
  std::array<double, 3> craniotomyAxis{};   // outward unit vector, LPS
  double shiftMm = 10;                      // peak sinking at the centre of the craniotomy
  double lateralSigmaMm = 25;               // Gaussian profile of the prescribed sinking
  double openingRadiusMm = 30;              // surface nodes within this distance of the axis (and on the outer side) are the loaded cap
  double elementSizeMm = 8;                 // CGAL facet/cell size (8: ccx about 31 s, 0.55 GB on the full built-in case; 6: 145 s, 1.6 GB)
  std::filesystem::path workFolder;         // where the .inp and ccx's outputs go (a temporary folder if empty; removed afterwards)
  std::uint64_t seed = 2000;                // CGAL's generators are seeded by the mesher (fixed 2000); kept for the interface
  double skullBaseFraction = 0.2;           // surface nodes in this lowest fraction of the brain's height (LPS z) are fixed
  double fieldTaperMm = 20;                 // outside the deformed brain, w fades to 0 over this distance (beyond the largest surface displacement)

  /// InputError naming the value for an axis that is not a unit vector, negative sizes, ...
  void validate() const;
};

struct FiniteElementTruthFigures {
  std::size_t nodes = 0, elements = 0;
  double ccxSeconds = 0, maxDisplacementMm = 0;
  std::size_t slidingNodes = 0, fixedNodes = 0, loadedNodes = 0;
  double ccxPeakMemoryMb = 0;   ///< ccx's maximum resident set size
  double meshSeconds = 0, fieldSeconds = 0;
  std::size_t invertedElements = 0;     ///< elements folded by the linear solution (Jacobian <= 0 at a corner or the centroid)
  std::size_t droppedElements = 0;      ///< CGAL elements outside the largest connected piece (not simulated)
  std::size_t newtonFallbacks = 0;      ///< field points where the fixed-point inversion stalled and Newton finished it
  std::size_t unconvergedInversions = 0; ///< field points where neither converged to 1e-6 mm (w taken from the last iterate)
};

/// The solved model: the quadratic mesh, its boundary conditions and the displacements.
struct FiniteElementTruthModel {
  enum class Role : unsigned char { Interior, Sliding, Fixed, Loaded };
  std::vector<std::array<double, 3>> nodes;        ///< LPS mm: the mesher's vertices, then the mid-edge nodes
  std::vector<std::array<std::int64_t, 10>> elements; ///< 0-based, CalculiX's C3D10 order (4 corners, then edges 12 23 31 14 24 34)
  std::vector<int> labels;                          ///< tissue of each element (2, 3, 4)
  std::vector<std::array<std::int64_t, 6>> boundaryFaces; ///< outward corners a b c, then the mid-edge nodes of ab bc ca
  std::vector<Role> roles;                          ///< per node
  std::vector<std::array<double, 3>> normals;       ///< outward unit normal of the surface nodes (0 inside)
  std::vector<std::array<double, 3>> prescribed;    ///< imposed displacement of the loaded nodes (0 elsewhere)
  std::vector<std::array<double, 3>> displacements; ///< u per node, mm (after the solve)
};

/// Meshes the brain and sets the boundary conditions. InputError for bad parameters or no brain;
/// NotAvailableError without CGAL.
FiniteElementTruthModel buildFiniteElementTruthModel(const LabelImage& preopLabels, const FiniteElementTruthParameters& parameters,
                                                     FiniteElementTruthFigures* figures = nullptr);

/// Writes the deck, runs ccx in the work folder and reads u back into `model`. NotAvailableError when ccx is
/// missing; MethodError with the end of ccx's output when it fails.
void solveFiniteElementTruthModel(FiniteElementTruthModel& model, const FiniteElementTruthParameters& parameters,
                                  FiniteElementTruthFigures& figures);

/// u(X) and the inverse of X -> X + u(X) on a solved model (point location by buckets).
class FiniteElementDisplacement {
public:
  explicit FiniteElementDisplacement(const FiniteElementTruthModel& model);
  ~FiniteElementDisplacement();
  /// u at the preoperative point X, or nothing outside the mesh.
  std::optional<std::array<double, 3>> at(const std::array<double, 3>& X) const;
  struct Inverse {
    std::array<double, 3> preoperative{};
    bool newton = false, converged = true;
  };
  /// X with X + u(X) = x' when x' lies in the deformed brain (its quadratic elements cut into 8 straight
  /// tetrahedra each), else nothing.
  std::optional<Inverse> preoperativePosition(const std::array<double, 3>& deformed) const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl;
};

/// Fills `field` (allocated by the caller) with w on the deformed configuration: x' + w(x') is the
/// preoperative position of the tissue at x' inside the deformed brain; outside it w is the value at the
/// nearest point of the deformed surface, kept up to the largest surface displacement (so that the gap
/// under the craniotomy maps outside the preoperative brain) and faded to 0 over fieldTaperMm after that.
void fillFiniteElementResamplingField(const FiniteElementTruthModel& model, itk::Image<itk::Vector<double, 3>, 3>& field,
                                      const FiniteElementTruthParameters& parameters, FiniteElementTruthFigures& figures);

/// Fills `resamplingField` (already allocated by the caller; its grid is the caller's, typically 4 mm over the
/// preoperative field of view, direction as the labels') with w(x') on the DEFORMED configuration:
/// for x' inside the deformed brain, x' + w(x') is the preoperative position of the tissue now at x'
/// (the inverse of the solved forward displacement u: X + u(X) = x', found by fixed-point iteration
/// X <- x' - u(X), with u interpolated by the elements' shape functions);
/// for x' in the preoperative brain but no longer covered by the deformed brain (the gap under the craniotomy),
/// x' + w(x') must fall OUTSIDE the preoperative brain (labels 2,3,4); far from the brain w = 0, and w
/// continuous enough to be sampled trilinearly.
FiniteElementTruthFigures solveFiniteElementTruth(const LabelImage& preopLabels, itk::Image<itk::Vector<double, 3>, 3>& resamplingField,
                                                  const FiniteElementTruthParameters& parameters);

} // namespace brainshift
