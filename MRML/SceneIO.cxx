#include "SceneIO.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "MarkupsIO.h"
#include "ModelIO.h"
#include "VolumeIO.h"

#include <vtkCellData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLDataParser.h>

#include <cmath>
#include <iomanip>
#include <limits>
#include <map>
#include <set>
#include <sstream>

namespace brainshift {
namespace fs = std::filesystem;

namespace {

constexpr const char* RoleAttribute = "BrainShift.Role";
constexpr const char* PairsAttribute = "BrainShift.LandmarkPairs"; // the LandmarksNode a point list belongs to
constexpr const char* SideAttribute = "BrainShift.LandmarkSide";   // "preop" or "intraop"

// ---- XML writing ------------------------------------------------------------------------
std::string xmlEscape(const std::string& text)
{
  std::string out;
  for (char c : text) {
    switch (c) {
    case '&': out += "&amp;"; break;
    case '"': out += "&quot;"; break;
    case '\'': out += "&apos;"; break;
    case '<': out += "&lt;"; break;
    case '>': out += "&gt;"; break;
    default: out += c;
    }
  }
  return out;
}

/// Slicer URL-decodes file names: a literal '%' must be written "%25".
std::string encodeFileName(const std::string& name)
{
  std::string out;
  for (char c : name) out += (c == '%') ? std::string("%25") : std::string(1, c);
  return out;
}

std::string decodeFileName(const std::string& name)
{
  static const std::map<std::string, char> codes = {{"%20", ' '}, {"%22", '"'}, {"%25", '%'},
                                                    {"%27", '\''}, {"%3C", '<'}, {"%3E", '>'}};
  std::string out;
  for (std::size_t i = 0; i < name.size(); ++i) {
    if (name[i] == '%' && i + 2 < name.size()) {
      auto code = codes.find(name.substr(i, 3));
      if (code != codes.end()) {
        out += code->second;
        i += 2;
        continue;
      }
    }
    out += name[i];
  }
  return out;
}

/// Slicer's "attributes": "key:value;key:value", with '%' and ';' escaped in values.
std::string encodeAttributes(const std::map<std::string, std::string>& attributes)
{
  std::string out;
  for (const auto& [key, value] : attributes) {
    std::string escaped;
    for (char c : value) {
      if (c == '%') escaped += "%25";
      else if (c == ';') escaped += "%3B";
      else escaped += c;
    }
    out += key + ":" + escaped + ";";
  }
  return out;
}

std::map<std::string, std::string> decodeAttributes(const std::string& text)
{
  std::map<std::string, std::string> attributes;
  std::istringstream in(text);
  std::string item;
  while (std::getline(in, item, ';')) {
    const auto colon = item.find(':');
    if (colon == std::string::npos) continue;
    std::string value = item.substr(colon + 1);
    std::string decoded;
    for (std::size_t i = 0; i < value.size(); ++i) {
      if (value.compare(i, 3, "%3B") == 0) { decoded += ';'; i += 2; }
      else if (value.compare(i, 3, "%25") == 0) { decoded += '%'; i += 2; }
      else decoded += value[i];
    }
    attributes[item.substr(0, colon)] = decoded;
  }
  return attributes;
}

std::string formatNumber(double value)
{
  std::ostringstream s;
  s << std::setprecision(std::numeric_limits<double>::max_digits10) << value;
  return s.str();
}

class Element {
public:
  explicit Element(std::string tag) : tag_(std::move(tag)) {}
  Element& set(const std::string& name, const std::string& value)
  {
    attributes_.emplace_back(name, value);
    return *this;
  }
  Element& set(const std::string& name, double value) { return set(name, formatNumber(value)); }
  Element& set(const std::string& name, bool value) { return set(name, std::string(value ? "true" : "false")); }
  Element& set(const std::string& name, const char* value) { return set(name, std::string(value)); }
  std::string str() const
  {
    std::string out = " <" + tag_;
    for (const auto& [name, value] : attributes_) out += "\n  " + name + "=\"" + xmlEscape(value) + "\"";
    return out + " ></" + tag_ + ">\n";
  }

private:
  std::string tag_;
  std::vector<std::pair<std::string, std::string>> attributes_;
};

std::string sanitizedFileStem(const std::string& name)
{
  std::string stem;
  for (unsigned char c : name) stem += (std::isalnum(c) || c == '-' || c == '_' || c == '.') ? static_cast<char>(c) : '_';
  return stem.empty() ? std::string("node") : stem;
}

std::string vectorString(const std::array<double, 3>& v)
{
  return formatNumber(v[0]) + " " + formatNumber(v[1]) + " " + formatNumber(v[2]);
}

/// 16 row-major numbers: the RAS matrix that takes child coordinates to the parent, for a node
/// whose transform from parent (LPS) is `fromParent`.
std::string matrixTransformToParent(const SpatialTransform* fromParent)
{
  const AffineParameters p = affineParametersOf(fromParent);
  // RAS form of the LPS transform: D T D with D = diag(-1, -1, 1).
  const double d[3] = {-1, -1, 1};
  double m[3][3], t[3];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m[r][c] = d[r] * p.matrix[r][c] * d[c];
    t[r] = d[r] * p.translation[r];
  }
  // Inverse of [m t; 0 1]: [m^-1, -m^-1 t].
  const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                     m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  if (std::abs(det) < 1e-12) throw std::invalid_argument("a linear transform with a singular matrix");
  double inv[3][3];
  inv[0][0] = (m[1][1] * m[2][2] - m[1][2] * m[2][1]) / det;
  inv[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det;
  inv[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det;
  inv[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) / det;
  inv[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det;
  inv[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det;
  inv[2][0] = (m[1][0] * m[2][1] - m[1][1] * m[2][0]) / det;
  inv[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det;
  inv[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det;
  std::string out;
  for (int r = 0; r < 3; ++r) {
    double translation = 0;
    for (int c = 0; c < 3; ++c) {
      out += formatNumber(inv[r][c]) + " ";
      translation -= inv[r][c] * t[c];
    }
    out += formatNumber(translation) + " ";
  }
  return out + "0 0 0 1";
}

struct WriteContext {
  fs::path sceneFolder;
  fs::path dataFolder;
  std::set<std::string> usedStems;
  int storageCounter = 0;
  int displayCounter = 0;

  fs::path newDataFile(const std::string& name, const std::string& extension)
  {
    std::string stem = sanitizedFileStem(name);
    std::string candidate = stem;
    for (int i = 1; usedStems.count(candidate + extension); ++i) candidate = stem + "_" + std::to_string(i);
    usedStems.insert(candidate + extension);
    return dataFolder / (candidate + extension);
  }

  std::string relative(const fs::path& file) const
  {
    return encodeFileName(
      fs::absolute(file).lexically_normal().lexically_relative(fs::absolute(sceneFolder).lexically_normal()).generic_string());
  }
};

std::string dataExtension(const Node& node)
{
  switch (node.kind()) {
  case NodeKind::ScalarVolume:
  case NodeKind::LabelMapVolume: return ".nii.gz";
  case NodeKind::Model: return static_cast<const ModelNode&>(node).isVolumetric() ? ".vtu" : ".vtp";
  case NodeKind::Transform:
    switch (static_cast<const TransformNode&>(node).type()) {
    case TransformNode::Type::Linear: return ".tfm";
    case TransformNode::Type::DisplacementField: return ".nrrd";
    case TransformNode::Type::Composite: return ".h5";
    }
    break;
  case NodeKind::Landmarks: return ".mrk.json";
  }
  return "";
}

void writeNodeData(Node& node, const fs::path& file)
{
  switch (node.kind()) {
  case NodeKind::ScalarVolume: writeScalarVolume(static_cast<ScalarVolumeNode&>(node).image(), file); break;
  case NodeKind::LabelMapVolume: writeLabelVolume(static_cast<LabelMapVolumeNode&>(node).image(), file); break;
  case NodeKind::Model: writeModel(static_cast<ModelNode&>(node).mesh(), file); break;
  case NodeKind::Transform: writeTransform(static_cast<TransformNode&>(node).transformFromParent(), file); break;
  case NodeKind::Landmarks: break; // written as two point lists by the caller
  }
}

bool hasData(const Node& node)
{
  switch (node.kind()) {
  case NodeKind::ScalarVolume: return static_cast<const ScalarVolumeNode&>(node).image() != nullptr;
  case NodeKind::LabelMapVolume: return static_cast<const LabelMapVolumeNode&>(node).image() != nullptr;
  case NodeKind::Model: return static_cast<const ModelNode&>(node).mesh() != nullptr;
  case NodeKind::Transform: return static_cast<const TransformNode&>(node).transformFromParent() != nullptr;
  case NodeKind::Landmarks: return true;
  }
  return false;
}

std::string referencesOf(const std::string& displayId, const std::string& storageId, const std::string& transformId)
{
  std::string refs;
  if (!displayId.empty()) refs += "display:" + displayId + ";";
  if (!storageId.empty()) refs += "storage:" + storageId + ";";
  if (!transformId.empty()) refs += "transform:" + transformId + ";";
  return refs;
}

Element commonElement(const char* tag, const std::string& id, const std::string& name,
                      const std::map<std::string, std::string>& attributes, const std::string& references)
{
  Element e(tag);
  e.set("id", id).set("name", name).set("hideFromEditors", false).set("selectable", true).set("selected", false);
  if (!attributes.empty()) e.set("attributes", encodeAttributes(attributes));
  e.set("references", references);
  return e;
}

std::map<std::string, std::string> attributesWithRole(const Node& node)
{
  auto attributes = node.attributes();
  if (!node.role().empty()) attributes[RoleAttribute] = node.role();
  return attributes;
}

void writeVolumeDisplay(std::string& xml, const std::string& tag, const std::string& id, const VolumeDisplay& display)
{
  Element e(tag);
  e.set("id", id).set("name", tag).set("hideFromEditors", true).set("visibility", true).set("opacity", display.opacity);
  e.set("colorNodeID", slicerColorNodeId(display.colorTable));
  if (tag == "VolumeDisplay") {
    const bool manual = display.window && display.level;
    e.set("autoWindowLevel", manual ? "0" : "1").set("interpolate", "1");
    if (manual) e.set("window", *display.window).set("level", *display.level);
    const bool threshold = display.lowerThreshold || display.upperThreshold;
    e.set("applyThreshold", threshold ? "1" : "0").set("autoThreshold", "0");
    if (display.lowerThreshold) e.set("lowerThreshold", *display.lowerThreshold);
    if (display.upperThreshold) e.set("upperThreshold", *display.upperThreshold);
  }
  xml += e.str();
}

std::string storageElement(const char* tag, const std::string& id, const std::string& fileName, bool coordinateSystem)
{
  Element e(tag);
  e.set("id", id).set("name", tag).set("hideFromEditors", true).set("fileName", fileName).set("useCompression", "1");
  if (coordinateSystem) e.set("coordinateSystem", "LPS");
  return e.str();
}

/// Landmark pairs are measured truth: locked in the scene and in their .mrk.json files alike (Slicer
/// applies the file's lock over the scene's), so a click in a view cannot move them.
constexpr bool LandmarkPairsLocked = true;

/// The layout node (Four-Up) and the slice composite nodes of the Red, Yellow and Green views, as
/// 3D Slicer 5 writes them (vtkMRMLLayoutNode, vtkMRMLSliceCompositeNode): the views show these
/// volumes on load. The volume references are written both as `references` roles (Slicer 5) and as
/// the legacy `backgroundVolumeID` attributes (Slicer 4), which Slicer 5 reads when the role is absent.
/// Nothing when the scene has no layers; a layer whose volume has no data (not written) is empty.
std::string sliceViewElements(const Scene& scene)
{
  SliceViewLayers layers = scene.sliceViewLayers();
  for (std::string* id : {&layers.backgroundVolumeId, &layers.foregroundVolumeId, &layers.labelVolumeId}) {
    if (!id->empty() && !hasData(*scene.node(*id))) id->clear();
  }
  if (layers.empty()) return "";
  Element layout("Layout");
  layout.set("id", "vtkMRMLLayoutNodevtkMRMLLayoutNode").set("name", "Layout").set("hideFromEditors", true);
  layout.set("singletonTag", "vtkMRMLLayoutNode").set("currentViewArrangement", "3"); // SlicerLayoutFourUpView
  std::string xml = layout.str();
  std::string references;
  const std::pair<const char*, const std::string*> roles[] = {{"backgroundVolume", &layers.backgroundVolumeId},
                                                              {"foregroundVolume", &layers.foregroundVolumeId},
                                                              {"labelVolume", &layers.labelVolumeId}};
  for (const auto& [role, id] : roles) {
    if (!id->empty()) references += std::string(role) + ":" + *id + ";";
  }
  for (const char* view : {"Red", "Yellow", "Green"}) {
    Element composite("SliceComposite");
    composite.set("id", std::string("vtkMRMLSliceCompositeNode") + view).set("name", "SliceComposite");
    composite.set("hideFromEditors", true).set("singletonTag", view).set("references", references);
    for (const auto& [role, id] : roles) composite.set(std::string(role) + "ID", *id);
    composite.set("compositing", "0").set("foregroundOpacity", layers.foregroundOpacity);
    composite.set("labelOpacity", layers.labelOpacity).set("fiducialVisibility", "1").set("fiducialLabelVisibility", "1");
    composite.set("layoutName", view).set("doPropagateVolumeSelection", "1");
    xml += composite.str();
  }
  return xml;
}

/// A landmark pair set as two point lists ("<name>_preop", "<name>_intraop"), each a .mrk.json file
/// and its MarkupsFiducial, display and storage elements. The preoperative points live in the
/// preoperative frame, under the node's transform.
std::string landmarkListElements(LandmarksNode& node, const std::string& transformId, WriteContext& context)
{
  std::string xml;
  for (const char* side : {"preop", "intraop"}) {
    const bool preop = std::string(side) == "preop";
    std::vector<NamedPoint> points;
    for (const LandmarkPair& pair : node.pairs()) points.push_back({pair.name, preop ? pair.preop : pair.intraop});
    const fs::path file = context.newDataFile(node.name() + "_" + side, ".mrk.json");
    writeMarkupsJson(points, file, LandmarkPairsLocked);
    const std::string listId = node.id() + (preop ? "_preop" : "_intraop");
    const std::string displayId = "vtkMRMLMarkupsDisplayNode" + std::to_string(++context.displayCounter);
    const std::string storageId = "vtkMRMLMarkupsJsonStorageNode" + std::to_string(++context.storageCounter);
    auto attributes = attributesWithRole(node);
    attributes[PairsAttribute] = node.name();
    attributes[SideAttribute] = side;
    Element list = commonElement("MarkupsFiducial", listId, node.name() + " " + side, attributes,
                                 referencesOf(displayId, storageId, preop ? transformId : ""));
    list.set("locked", LandmarkPairsLocked).set("controlPointLabelFormat", "%N-%d");
    xml += list.str();
    Element display("MarkupsDisplay");
    display.set("id", displayId).set("name", "MarkupsDisplay").set("hideFromEditors", true).set("visibility", true);
    display.set("color", preop ? "0.4 1 1" : "1 1 0.4").set("selectedColor", preop ? "0.2 0.8 1" : "1 0.8 0.2");
    display.set("pointLabelsVisibility", true); // each point shows its name
    xml += display.str();
    xml += storageElement("MarkupsJsonStorage", storageId, context.relative(file), true);
  }
  return xml;
}

} // namespace

std::string slicerColorNodeId(const std::string& colorTable)
{
  if (colorTable.rfind("vtkMRML", 0) == 0) return colorTable;
  static const std::map<std::string, std::string> ids = {
    {"Grey", "vtkMRMLColorTableNodeGrey"},
    {"Labels", "vtkMRMLColorTableNodeLabels"},
    {"GenericAnatomyColors", "vtkMRMLColorTableNodeFileGenericAnatomyColors.txt"},
    {"Rainbow", "vtkMRMLColorTableNodeRainbow"},
    {"ColdToHotRainbow", "vtkMRMLColorTableNodeFileColdToHotRainbow.txt"},
    {"Viridis", "vtkMRMLColorTableNodeFileViridis.txt"},
    {"Red", "vtkMRMLColorTableNodeRed"},
    {"RedGreenBlue", "vtkMRMLProceduralColorNodeRedGreenBlue"}};
  auto it = ids.find(colorTable);
  return it != ids.end() ? it->second : "vtkMRMLColorTableNodeGrey";
}

std::string colorTableFromSlicerId(const std::string& colorNodeId)
{
  for (const char* name : {"Grey", "Labels", "GenericAnatomyColors", "Rainbow", "ColdToHotRainbow", "Viridis", "Red", "RedGreenBlue"}) {
    if (slicerColorNodeId(name) == colorNodeId) return name;
  }
  return colorNodeId;
}

namespace {
/// The scene's folders; the file names its nodes already use are taken.
WriteContext writeContextFor(const Scene& scene, const fs::path& mrmlPath, const SceneWriteOptions& options)
{
  WriteContext context;
  context.sceneFolder = mrmlPath.has_parent_path() ? mrmlPath.parent_path() : fs::path(".");
  context.dataFolder = context.sceneFolder / options.dataFolder;
  fs::create_directories(context.dataFolder);
  for (const auto& node : scene.nodes()) {
    if (!node->storageFile().empty()) context.usedStems.insert(node->storageFile().filename().string());
  }
  return context;
}

/// Writes the node's data to a new file of the data folder unless its storage file is current.
void storeNodeData(Node& node, WriteContext& context)
{
  std::error_code ec;
  if (node.storageFile().empty() || node.dataModifiedSinceStorage() || !fs::exists(node.storageFile(), ec)) {
    const fs::path file = context.newDataFile(node.name(), dataExtension(node));
    writeNodeData(node, file);
    node.setStorageFile(fs::absolute(file));
  }
  node.markStored();
}

std::string modelDisplayElement(const ModelNode& model, const std::string& displayId)
{
  const ModelDisplay& d = model.display();
  Element display("ModelDisplay");
  display.set("id", displayId).set("name", "ModelDisplay").set("hideFromEditors", true);
  display.set("color", vectorString(d.color)).set("opacity", d.opacity).set("visibility", true);
  display.set("visibility2D", true).set("visibility3D", true).set("scalarVisibility", d.scalarVisibility);
  if (!d.activeScalarName.empty()) {
    const bool onCells = model.mesh() && !model.mesh()->GetPointData()->HasArray(d.activeScalarName.c_str()) &&
                         model.mesh()->GetCellData()->HasArray(d.activeScalarName.c_str());
    display.set("activeScalarName", d.activeScalarName).set("activeAttributeLocation", onCells ? "cell" : "point");
  }
  display.set("colorNodeID", slicerColorNodeId(d.colorTable));
  if (d.scalarRange) {
    display.set("scalarRangeFlag", "UseManual")
      .set("scalarRange", formatNumber((*d.scalarRange)[0]) + " " + formatNumber((*d.scalarRange)[1]));
  } else {
    display.set("scalarRangeFlag", "UseData");
  }
  return display.str();
}

std::string transformElements(const TransformNode& transform, const std::string& fileName, const std::string& storageId,
                              const std::string& transformId)
{
  const char* tag = transform.type() == TransformNode::Type::Linear ? "LinearTransform"
                    : transform.type() == TransformNode::Type::DisplacementField ? "GridTransform"
                                                                                 : "Transform";
  Element e = commonElement(tag, transform.id(), transform.name(), attributesWithRole(transform), referencesOf("", storageId, transformId));
  if (transform.type() == TransformNode::Type::Linear) {
    e.set("matrixTransformToParent", matrixTransformToParent(transform.transformFromParent()));
  }
  Element storage("TransformStorage");
  storage.set("id", storageId).set("name", "TransformStorage").set("hideFromEditors", true);
  storage.set("fileName", fileName).set("useCompression", "1").set("preferITKv3CompatibleTransforms", false);
  return e.str() + storage.str();
}

/// The MRML elements of a stored node (not landmarks): the node, its display, its storage.
std::string nodeElements(const Node& node, const std::string& fileName, const std::string& transformId)
{
  const std::string storageId = node.id() + "Storage";
  const std::string displayId = node.id() + "Display";
  std::string xml;
  switch (node.kind()) {
  case NodeKind::ScalarVolume:
    xml += commonElement("Volume", node.id(), node.name(), attributesWithRole(node), referencesOf(displayId, storageId, transformId)).str();
    writeVolumeDisplay(xml, "VolumeDisplay", displayId, static_cast<const ScalarVolumeNode&>(node).display());
    xml += storageElement("VolumeArchetypeStorage", storageId, fileName, false);
    break;
  case NodeKind::LabelMapVolume:
    xml += commonElement("LabelMapVolume", node.id(), node.name(), attributesWithRole(node),
                         referencesOf(displayId, storageId, transformId)).str();
    writeVolumeDisplay(xml, "LabelMapVolumeDisplay", displayId, static_cast<const LabelMapVolumeNode&>(node).display());
    xml += storageElement("VolumeArchetypeStorage", storageId, fileName, false);
    break;
  case NodeKind::Model:
    xml += commonElement("Model", node.id(), node.name(), attributesWithRole(node), referencesOf(displayId, storageId, transformId)).str();
    xml += modelDisplayElement(static_cast<const ModelNode&>(node), displayId);
    xml += storageElement("ModelStorage", storageId, fileName, true);
    break;
  case NodeKind::Transform:
    xml += transformElements(static_cast<const TransformNode&>(node), fileName, storageId, transformId);
    break;
  case NodeKind::Landmarks: break;
  }
  return xml;
}
} // namespace

void writeScene(Scene& scene, const fs::path& mrmlPath, const SceneWriteOptions& options)
{
  WriteContext context = writeContextFor(scene, mrmlPath, options);
  std::string xml = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<MRML  version=\"Slicer 5.2.2 31382\"  userTags=\"\">\n";
  for (const auto& nodePointer : scene.nodes()) {
    Node& node = *nodePointer;
    if (!hasData(node)) continue;
    const std::string transformId =
      !node.parentTransformId().empty() && scene.node(node.parentTransformId()) ? node.parentTransformId() : "";
    if (node.kind() == NodeKind::Landmarks) {
      xml += landmarkListElements(static_cast<LandmarksNode&>(node), transformId, context);
      node.markStored();
      continue;
    }
    storeNodeData(node, context);
    xml += nodeElements(node, context.relative(node.storageFile()), transformId);
  }
  xml += sliceViewElements(scene);
  xml += "</MRML>\n";
  writeTextFileAtomically(mrmlPath, xml);
}

// ---- Reading ------------------------------------------------------------------------------
namespace {

struct ParsedElement {
  std::string tag;
  std::map<std::string, std::string> attributes;
  std::string get(const std::string& name, const std::string& fallback = "") const
  {
    auto it = attributes.find(name);
    return it != attributes.end() ? it->second : fallback;
  }
  /// The ids of a reference role ("display", "storage", "transform"), from `references` or
  /// the legacy `<role>NodeRef`.
  std::vector<std::string> references(const std::string& role) const
  {
    std::vector<std::string> ids;
    std::istringstream in(get("references"));
    std::string item;
    bool found = false;
    while (std::getline(in, item, ';')) {
      const auto colon = item.find(':');
      if (colon == std::string::npos || item.substr(0, colon) != role) continue;
      found = true;
      std::istringstream list(item.substr(colon + 1));
      std::string id;
      while (list >> id) ids.push_back(id);
    }
    if (!found) {
      std::istringstream legacy(get(role + "NodeRef"));
      std::string id;
      while (legacy >> id) ids.push_back(id);
    }
    return ids;
  }
};

std::optional<double> optionalNumber(const ParsedElement& e, const std::string& name)
{
  const std::string text = e.get(name);
  if (text.empty()) return std::nullopt;
  try {
    return std::stod(text);
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

VolumeDisplay readVolumeDisplay(const ParsedElement* e, VolumeDisplay display)
{
  if (!e) return display;
  if (!e->get("colorNodeID").empty()) display.colorTable = colorTableFromSlicerId(e->get("colorNodeID"));
  if (auto opacity = optionalNumber(*e, "opacity")) display.opacity = *opacity;
  if (e->get("autoWindowLevel", "1") == "0") {
    display.window = optionalNumber(*e, "window");
    display.level = optionalNumber(*e, "level");
  }
  if (e->get("applyThreshold", "0") == "1") {
    display.lowerThreshold = optionalNumber(*e, "lowerThreshold");
    display.upperThreshold = optionalNumber(*e, "upperThreshold");
  }
  return display;
}

ModelDisplay readModelDisplay(const ParsedElement* e)
{
  ModelDisplay display;
  if (!e) return display;
  std::istringstream color(e->get("color"));
  std::array<double, 3> c{};
  if (color >> c[0] >> c[1] >> c[2]) display.color = c;
  if (auto opacity = optionalNumber(*e, "opacity")) display.opacity = *opacity;
  display.scalarVisibility = e->get("scalarVisibility") == "true";
  display.activeScalarName = e->get("activeScalarName");
  if (!e->get("colorNodeID").empty()) display.colorTable = colorTableFromSlicerId(e->get("colorNodeID"));
  if (e->get("scalarRangeFlag") == "UseManual") {
    std::istringstream range(e->get("scalarRange"));
    std::array<double, 2> r{};
    if (range >> r[0] >> r[1]) display.scalarRange = r;
  }
  return display;
}

/// The layers of the Red slice view, with the ids of the file; nothing when the file has none.
std::optional<SliceViewLayers> readSliceViewLayers(const std::map<std::string, ParsedElement>& byId)
{
  for (const auto& [id, e] : byId) {
    if (e.tag != "SliceComposite" || e.get("layoutName") != "Red") continue;
    auto volumeOf = [&e](const std::string& role) {
      const auto ids = e.references(role);
      return ids.empty() ? e.get(role + "ID") : ids.front();
    };
    SliceViewLayers layers;
    layers.backgroundVolumeId = volumeOf("backgroundVolume");
    layers.foregroundVolumeId = volumeOf("foregroundVolume");
    layers.labelVolumeId = volumeOf("labelVolume");
    if (auto opacity = optionalNumber(e, "foregroundOpacity")) layers.foregroundOpacity = *opacity;
    if (auto opacity = optionalNumber(e, "labelOpacity")) layers.labelOpacity = *opacity;
    return layers;
  }
  return std::nullopt;
}

/// A scene file's elements by id (in the file's order), and how its nodes' files are found.
struct ParsedScene {
  fs::path mrmlPath, sceneFolder;
  std::map<std::string, ParsedElement> byId;
  std::vector<std::string> order;

  /// The first of `ids` the file holds.
  const ParsedElement* find(const std::vector<std::string>& ids) const
  {
    for (const auto& id : ids) {
      auto it = byId.find(id);
      if (it != byId.end()) return &it->second;
    }
    return nullptr;
  }

  /// The node's storage file (relative to the scene's folder), which must exist.
  fs::path storageFileOf(const ParsedElement& e) const
  {
    const ParsedElement* storage = find(e.references("storage"));
    if (!storage || storage->get("fileName").empty()) {
      throw InputError(mrmlPath.string() + ": node '" + e.get("name") + "' (" + e.get("id") + ") has no storage file");
    }
    fs::path file = decodeFileName(storage->get("fileName"));
    if (file.is_relative()) file = sceneFolder / file;
    file = file.lexically_normal();
    std::error_code missing;
    if (!fs::exists(file, missing)) {
      throw InputError(mrmlPath.string() + ": node '" + e.get("name") + "' refers to " + file.string() +
                       ", which does not exist");
    }
    return file;
  }

  /// A data file's error, prefixed with the scene that refers to it.
  template <class Read>
  auto withSceneContext(Read&& read) const
  {
    try {
      return read();
    } catch (const InputError& error) {
      throw InputError(mrmlPath.string() + ": " + error.what());
    }
  }
};

ParsedScene parseScene(const fs::path& mrmlPath)
{
  std::error_code ec;
  if (!fs::is_regular_file(mrmlPath, ec)) {
    throw InputError(mrmlPath.string() + ": no such scene file");
  }
  vtkNew<vtkXMLDataParser> parser;
  parser->SetFileName(mrmlPath.c_str());
  parser->SetIgnoreCharacterData(1);
  if (!parser->Parse() || !parser->GetRootElement() || std::string(parser->GetRootElement()->GetName()) != "MRML") {
    throw InputError(mrmlPath.string() + ": not a MRML scene (no <MRML> root element, or malformed XML)");
  }
  vtkXMLDataElement* root = parser->GetRootElement();
  ParsedScene parsed;
  parsed.mrmlPath = mrmlPath;
  parsed.sceneFolder = mrmlPath.has_parent_path() ? mrmlPath.parent_path() : fs::path(".");
  for (int i = 0; i < root->GetNumberOfNestedElements(); ++i) {
    vtkXMLDataElement* xml = root->GetNestedElement(i);
    ParsedElement e;
    e.tag = xml->GetName();
    for (int a = 0; a < xml->GetNumberOfAttributes(); ++a) e.attributes[xml->GetAttributeName(a)] = xml->GetAttributeValue(a);
    const std::string id = e.get("id");
    if (id.empty()) continue;
    parsed.byId[id] = e;
    parsed.order.push_back(id);
  }
  return parsed;
}

/// What reading the elements gathers before anything is added to the scene.
struct SceneReading {
  std::vector<std::pair<std::string, std::shared_ptr<Node>>> loaded;                   // old id -> node
  std::map<std::string, std::string> parentOf;                                         // old id -> old parent transform id
  std::map<std::string, std::map<std::string, std::vector<NamedPoint>>> landmarkSides; // pairs name -> side -> points
  std::map<std::string, std::pair<std::string, std::string>> landmarkInfo;             // pairs name -> (old id, role)
};

bool isTransformTag(const std::string& tag)
{
  return tag == "LinearTransform" || tag == "GridTransform" || tag == "Transform" || tag == "BSplineTransform";
}

/// The volume, model or transform node an element describes, with its data read; null for other elements.
std::shared_ptr<Node> readDataNode(const ParsedScene& parsed, const ParsedElement& e, const std::string& name)
{
  std::shared_ptr<Node> node;
  if (e.tag == "Volume" || e.tag == "LabelMapVolume") {
    const fs::path file = parsed.storageFileOf(e);
    const ParsedElement* display = parsed.find(e.references("display"));
    if (e.tag == "Volume" && e.get("labelMap") != "1") {
      auto volume = ScalarVolumeNode::create(name, parsed.withSceneContext([&] { return readScalarVolume(file); }));
      volume->setDisplay(readVolumeDisplay(display, VolumeDisplay{}));
      node = volume;
    } else {
      auto labels = LabelMapVolumeNode::create(name, parsed.withSceneContext([&] { return readLabelVolume(file); }));
      labels->setDisplay(readVolumeDisplay(display, VolumeDisplay{"Labels", {}, {}, {}, {}, 1.0}));
      node = labels;
    }
    node->setStorageFile(fs::absolute(file));
  } else if (e.tag == "Model") {
    const fs::path file = parsed.storageFileOf(e);
    auto model = ModelNode::create(name, parsed.withSceneContext([&] { return readModel(file); }));
    model->setDisplay(readModelDisplay(parsed.find(e.references("display"))));
    model->setStorageFile(fs::absolute(file));
    node = model;
  } else if (isTransformTag(e.tag)) {
    const fs::path file = parsed.storageFileOf(e);
    auto transform = TransformNode::create(name, parsed.withSceneContext([&] { return readTransform(file); }));
    transform->setStorageFile(fs::absolute(file));
    node = transform;
  }
  return node;
}

/// One side of a landmark pair set (a MarkupsFiducial element with the pairs and side attributes;
/// other point lists are skipped): its points, and from the preoperative side the role and parent.
void readLandmarkSide(const ParsedScene& parsed, const std::string& id, const ParsedElement& e, SceneReading& reading)
{
  const fs::path file = parsed.storageFileOf(e);
  const auto attributes = decodeAttributes(e.get("attributes"));
  auto pairs = attributes.find(PairsAttribute);
  auto side = attributes.find(SideAttribute);
  if (pairs == attributes.end() || side == attributes.end()) return; // a point list that is not a pair set
  reading.landmarkSides[pairs->second][side->second] = parsed.withSceneContext([&] { return readMarkupsJson(file); });
  if (side->second == "preop") {
    auto role = attributes.find(RoleAttribute);
    reading.landmarkInfo[pairs->second] = {id, role != attributes.end() ? role->second : ""};
    const auto transforms = e.references("transform");
    if (!transforms.empty()) reading.parentOf[id] = transforms.front();
  }
}

/// The element's role and attributes onto the node; its parent transform noted.
void applyElementAttributes(const std::string& id, const ParsedElement& e, Node& node, SceneReading& reading)
{
  auto attributes = decodeAttributes(e.get("attributes"));
  if (auto role = attributes.find(RoleAttribute); role != attributes.end()) {
    node.setRole(role->second);
    attributes.erase(role);
  }
  for (const auto& [key, value] : attributes) node.setAttribute(key, value);
  const auto transforms = e.references("transform");
  if (!transforms.empty()) reading.parentOf[id] = transforms.front();
}

/// Each landmark pair set from its two point lists, matched by point name.
void pairLandmarks(const ParsedScene& parsed, SceneReading& reading)
{
  for (const auto& [name, sides] : reading.landmarkSides) {
    auto preop = sides.find("preop");
    auto intraop = sides.find("intraop");
    if (preop == sides.end() || intraop == sides.end()) {
      throw InputError(parsed.mrmlPath.string() + ": landmark pairs '" + name + "' lack their " +
                       (preop == sides.end() ? "preop" : "intraop") + " point list");
    }
    std::map<std::string, PhysicalPoint> intraopByName;
    for (const NamedPoint& p : intraop->second) intraopByName[p.name] = p.position;
    std::vector<LandmarkPair> pairs;
    for (const NamedPoint& p : preop->second) {
      auto match = intraopByName.find(p.name);
      if (match == intraopByName.end()) {
        throw InputError(parsed.mrmlPath.string() + ": landmark '" + p.name + "' of '" + name + "' has no intraop point");
      }
      pairs.push_back({p.name, p.position, match->second});
    }
    auto node = LandmarksNode::create(name, pairs);
    node->setRole(reading.landmarkInfo[name].second);
    node->markStored();
    reading.loaded.emplace_back(reading.landmarkInfo[name].first, node);
  }
}

/// Everything read: adds the nodes to the scene, then resolves transform placement and the slice
/// view's layers to the new ids.
void addReadNodes(Scene& scene, const ParsedScene& parsed, const SceneReading& reading)
{
  std::map<std::string, std::string> newIdOf;
  for (auto& [oldId, node] : reading.loaded) {
    scene.addNode(node);
    newIdOf[oldId] = node->id();
  }
  for (auto& [oldId, node] : reading.loaded) {
    auto parent = reading.parentOf.find(oldId);
    if (parent != reading.parentOf.end() && newIdOf.count(parent->second)) node->setParentTransformId(newIdOf[parent->second]);
  }
  if (auto layers = readSliceViewLayers(parsed.byId)) {
    for (std::string* id : {&layers->backgroundVolumeId, &layers->foregroundVolumeId, &layers->labelVolumeId}) {
      // A layer showing a node that was not read (or is no volume) stays empty.
      const auto node = newIdOf.count(*id) ? scene.node(newIdOf[*id]) : nullptr;
      const bool volume = node && (node->kind() == NodeKind::ScalarVolume || node->kind() == NodeKind::LabelMapVolume);
      *id = volume ? node->id() : std::string();
    }
    scene.setSliceViewLayers(*layers);
  }
}

} // namespace

void readScene(Scene& scene, const fs::path& mrmlPath)
{
  const ParsedScene parsed = parseScene(mrmlPath);
  SceneReading reading;
  for (const std::string& id : parsed.order) {
    const ParsedElement& e = parsed.byId.at(id);
    if (e.tag == "MarkupsFiducial") {
      readLandmarkSide(parsed, id, e, reading);
      continue;
    }
    // Display and storage nodes, and node kinds the workflow does not use, give no node.
    std::shared_ptr<Node> node = readDataNode(parsed, e, e.get("name", id));
    if (!node) continue;
    applyElementAttributes(id, e, *node, reading);
    node->markStored();
    reading.loaded.emplace_back(id, node);
  }
  pairLandmarks(parsed, reading);
  addReadNodes(scene, parsed, reading);
}

} // namespace brainshift
