#pragma once
// The built-in case: a preoperative T1 with its labels and an fMRI overlay, made from the Colin27
// template (Debian package mricron-data), and an intraoperative scan of the same head after a
// brain shift with known truth.
//
// The truth deformation is a kinematic subsidence model, independent of the finite element solver
// that BrainShift uses (a solver cannot be judged against itself): under the craniotomy the brain
// surface sinks along the craniotomy axis by `shift` * exp(-r^2 / 2 sigma^2) (r: distance from the
// axis), and the sinking decays exponentially with depth below the sunken surface (length lambda).
// It is defined as the resampling field w on the deformed configuration (x = x' + w(x')), so the
// image, the labels and the landmarks all follow from one sampled field, exactly. Brain tissue
// moves with it; the head outside the brain does not move; where the brain has sunk away from the
// skull a dark gap opens; the bone flap is removed; the tumour may be resected. Then the head is
// rigidly moved in the scanner, resampled onto an intraoperative grid with slice thickness, given
// another contrast, a bias field and Rician noise.
#include "ImageTypes.h"
#include "LandmarkIO.h"
#include "TransformIO.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace brainshift {

enum class CaseSize {
  Full,  ///< preop 1 mm (181x217x181), intraop 256x256x60 at 0.9375x0.9375x2.5 mm
  Small  ///< preop 2 mm, intraop 96x96x30 at 2.5x2.5x5 mm: seconds, for tests
};

enum class CraniotomySite { RightFrontal, LeftFrontal, RightParietal, LeftParietal, Vertex };

/// The intraoperative scanner's contrast, as a map of the preoperative T1 intensity through the
/// tissue means (CSF, grey, white, fat): T1 (a gamma of 0.85, the default), low-field T1 (grey,
/// white and CSF closer together), T2-weighted (fluid bright, white matter dark), FLAIR (fluid
/// suppressed, grey brighter than white), T1 post-contrast (the T1 map, and what takes up the agent
/// enhances strongly: a tumour's rim, the tissue lining a resection cavity, the dura around the
/// craniotomy).
enum class IntraopContrast { T1, LowFieldT1, T2, Flair, T1PostContrast };

/// How the tumour looks in the preoperative (post-contrast T1) scan.
enum class TumourAppearance {
  RimEnhancing,     ///< hypointense core, enhancing rim (the default)
  Hypointense,      ///< dark throughout, no rim
  NearlyIsointense  ///< within a few per cent of the surrounding parenchyma
};

/// Where the truth deformation comes from: the kinematic subsidence (analytic, fast), or a finite
/// element solution by CalculiX on another mesher's quadratic tetrahedra, with the skull base fixed
/// and the brain surface outside the craniotomy sliding along the skull (FiniteElementTruth.h):
/// neither is BrainShift's own model.
enum class TruthModel { Kinematic, FiniteElementSliding };

/// What fills the space the brain sank away from under the skull.
enum class GapContent {
  Dark,        ///< one dark value (0.6 of CSF), the default
  FluidAndAir  ///< CSF-like fluid with an air-fluid level set by gravity: air above, fluid below
};
/// What the intraoperative scan covers: the whole head (the default), or a slab of axial slices
/// around the craniotomy (30 slices of 2.5 mm, 15 of 5 mm for the small case: 75 mm), centred
/// between the craniotomy and the tumour so that both are inside; the rest of the head is not scanned.
enum class FieldOfView { WholeHead, Slab };

struct CaseParameters {
  CaseSize size = CaseSize::Full;
  std::uint64_t seed = 2000;
  double shiftMillimetres = 10.0;  ///< peak sinking of the brain surface under the craniotomy
  CraniotomySite craniotomy = CraniotomySite::RightFrontal;
  bool resection = true;           ///< the tumour is removed (a fluid-filled cavity) in the intraop scan
  std::array<double, 3> rotationDegrees{4.0, -3.0, 6.0};       ///< head in the scanner, about L, P, S
  std::array<double, 3> translationMillimetres{6.0, -8.0, 5.0};
  double noiseFraction = 0.03; ///< Rician noise sigma, as a fraction of the white matter intensity
  double biasStrength = 0.2;   ///< log-amplitude of the multiplicative bias field (0.2: about +-20 %)
  IntraopContrast contrast = IntraopContrast::T1;
  TumourAppearance tumourAppearance = TumourAppearance::RimEnhancing;
  /// How far the tumour's centre lies below the brain's surface at the craniotomy's centre, along
  /// the craniotomy's axis (its semi-axis that way is 10 mm: at 22 mm its top is 12 mm deep; at 13
  /// mm it reaches the cortex, which keeps its outer 3 mm).
  double tumourDepthMm = 22.0;
  GapContent gap = GapContent::Dark;
  /// FluidAndAir: the share of the gap (and of the cavity) below the air-fluid level, by volume.
  double gapFluidFraction = 0.6, cavityFluidFraction = 0.8;
  /// The patient's head is tilted this far (degrees) from "craniotomy straight up": gravity is the
  /// inward craniotomy axis tilted towards the patient's posterior (FluidAndAir only).
  double gravityTiltDegrees = 20.0;
  /// A bright rim (blood products, 1.5 mm) on the wall of the resection cavity.
  bool cavityRim = false;
  TruthModel truth = TruthModel::Kinematic;
  FieldOfView fieldOfView = FieldOfView::WholeHead;
  std::filesystem::path templateFolder = "/usr/share/mricron/templates";

  /// InputError naming the option for values outside what the model means.
  void validate() const;
};

std::string toString(CraniotomySite site);
/// "right-frontal", ... ; InputError listing the choices otherwise.
CraniotomySite craniotomySiteFromString(const std::string& text);
std::string toString(IntraopContrast contrast);   ///< "t1", "low-field-t1", "t2", "flair", "t1-post-contrast"
IntraopContrast intraopContrastFromString(const std::string& text);
std::string toString(TumourAppearance appearance); ///< "rim-enhancing", "hypointense", "nearly-isointense"
TumourAppearance tumourAppearanceFromString(const std::string& text);
std::string toString(TruthModel truth);            ///< "kinematic", "finite-element-sliding"
TruthModel truthModelFromString(const std::string& text);
std::string toString(GapContent gap);              ///< "dark", "fluid-and-air"
GapContent gapContentFromString(const std::string& text);
std::string toString(FieldOfView fieldOfView);     ///< "whole-head", "slab"
FieldOfView fieldOfViewFromString(const std::string& text);

/// A named variant of the built-in case: the hard scenarios that real surgery brings (fluid and
/// air under the craniotomy, another scanner's contrast, tumours resected or not and of every
/// look, a bright cavity rim, shifts of 5 to 20 mm at four craniotomy sites, strong noise and
/// bias, a large misalignment), each deterministic from its seed.
struct CaseScenario {
  std::string name;
  std::string description;
  CaseParameters parameters; ///< at full size; the caller sets `size`
};
/// The catalogue, "default" (the built-in case as it always was) first.
const std::vector<CaseScenario>& caseScenarios();
/// InputError listing the names for an unknown one.
const CaseScenario& caseScenario(const std::string& name);

/// Figures of the simulated case, for case.json and the tests.
struct CaseFigures {
  PhysicalPoint craniotomyCentre;   ///< on the preop brain surface, LPS
  std::array<double, 3> craniotomyAxis{}; ///< outward unit vector, LPS
  PhysicalPoint tumourCentre;
  double tumourVolumeMl = 0, ventricleVolumeMl = 0, brainVolumeMl = 0;
  double maxBrainDisplacementMm = 0;  ///< largest |w| over the deformed brain
  double gapVolumeMl = 0;             ///< the gap between skull and sunken brain
  double gapAirMl = 0, cavityAirMl = 0; ///< of which air (FluidAndAir)
  double cavityVolumeMl = 0;
  double brainInFieldOfViewMl = 0;    ///< of the deformed brain, inside the intraoperative grid
  double minJacobianDeterminant = 0;  ///< of x' -> x' + w(x') over the brain; > 0: no folding
  double decayLengthMm = 0, lateralSigmaMm = 0;
  /// The finite element truth: nodes, quadratic elements, CalculiX's seconds, folded elements.
  std::size_t truthNodes = 0, truthElements = 0, truthFoldedElements = 0;
  double truthSolverSeconds = 0;
};

struct SimulatedCase {
  ScalarImage::Pointer preopImage;
  LabelImage::Pointer preopLabels;   ///< 0 background, 1 head, 2 parenchyma, 3 ventricles, 4 tumour
  ScalarImage::Pointer preopFmri;    ///< a t-statistic map on its own 3 mm grid
  ScalarImage::Pointer intraopImage;
  LabelImage::Pointer intraopLabels; ///< the truth; the gap, the cavity and the bone flap are 0
  SpatialTransform::Pointer intraopToPreop;      ///< the truth: the subsidence field after the rigid part
  SpatialTransform::Pointer rigidIntraopToPreop; ///< the rigid part alone
  /// "brain-", "craniotomy-", "near-cavity-" (within 10 mm of a resection cavity), "tumour-margin-"
  /// (within 8 mm of the boundary of a tumour left in place) and "head-" pairs
  std::vector<LandmarkPair> landmarks;
  CaseFigures figures;
};

/// Builds the case. InputError if the template is missing or the parameters are invalid.
SimulatedCase simulateCase(const CaseParameters& parameters);

/// A truth that folds (its Jacobian determinant not positive somewhere in the brain) is
/// ill-defined where it folds: the inverted field carries preoperative brain where there is none
/// (lp15-fe-superficial-intact: pieces of "brain" in the gap under the craniotomy), and figures
/// against it there measure the fold as well as the update. The warning that says so, with the
/// figures (and the finite elements the linear solve inverted); none for a truth that does not
/// fold (rf10-fe-sliding: 15 elements inverted, the field's determinant at least 0.20).
std::optional<std::string> foldedTruthWarning(const CaseFigures& figures);

/// Where a case's files are, inside its folder.
struct CaseFiles {
  explicit CaseFiles(const std::filesystem::path& folder);
  std::filesystem::path folder, preopImage, preopLabels, preopFmri, intraopImage, landmarks,
    truthIntraopLabels, truthTransform, truthRigidTransform, description;
};

/// Writes every file of CaseFiles (atomically) and case.json with the parameters and figures.
void writeCase(const SimulatedCase& simulated, const CaseParameters& parameters, const std::filesystem::path& folder);

} // namespace brainshift
