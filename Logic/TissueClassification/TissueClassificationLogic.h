#pragma once
// Intraoperative tissue classification (Warfield et al. 2000): k-nearest-neighbour classification
// of a multichannel feature, the intraoperative intensity together with an explicit spatial model
// of each tissue: the saturated distance to that tissue in the preoperative label map, brought onto
// the intraoperative grid through the rigid transform. Prototype voxels are chosen once, their
// positions (intraoperative scanner frame, LPS) recorded, and re-sampled on every later scan.
//
// What the rigid prior cannot know, the intensity decides and a clean-up settles: thick fluid
// (the gap under the craniotomy, the resection cavity) is outside the brain unless it is where the
// ventricles are; a tumour whose prototypes look like fluid has been resected.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"
#include "TransformIO.h"

#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace brainshift {

/// A prototype voxel: a named position (intraoperative LPS) known to show one tissue.
struct TissuePrototype {
  std::string name;
  LabelPixel label = 0;
  PhysicalPoint position;
};

/// What the classification derives from the preoperative labels alone: the tissues present and
/// each one's signed distance map (about 2 mm). The same for every scan of a case, so a session
/// (brainshift watch) computes it once.
class PreoperativeTissueMaps;
std::shared_ptr<const PreoperativeTissueMaps> preparePreoperativeTissueMaps(const LabelImage& preopLabels);

/// Whether the tumour of the preoperative labels has been resected: decided from the image
/// (Auto), or told by the user who knows (`--tumour-resected yes|no`).
enum class TumourResection { Auto, Resected, InPlace };
std::string toString(TumourResection decision); ///< "auto", "yes", "no"
TumourResection tumourResectionFromString(const std::string& text); ///< InputError for others

/// The preoperative tumour's intensity relative to the preoperative fluid (0) and parenchyma (1),
/// medians over the labels (a hypointense tumour about 0.3, an enhancing one near or above 1);
/// NaN without a tumour or ventricles.
double preoperativeTumourContrast(const ScalarImage& preopImage, const LabelImage& preopLabels);

/// The medians of the preoperative image over the ventricles (fluid) and the parenchyma; NaN where
/// a tissue is missing.
struct PreoperativeFluidAndParenchyma {
  double fluid = std::numeric_limits<double>::quiet_NaN();
  double parenchyma = std::numeric_limits<double>::quiet_NaN();
};

/// The preoperative image as the classification reads it: through the rigid transform (also when
/// the spatial prior is the refine pass's warped labels), tissue where a value is nearer the
/// preoperative parenchyma's median than the ventricles'.
struct PreoperativeImageLook {
  ScalarImage::ConstPointer image;
  SpatialTransform::ConstPointer intraopToPreop;
  PreoperativeFluidAndParenchyma medians;
};

/// What the resection decision saw: the medians of the intraoperative intensity (0-100 scale) at
/// the tumour's, the ventricles' and the parenchyma's prototypes, the tumour's place between fluid
/// (0) and parenchyma (1) now and before surgery, the shares of the tumour's prototypes nearest the
/// fluid, the tumour's own expected intensity and the parenchyma, and who decided.
struct TumourResectionEvidence {
  double tumourMedian = 0, fluidMedian = 0, parenchymaMedian = 0;
  double airMedian = std::numeric_limits<double>::quiet_NaN(); ///< the background's prototypes: air
  double intraopRelative = 0, preopRelative = 0;
  double fluidLikeShare = 0, tumourLikeShare = 0, parenchymaLikeShare = 0;
  double airLikeShare = 0; ///< of the fluid-like share, those nearer the air than the fluid
  std::size_t voxels = 0; ///< the intensities that voted (the tumour's prototypes, or its voxels)
  std::string decidedBy; ///< "image" or "user"; empty without a tumour
};

/// This scan's contrast as its prototypes learned it: the medians (0-100 scale) of the background
/// (air), the ventricles (fluid) and the parenchyma. Every intensity rule of the classification is
/// stated through them, not through a T1 order: fluid is dark in T1 and FLAIR, bright in T2; air is
/// dark in all. NaN for a class without prototypes.
struct ScanContrast {
  double air = std::numeric_limits<double>::quiet_NaN();
  double fluid = std::numeric_limits<double>::quiet_NaN();
  double parenchyma = std::numeric_limits<double>::quiet_NaN();
  /// Nearer this scan's fluid or air than its parenchyma (T1: darker than halfway to the parenchyma).
  bool looksLikeFluidOrAir(double intensity) const;
  bool fluidBrighterThanParenchyma() const; ///< T2-like
};
/// The medians of the prototypes' intensities per label (0 background, 2 parenchyma, 3 ventricles).
ScanContrast scanContrastOf(const std::map<LabelPixel, std::vector<float>>& prototypeIntensity);

/// The tumour's evidence from its intraoperative intensities (0-100 scale): each votes for fluid
/// (or air), the tumour as it looked before surgery (`preopRelative`: its place between fluid (0)
/// and parenchyma (1) then; NaN: the parenchyma), or the parenchyma.
TumourResectionEvidence tumourResectionEvidenceOf(const std::vector<float>& tumourIntensities, const ScanContrast& contrast,
                                                  double preopRelative, TumourResection told);
/// Resected or not, as the evidence says (or as `told`, when not Auto).
bool decideTumourResection(const TumourResectionEvidence& evidence, TumourResection told);
/// How the classification's warning of a resection it found by the image begins.
constexpr const char* TumourLooksResectedWarning = "classify: the tumour looks resected";
/// The evidence of the tumour's voxels where a solve put it, after a first classification found the
/// tumour in place through the rigid prior. Under a large shift that prior's tumour site holds the
/// parenchyma that sank into it; where the solve put the tumour, a cavity shows. Resected when air
/// shows in it (5 %) and, for a tumour with its own look, the vote says so: a cavity under an open
/// craniotomy holds air at its top, no tumour does, while a necrotic or cystic tumour's core looks
/// like fluid (measured on the built-in scenarios, 144 runs: 8.4-16.8 % air where the tumour was
/// resected, at most 2.2 % where it was not; fluid-like 34-81 % resected, up to 34 % in place,
/// 49-51 % in T2). For a tumour that looked like the parenchyma the air decides alone: its vote
/// cannot tell it from the tissue that sank into its place, and resected tumours only just reached
/// the first look's 35 % of fluid (rf15-cavityrim 35 %, the small case 27.5 %). A tumour with its
/// own look must also look more like fluid than like itself: one beside the gap's air is kept. A
/// cavity filled with saline alone is not told from a cystic tumour: it stays in place unless the
/// user says otherwise.
bool resectionShownWhereSolved(const TumourResectionEvidence& whereSolved);
/// The evidence of the tumour's voxels where a solve put it, after a first classification found the
/// tumour resected through the rigid prior. A tumour near the cortex sinks with the brain: under a
/// large shift its place through the rigid prior holds the gap's fluid, and it looks resected there.
/// In place when no cavity shows where the solve put it: the scan's air known, less of it than a
/// cavity holds (the 5 % of resectionShownWhereSolved), less than 20 % like fluid (a cavity shows
/// 34-81 %; the tumours near the cortex that sank, 0.7-17 % in the probes of the built-in cases),
/// and the vote for in place (decideTumourResection).
bool tumourShownInPlaceWhereSolved(const TumourResectionEvidence& whereSolved);

/// The intensity channel's 0-100 scale: 0 and 100 are these values of the intraoperative image
/// (its 1st and 99th percentiles over the head).
struct IntensityScale {
  double low = 0, high = 100;
  float of(double value) const { return float((value - low) * (high > low ? 100.0 / (high - low) : 1.0)); }
};

struct TissueClassificationParameters {
  /// Polled between the phases and every 65,536 voxels of the k-NN: CancelledError when set.
  CancelFlag cancel = nullptr;
  /// Prepared from the very labels given to classifyTissues (else std::invalid_argument); null:
  /// computed there.
  std::shared_ptr<const PreoperativeTissueMaps> preoperativeMaps;
  unsigned k = 7;
  double saturationMm = 10.0;          ///< spatial channels: distance to each tissue, capped here
  double intensityWeight = 1.0;        ///< intensity channel, scaled to 0..100 over the head
  double spatialWeight = 1.0;          ///< per mm of distance
  unsigned prototypesPerClass = 150;   ///< automatic choice
  double prototypeErosionMm = 3.0;     ///< automatic choice: this far inside the (aligned) tissue
  bool biasCorrection = false;         ///< N4 under a head mask before the intensity is used
  double fluidOpeningMm = 2.0;         ///< fluid thicker than this is a gap or a cavity, not a sulcus
  /// The fluid's thickness is measured over what the k-NN calls brain and, besides, over the aligned
  /// preoperative brain (true; not where the fluid is brighter than the parenchyma, T2); or over
  /// what the k-NN calls brain alone (false: a gap whose shallow part the k-NN gave to the head is
  /// left a thin sheet, and stays brain).
  bool fluidThicknessInAlignedBrain = true;
  /// A tumour decided in place: what the k-NN calls tumour but looks more like this scan's fluid or
  /// air than the tumour did before surgery may be fluid (true); or all of it is tissue (false: the
  /// gap's or cavity's fluid the k-NN gave to a tumour wrongly kept stays brain).
  bool tumourFluidByLook = true;
  double smallHoleMl = 0.5;            ///< holes in the brain smaller than this are filled
  /// Where given, a gap or a cavity (thick fluid given to the background) takes the fluid it reaches
  /// through fluid within gapReachMm (the path's length in mm, at least one voxel step each way),
  /// where the preoperative image showed tissue: the sheet of fluid pooled over a sunken brain,
  /// which 2.5 mm slices leave too thin for the opening, and which was brain before it sank. Fluid
  /// that was fluid before surgery (sulci, cisterns) stays brain, and so do the ventricles (moved,
  /// they lie where tissue was). Empty, or where the scan's fluid is brighter than its parenchyma
  /// (T2: the cortex with its CSF looks like fluid there): no growth.
  std::optional<PreoperativeImageLook> preopLook;
  double gapReachMm = 6.0;
  /// The reach around a resected tumour (within saturationMm of where the spatial prior puts it: the
  /// rigid prior, or in a refine pass the warped labels): the cavity and the gap are one body of
  /// fluid there, and a long reach takes the tissue around the cavity.
  double cavityReachMm = 3.0;
  std::uint64_t seed = 2000;
  TumourResection tumourResection = TumourResection::Auto;
  /// preoperativeTumourContrast of the case; NaN: the tumour is compared with fluid and parenchyma alone.
  double preopTumourContrast = std::numeric_limits<double>::quiet_NaN();
  void validate() const;
};

struct Configuration;
/// The classification's parameters from the one configuration (k, saturation, N4, the resection
/// decision); every front end takes them from here.
TissueClassificationParameters classificationParametersFrom(const Configuration& configuration);

/// What the preoperative image tells the classification, set on `parameters`: the tumour's look
/// before surgery (preopTumourContrast) and where tissue was (preopLook, through `intraopToPreop`).
/// Every front end that has the preoperative image calls it. The labels may lie on another grid
/// than the image (the image is then interpolated at their voxels).
void takePreoperativeImage(TissueClassificationParameters& parameters, const ScalarImage& preopImage,
                           const LabelImage& preopLabels, const SpatialTransform& intraopToPreop);

struct TissueClassificationResult {
  LabelImage::Pointer labels;                ///< on the intraoperative grid, the contract's labels
  std::vector<TissuePrototype> prototypes;   ///< the ones used (record them for the next scan)
  std::map<LabelPixel, unsigned> prototypesPerClass;
  bool tumourResected = false;               ///< the tumour's prototypes look like fluid (or the user said so)
  TumourResectionEvidence tumourEvidence;
  ScanContrast contrast;                     ///< what the prototypes learned of this scan's contrast
  IntensityScale intensityScale;             ///< of the intensity channel (after N4 when asked)
  double featureSeconds = 0, knnSeconds = 0, cleanupSeconds = 0;
  std::size_t voxels = 0;
  std::size_t knnQueries = 0;                ///< voxels that needed a tree query (the rest shared an answer)
  double fluidJoinedToGapsMl = 0;            ///< brain-labelled fluid a gap or cavity took (preopImage)
  Warnings warnings;
};

/// Classifies `intraop`. `rigidIntraopToPreop` aligns `preopLabels` with it. Prototypes: when
/// `given` is set they are used (and checked: inside the image, known labels, enough per class,
/// k not above any class's count), else they are chosen from the aligned labels' interiors.
TissueClassificationResult classifyTissues(const ScalarImage& intraop, const LabelImage& preopLabels,
                                           const SpatialTransform& rigidIntraopToPreop,
                                           const std::optional<std::vector<TissuePrototype>>& given,
                                           const TissueClassificationParameters& parameters);

/// Prototype files: JSON {"frame": "intraop", "prototypes": [{"name", "label", "position"}]},
/// or a 3D Slicer .mrk.json whose point names start with the label ("2", "2-07") or tissue name
/// ("parenchyma-07", "ventricles", "tumour-1", "head", "background"). LPS.
std::vector<TissuePrototype> readPrototypes(const std::filesystem::path& path);
void writePrototypes(const std::vector<TissuePrototype>& prototypes, const std::filesystem::path& path);

/// "background", "head", "parenchyma", "ventricles", "tumour", or the number.
std::string tissueName(LabelPixel label);

} // namespace brainshift
