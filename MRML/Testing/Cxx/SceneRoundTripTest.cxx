// A scene with every node kind, written as a Slicer .mrml and read back: (a) the file follows
// Slicer's schema (Documentation/SlicerSceneFormat.md), (b) the linear transform's RAS
// matrixTransformToParent is the inverse of the LPS transform from parent, (c) reading gives back
// the same data, display and placement, (d) a scene with a missing data file is refused and
// leaves the target scene as it was.
#include "AtomicFile.h"
#include "BrainShiftTestingSupport.h"
#include "MarkupsIO.h"
#include "SceneIO.h"
#include "SyntheticData.h"

#include <itkCompositeTransform.h>
#include <itkImageRegionIteratorWithIndex.h>

#include <vtkCellData.h>
#include <vtkFieldData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkStringArray.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLDataParser.h>
#include <vtkXMLPolyDataReader.h>

#include <map>
#include <sstream>
#include <vector>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;
using brainshift::testing::point;

// ---- The scene's data ---------------------------------------------------------------------
/// The grid of both volumes: 12x10x8 anisotropic voxels, oblique.
ImageGeometry volumeGrid()
{
  return testing::grid({{12, 10, 8}}, {1.2, 0.9, 2.0}, point(-20.5, 14.25, 3.125), testing::rotationAbout(1, 2, -1, 20.0));
}

ScalarImage::Pointer makeIntensities()
{
  auto image = testing::makeImage<ScalarImage>(volumeGrid());
  itk::ImageRegionIteratorWithIndex<ScalarImage> it(image, image->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    const auto i = it.GetIndex();
    it.Set(static_cast<float>(i[0] + 10 * i[1] + 100 * i[2]) + 0.25f);
  }
  return image;
}

LabelImage::Pointer makeLabels()
{
  auto image = testing::makeImage<LabelImage>(volumeGrid());
  itk::ImageRegionIteratorWithIndex<LabelImage> it(image, image->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    const auto i = it.GetIndex();
    it.Set(static_cast<LabelPixel>((i[0] + i[1] + i[2]) % 5));
  }
  return image;
}

/// A smooth displacement field on a 6x6x6 grid of 4 mm around the origin.
SpatialTransform::Pointer makeWarp()
{
  return makeDisplacementFieldTransform(
    testing::makeSmoothDisplacementField(testing::grid({{6, 6, 6}}, {4.0, 4.0, 4.0}, point(-10, -10, -10))));
}

std::vector<LandmarkPair> makeLandmarks()
{
  return {{"nasion", point(0.1, -90.25, 12.3), point(2.75, -88.5, 13.0)},
          {"left tragus", point(71.333333333333329, 10.2, -5.0), point(70.1, 11.0, -4.4)},
          {"vertex", point(-0.5, 1e-3, 95.125), point(0.0, 2.5, 93.875)}};
}

// ---- Checks ---------------------------------------------------------------------------------
const std::vector<PhysicalPoint>& probePoints()
{
  static const std::vector<PhysicalPoint> points = {point(0, 0, 0),     point(3.3, -2.1, 5.7), point(-7.5, 6.2, -1.4),
                                                    point(8, 8, -8),     point(-4.4, 1.1, 9.0), point(40, -30, 25)};
  return points;
}

void checkSameMapping(const SpatialTransform* expected, const SpatialTransform* actual, double tolerance)
{
  BS_CHECK(actual != nullptr);
  for (const PhysicalPoint& y : probePoints()) {
    const auto a = expected->TransformPoint(y);
    const auto b = actual->TransformPoint(y);
    BS_CHECK_MSG(a.EuclideanDistanceTo(b) < tolerance, "at " << y << ": " << a << " became " << b);
  }
}

template <class TImage>
void checkSameImage(const TImage* expected, const TImage* actual)
{
  BS_CHECK(actual != nullptr);
  BS_CHECK(expected->GetLargestPossibleRegion().GetSize() == actual->GetLargestPossibleRegion().GetSize());
  for (unsigned r = 0; r < 3; ++r) {
    BS_CHECK_NEAR(actual->GetSpacing()[r], expected->GetSpacing()[r], 1e-5);
    BS_CHECK_NEAR(actual->GetOrigin()[r], expected->GetOrigin()[r], 1e-4);
    for (unsigned c = 0; c < 3; ++c) BS_CHECK_NEAR(actual->GetDirection()(r, c), expected->GetDirection()(r, c), 1e-5);
  }
  const std::size_t n = expected->GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) {
    BS_CHECK_MSG(actual->GetBufferPointer()[i] == expected->GetBufferPointer()[i], "voxel " << i);
  }
}

void checkSameArray(vtkDataArray* expected, vtkDataArray* actual)
{
  BS_CHECK_MSG(actual != nullptr, "array " << expected->GetName() << " is missing");
  BS_CHECK(actual->GetNumberOfTuples() == expected->GetNumberOfTuples());
  BS_CHECK(actual->GetNumberOfComponents() == expected->GetNumberOfComponents());
  for (vtkIdType t = 0; t < expected->GetNumberOfTuples(); ++t) {
    for (int c = 0; c < expected->GetNumberOfComponents(); ++c) {
      BS_CHECK(actual->GetComponent(t, c) == expected->GetComponent(t, c));
    }
  }
}

void checkSamePoints(vtkPointSet* expected, vtkPointSet* actual)
{
  BS_CHECK(actual != nullptr);
  BS_CHECK(actual->GetNumberOfPoints() == expected->GetNumberOfPoints());
  BS_CHECK(actual->GetNumberOfCells() == expected->GetNumberOfCells());
  for (vtkIdType i = 0; i < expected->GetNumberOfPoints(); ++i) {
    double a[3], b[3];
    expected->GetPoint(i, a);
    actual->GetPoint(i, b);
    for (int k = 0; k < 3; ++k) BS_CHECK(a[k] == b[k]);
  }
}

// ---- (a) the .mrml file -------------------------------------------------------------------
std::string attributeOf(vtkXMLDataElement* element, const char* name)
{
  const char* value = element->GetAttribute(name);
  return value ? value : "";
}

std::string tagOf(vtkXMLDataElement* element)
{
  return element->GetName();
}

/// The ids of a `references` attribute ("display:id1;storage:id2 id3;") by role.
std::multimap<std::string, std::string> referencesOf(vtkXMLDataElement* element)
{
  std::multimap<std::string, std::string> ids;
  std::istringstream in(attributeOf(element, "references"));
  std::string item;
  while (std::getline(in, item, ';')) {
    const auto colon = item.find(':');
    if (colon == std::string::npos) continue;
    std::istringstream list(item.substr(colon + 1));
    std::string id;
    while (list >> id) ids.emplace(item.substr(0, colon), id);
  }
  return ids;
}

std::vector<double> numbersOf(const std::string& text)
{
  std::vector<double> numbers;
  std::istringstream in(text);
  double value;
  while (in >> value) numbers.push_back(value);
  BS_CHECK_MSG(in.eof(), "'" << text << "' is not a list of numbers");
  return numbers;
}

/// The elements of a .mrml file by tag and by id (the parser owns them).
class SceneXml {
public:
  explicit SceneXml(const fs::path& mrml)
  {
    parser_->SetFileName(mrml.c_str());
    BS_CHECK_MSG(parser_->Parse() == 1, mrml << " is not well-formed XML");
    vtkXMLDataElement* root = parser_->GetRootElement();
    BS_CHECK(root != nullptr && tagOf(root) == "MRML");
    for (int i = 0; i < root->GetNumberOfNestedElements(); ++i) {
      vtkXMLDataElement* e = root->GetNestedElement(i);
      const std::string id = attributeOf(e, "id");
      BS_CHECK_MSG(!id.empty() && byId_.count(id) == 0, "<" << tagOf(e) << "> has the id '" << id << "'");
      byId_[id] = e;
      byTag_.emplace(tagOf(e), e);
    }
  }

  const std::map<std::string, vtkXMLDataElement*>& byId() const { return byId_; }
  std::size_t count(const std::string& tag) const { return byTag_.count(tag); }

  std::vector<vtkXMLDataElement*> withTag(const std::string& tag) const
  {
    std::vector<vtkXMLDataElement*> elements;
    for (auto [it, end] = byTag_.equal_range(tag); it != end; ++it) elements.push_back(it->second);
    BS_CHECK_MSG(!elements.empty(), "no <" << tag << ">");
    return elements;
  }

  /// The element `e` refers to in `role` ("display", "storage", "transform").
  vtkXMLDataElement* referenced(vtkXMLDataElement* e, const std::string& role) const
  {
    const auto references = referencesOf(e);
    const auto it = references.find(role);
    BS_CHECK_MSG(it != references.end(), attributeOf(e, "id") << " has no " << role << " reference");
    return byId_.at(it->second);
  }

private:
  vtkNew<vtkXMLDataParser> parser_;
  std::multimap<std::string, vtkXMLDataElement*> byTag_;
  std::map<std::string, vtkXMLDataElement*> byId_;
};

/// The tags, attributes, references and files that 3D Slicer needs (SlicerSceneFormat.md).
void checkSlicerSchema(const SceneXml& xml, const fs::path& folder)
{
  for (const char* tag : {"Volume", "VolumeDisplay", "VolumeArchetypeStorage", "LabelMapVolume", "LabelMapVolumeDisplay",
                          "Model", "ModelDisplay", "ModelStorage", "LinearTransform", "GridTransform", "Transform",
                          "TransformStorage", "MarkupsFiducial", "MarkupsJsonStorage"}) {
    BS_CHECK_MSG(xml.count(tag) > 0, "no <" << tag << ">");
  }
  BS_CHECK(xml.count("Model") == 2 && xml.count("TransformStorage") == 3);
  BS_CHECK(xml.count("MarkupsFiducial") == 2 && xml.count("MarkupsJsonStorage") == 2);

  // Every reference resolves; every data file is named relative to the scene and exists.
  for (const auto& [id, e] : xml.byId()) {
    for (const auto& [role, referenced] : referencesOf(e)) {
      BS_CHECK_MSG(xml.byId().count(referenced), id << " refers (" << role << ") to " << referenced << ", not in the file");
    }
    if (e->GetAttribute("fileName")) {
      const fs::path fileName = attributeOf(e, "fileName");
      BS_CHECK_MSG(fileName.is_relative() && fs::is_regular_file(folder / fileName), fileName);
    }
  }

  vtkXMLDataElement* volume = xml.withTag("Volume").front();
  vtkXMLDataElement* volumeDisplay = xml.referenced(volume, "display");
  BS_CHECK(tagOf(volumeDisplay) == "VolumeDisplay");
  BS_CHECK(attributeOf(volumeDisplay, "autoWindowLevel") == "0");
  BS_CHECK(numbersOf(attributeOf(volumeDisplay, "window")) == std::vector<double>{350});
  BS_CHECK(numbersOf(attributeOf(volumeDisplay, "level")) == std::vector<double>{42.5});
  BS_CHECK(attributeOf(volumeDisplay, "colorNodeID") == "vtkMRMLColorTableNodeGrey");
  BS_CHECK(tagOf(xml.referenced(volume, "storage")) == "VolumeArchetypeStorage");
  vtkXMLDataElement* labelMap = xml.withTag("LabelMapVolume").front();
  BS_CHECK(tagOf(xml.referenced(labelMap, "display")) == "LabelMapVolumeDisplay");
  BS_CHECK(tagOf(xml.referenced(labelMap, "storage")) == "VolumeArchetypeStorage");

  for (vtkXMLDataElement* model : xml.withTag("Model")) {
    vtkXMLDataElement* storage = xml.referenced(model, "storage");
    BS_CHECK(tagOf(storage) == "ModelStorage" && attributeOf(storage, "coordinateSystem") == "LPS");
    BS_CHECK(attributeOf(xml.referenced(model, "transform"), "name") == "rigid");
    if (attributeOf(model, "name") != "brain surface") continue;
    vtkXMLDataElement* display = xml.referenced(model, "display");
    BS_CHECK(tagOf(display) == "ModelDisplay");
    BS_CHECK(attributeOf(display, "scalarVisibility") == "true");
    BS_CHECK(attributeOf(display, "activeScalarName") == "DisplacementMagnitude");
    // The surface file says it is LPS as Slicer 5 does: a one-value string array "SPACE".
    const fs::path surfaceFile = folder / attributeOf(storage, "fileName");
    BS_CHECK(surfaceFile.extension() == ".vtp");
    vtkNew<vtkXMLPolyDataReader> reader;
    reader->SetFileName(surfaceFile.c_str());
    reader->Update();
    auto* space = vtkStringArray::SafeDownCast(reader->GetOutput()->GetFieldData()->GetAbstractArray("SPACE"));
    BS_CHECK_MSG(space != nullptr, surfaceFile << " has no SPACE field data");
    BS_CHECK(space->GetNumberOfValues() == 1 && space->GetValue(0) == "LPS");
  }

  for (const char* tag : {"LinearTransform", "GridTransform", "Transform"}) {
    BS_CHECK(tagOf(xml.referenced(xml.withTag(tag).front(), "storage")) == "TransformStorage");
  }
  const std::string toParent = attributeOf(xml.withTag("LinearTransform").front(), "matrixTransformToParent");
  BS_CHECK_MSG(numbersOf(toParent).size() == 16, "matrixTransformToParent=\"" << toParent << "\"");

  // Two point lists; the preoperative one is placed under the rigid transform.
  int preopLists = 0;
  for (vtkXMLDataElement* list : xml.withTag("MarkupsFiducial")) {
    vtkXMLDataElement* storage = xml.referenced(list, "storage");
    BS_CHECK(tagOf(storage) == "MarkupsJsonStorage");
    const fs::path file = folder / attributeOf(storage, "fileName");
    const std::string json = readTextFile(file);
    BS_CHECK(json.find("\"@schema\"") != std::string::npos);
    BS_CHECK(json.find("\"coordinateSystem\": \"LPS\"") != std::string::npos);
    BS_CHECK(json.find("\"position\"") != std::string::npos);
    const bool preop = referencesOf(list).count("transform") == 1;
    if (preop) {
      ++preopLists;
      BS_CHECK(attributeOf(xml.referenced(list, "transform"), "name") == "rigid");
    }
    const auto points = readMarkupsJson(file);
    BS_CHECK(points.size() == 3 && points[1].name == "left tragus");
    BS_CHECK(points[1].position == (preop ? makeLandmarks()[1].preop : makeLandmarks()[1].intraop));
  }
  BS_CHECK(preopLists == 1);
}

// ---- (b) the RAS matrix of the linear transform ----------------------------------------------
/// `matrixTransformToParent` (16 numbers, row-major, RAS) must be inverse(D T D), D = diag(-1, -1, 1, 1),
/// for the LPS transform from parent T: T maps a parent point y to the child point x, and the
/// matrix takes x back to y, both in RAS.
void checkMatrixTransformToParent(const std::string& attribute, const SpatialTransform* fromParent)
{
  const std::vector<double> m = numbersOf(attribute);
  BS_CHECK(m.size() == 16 && m[12] == 0 && m[13] == 0 && m[14] == 0 && m[15] == 1);
  for (const PhysicalPoint& y : probePoints()) {
    const auto x = fromParent->TransformPoint(y);
    const double xRas[3] = {-x[0], -x[1], x[2]};
    const double yRas[3] = {-y[0], -y[1], y[2]};
    for (int r = 0; r < 3; ++r) {
      double mapped = m[4 * r + 3];
      for (int c = 0; c < 3; ++c) mapped += m[4 * r + c] * xRas[c];
      BS_CHECK_NEAR(mapped, yRas[r], 1e-9);
    }
  }
}

// ---- (c) the scene read back ------------------------------------------------------------
template <class TNode>
std::shared_ptr<TNode> named(const Scene& scene, const std::string& name)
{
  auto node = scene.findByName<TNode>(name);
  BS_CHECK_MSG(node != nullptr, "no node '" << name << "' of the expected type");
  return node;
}

std::string parentNameOf(const Scene& scene, const Node& node)
{
  const auto parent = scene.node(node.parentTransformId());
  return parent ? parent->name() : "";
}

/// `read` holds the nodes of `written`: same data, display, role and placement.
void checkSameScene(const Scene& written, const Scene& read)
{
  BS_CHECK(read.nodes().size() == written.nodes().size());
  for (const auto& node : written.nodes()) {
    const auto copy = named<Node>(read, node->name());
    BS_CHECK(copy->kind() == node->kind());
    BS_CHECK_MSG(copy->role() == node->role(), node->name() << ": role '" << copy->role() << "'");
    BS_CHECK_MSG(parentNameOf(read, *copy) == parentNameOf(written, *node),
                 node->name() << " is under '" << parentNameOf(read, *copy) << "'");
    BS_CHECK_MSG(!copy->dataModifiedSinceStorage(), node->name());
  }
  BS_CHECK(parentNameOf(read, *named<ModelNode>(read, "mesh")) == "rigid");

  const auto intraop = named<ScalarVolumeNode>(written, "intraop image");
  const auto intraopRead = named<ScalarVolumeNode>(read, "intraop image");
  checkSameImage<ScalarImage>(intraop->image(), intraopRead->image());
  const VolumeDisplay& window = intraopRead->display();
  BS_CHECK(window.window && *window.window == 350 && window.level && *window.level == 42.5);
  BS_CHECK(window.opacity == 0.75 && window.colorTable == "Grey");

  const auto labelsRead = named<LabelMapVolumeNode>(read, "intraop labels");
  checkSameImage<LabelImage>(named<LabelMapVolumeNode>(written, "intraop labels")->image(), labelsRead->image());
  BS_CHECK(labelsRead->display().colorTable == "Labels");

  const std::pair<const char*, TransformNode::Type> transforms[] = {
    {"rigid", TransformNode::Type::Linear}, {"warp", TransformNode::Type::DisplacementField}, {"total", TransformNode::Type::Composite}};
  for (const auto& [name, type] : transforms) {
    const auto transformRead = named<TransformNode>(read, name);
    BS_CHECK_MSG(transformRead->type() == type, name);
    // Linear: text with full precision; fields: float vectors.
    checkSameMapping(named<TransformNode>(written, name)->transformFromParent(), transformRead->transformFromParent(),
                     type == TransformNode::Type::Linear ? 1e-6 : 1e-4);
  }

  const auto surface = named<ModelNode>(written, "brain surface");
  const auto surfaceRead = named<ModelNode>(read, "brain surface");
  BS_CHECK(!surfaceRead->isVolumetric());
  checkSamePoints(surface->mesh(), surfaceRead->mesh());
  checkSameArray(surface->mesh()->GetPointData()->GetArray("DisplacementMagnitude"),
                 surfaceRead->mesh()->GetPointData()->GetArray("DisplacementMagnitude"));
  BS_CHECK(surfaceRead->mesh()->GetFieldData()->GetAbstractArray("SPACE") == nullptr);
  const ModelDisplay& display = surfaceRead->display();
  BS_CHECK(display.scalarVisibility && display.activeScalarName == "DisplacementMagnitude");
  BS_CHECK(display.color == surface->display().color && display.opacity == 0.6);
  BS_CHECK(display.colorTable == "ColdToHotRainbow");
  BS_CHECK(display.scalarRange && (*display.scalarRange)[0] == 0.0 && (*display.scalarRange)[1] == 5.0);

  const auto mesh = named<ModelNode>(written, "mesh");
  const auto meshRead = named<ModelNode>(read, "mesh");
  BS_CHECK(meshRead->isVolumetric() && meshRead->mesh()->GetCellType(1) == VTK_TETRA);
  checkSamePoints(mesh->mesh(), meshRead->mesh());
  checkSameArray(mesh->mesh()->GetCellData()->GetArray("Label"), meshRead->mesh()->GetCellData()->GetArray("Label"));
  BS_CHECK(!meshRead->display().scalarVisibility);

  const auto& pairs = named<LandmarksNode>(written, "landmarks")->pairs();
  const auto& pairsRead = named<LandmarksNode>(read, "landmarks")->pairs();
  BS_CHECK(pairsRead.size() == pairs.size());
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    BS_CHECK(pairsRead[i].name == pairs[i].name);
    BS_CHECK(pairsRead[i].preop == pairs[i].preop && pairsRead[i].intraop == pairs[i].intraop);
  }
}
} // namespace

int SceneRoundTripTest(int, char*[])
{
  return brainshift::testing::runTest("SceneRoundTripTest", [&] {
    const fs::path folder = brainshift::testing::temporaryFolder("SceneRoundTripTest");
    const fs::path mrml = folder / "scene.mrml";

    Scene scene;
    auto intraop = scene.add(ScalarVolumeNode::create("intraop image", makeIntensities()));
    intraop->setRole("intraop");
    VolumeDisplay window;
    window.window = 350;
    window.level = 42.5;
    window.opacity = 0.75;
    intraop->setDisplay(window);
    scene.add(LabelMapVolumeNode::create("intraop labels", makeLabels()))->setRole("intraop");

    const auto rigidTransform = testing::makeRigidTransform();
    auto rigid = scene.add(TransformNode::create("rigid", rigidTransform.GetPointer()));
    rigid->setRole("rigid");
    auto warp = scene.add(TransformNode::create("warp", makeWarp()));
    warp->setRole("warp");
    auto composite = itk::CompositeTransform<double, 3>::New();
    composite->AddTransform(warp->transformFromParent()->Clone());
    composite->AddTransform(rigidTransform->Clone());
    scene.add(TransformNode::create("total", composite.GetPointer()))->setRole("total");

    auto surface = scene.add(ModelNode::create("brain surface", testing::makeTetrahedronSurface()));
    surface->setRole("surface");
    ModelDisplay coloured;
    coloured.scalarVisibility = true;
    coloured.activeScalarName = "DisplacementMagnitude";
    coloured.color = {0.25, 0.5, 1.0};
    coloured.opacity = 0.6;
    coloured.scalarRange = std::array<double, 2>{0.0, 5.0};
    surface->setDisplay(coloured);
    auto mesh = scene.add(ModelNode::create("mesh", testing::makeTwoTetrahedra()));
    mesh->setRole("mesh");
    auto landmarks = scene.add(LandmarksNode::create("landmarks", makeLandmarks()));
    landmarks->setRole("truth");
    for (Node* placed : {static_cast<Node*>(surface.get()), static_cast<Node*>(mesh.get()), static_cast<Node*>(landmarks.get())}) {
      placed->setParentTransformId(rigid->id());
    }

    writeScene(scene, mrml);
    for (const auto& node : scene.nodes()) BS_CHECK_MSG(!node->dataModifiedSinceStorage(), node->name());

    const SceneXml xml(mrml);
    checkSlicerSchema(xml, folder);
    checkMatrixTransformToParent(attributeOf(xml.withTag("LinearTransform").front(), "matrixTransformToParent"),
                                 rigidTransform);

    Scene reread;
    readScene(reread, mrml);
    checkSameScene(scene, reread);

    // (d) A data file gone (the last one read): refused, naming it, and nothing is added.
    const fs::path intraopPoints = folder / "landmarks_intraop.mrk.json";
    BS_CHECK(fs::remove(intraopPoints));
    const std::size_t before = reread.nodes().size();
    BS_CHECK_THROWS(readScene(reread, mrml), InputError, intraopPoints.filename().string());
    BS_CHECK(reread.nodes().size() == before);
  });
}
