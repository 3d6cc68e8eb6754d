// The scene opens fused in 3D Slicer 5 (issue 17, item 3): a scene with slice view layers is
// written with a Four-Up layout node and the Red, Yellow and Green slice composite nodes that
// name the intraoperative scan (background), an overlay (foreground) and the labels, by ids that
// exist in the file; the landmark lists are locked in the scene and in their .mrk.json files alike
// and show their point labels; the layers survive a read; removing a shown volume empties its layer.
#include "AtomicFile.h"
#include "BrainShiftTestingSupport.h"
#include "SceneIO.h"
#include "SyntheticData.h"

#include <nlohmann/json.hpp>

#include <vtkNew.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLDataParser.h>

#include <map>
#include <set>
#include <sstream>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;
using brainshift::testing::point;

ImageGeometry volumeGrid()
{
  return testing::grid({{6, 5, 4}}, {1.5, 1.5, 2.0}, point(-4, 3, 1));
}

template <class TImage>
typename TImage::Pointer filled(typename TImage::PixelType value)
{
  auto image = testing::makeImage<TImage>(volumeGrid());
  image->FillBuffer(value);
  return image;
}

std::string attributeOf(vtkXMLDataElement* e, const char* name)
{
  const char* value = e->GetAttribute(name);
  return value ? value : "";
}

/// The elements of a written .mrml, by tag and by id (the parser owns them).
struct WrittenScene {
  vtkNew<vtkXMLDataParser> parser;
  std::multimap<std::string, vtkXMLDataElement*> byTag;
  std::map<std::string, vtkXMLDataElement*> byId;

  explicit WrittenScene(const fs::path& mrml)
  {
    parser->SetFileName(mrml.c_str());
    BS_CHECK_MSG(parser->Parse() == 1, mrml << " is not well-formed XML");
    vtkXMLDataElement* root = parser->GetRootElement();
    for (int i = 0; i < root->GetNumberOfNestedElements(); ++i) {
      vtkXMLDataElement* e = root->GetNestedElement(i);
      byTag.emplace(e->GetName(), e);
      byId[attributeOf(e, "id")] = e;
    }
  }
  std::vector<vtkXMLDataElement*> withTag(const std::string& tag) const
  {
    std::vector<vtkXMLDataElement*> found;
    for (auto [it, end] = byTag.equal_range(tag); it != end; ++it) found.push_back(it->second);
    return found;
  }
};

/// The id a `references` attribute gives for `role` ("backgroundVolume:id;..."), or "".
std::string referenceOf(vtkXMLDataElement* e, const std::string& role)
{
  std::istringstream in(attributeOf(e, "references"));
  std::string item;
  while (std::getline(in, item, ';')) {
    if (item.rfind(role + ":", 0) == 0) return item.substr(role.size() + 1);
  }
  return "";
}

/// Each slice view names the expected volume (by the tag and name of the element the id leads
/// to) in its `references` role and in the legacy attribute alike.
void checkSliceViews(const WrittenScene& xml, const std::string& foregroundName)
{
  const auto layouts = xml.withTag("Layout");
  BS_CHECK(layouts.size() == 1);
  BS_CHECK(attributeOf(layouts.front(), "currentViewArrangement") == "3");
  BS_CHECK(attributeOf(layouts.front(), "singletonTag") == "vtkMRMLLayoutNode");
  std::set<std::string> views;
  const std::map<std::string, std::pair<std::string, std::string>> expected = {
    {"backgroundVolume", {"Volume", "intraop image"}},
    {"foregroundVolume", {"Volume", foregroundName}},
    {"labelVolume", {"LabelMapVolume", "warped preop labels"}}};
  for (vtkXMLDataElement* composite : xml.withTag("SliceComposite")) {
    const std::string view = attributeOf(composite, "layoutName");
    views.insert(view);
    BS_CHECK(attributeOf(composite, "singletonTag") == view);
    BS_CHECK(attributeOf(composite, "id") == "vtkMRMLSliceCompositeNode" + view);
    BS_CHECK_NEAR(std::stod(attributeOf(composite, "foregroundOpacity")), 0.5, 1e-12);
    BS_CHECK_NEAR(std::stod(attributeOf(composite, "labelOpacity")), 0.6, 1e-12);
    for (const auto& [role, tagAndName] : expected) {
      const std::string id = referenceOf(composite, role);
      BS_CHECK_MSG(xml.byId.count(id) == 1, view << " " << role << " '" << id << "' is not in the scene");
      BS_CHECK(attributeOf(composite, (role + "ID").c_str()) == id);
      vtkXMLDataElement* volume = xml.byId.at(id);
      BS_CHECK_MSG(volume->GetName() == tagAndName.first && attributeOf(volume, "name") == tagAndName.second,
                   view << " " << role << " shows <" << volume->GetName() << "> '" << attributeOf(volume, "name") << "'");
    }
  }
  BS_CHECK((views == std::set<std::string>{"Red", "Yellow", "Green"}));
}

/// Both point lists are locked in the scene and in their files (list and every point), and show
/// their point labels.
void checkLandmarksLocked(const WrittenScene& xml, const fs::path& folder)
{
  const auto lists = xml.withTag("MarkupsFiducial");
  BS_CHECK(lists.size() == 2);
  for (vtkXMLDataElement* list : lists) {
    BS_CHECK(attributeOf(list, "locked") == "true");
    vtkXMLDataElement* display = xml.byId.at(referenceOf(list, "display"));
    BS_CHECK(attributeOf(display, "pointLabelsVisibility") == "true");
    const fs::path file = folder / attributeOf(xml.byId.at(referenceOf(list, "storage")), "fileName");
    const auto markup = nlohmann::json::parse(readTextFile(file))["markups"][0];
    BS_CHECK_MSG(markup["locked"] == true, file << " says unlocked while the scene says locked");
    BS_CHECK(markup["controlPoints"].size() == 2);
    for (const auto& controlPoint : markup["controlPoints"]) BS_CHECK(controlPoint["locked"] == true);
  }
}
} // namespace

int SceneSliceViewsTest(int, char*[])
{
  return brainshift::testing::runTest("SceneSliceViewsTest", [&] {
    const fs::path folder = brainshift::testing::temporaryFolder("SceneSliceViewsTest");
    Scene scene;
    auto intraop = scene.add(ScalarVolumeNode::create("intraop image", filled<ScalarImage>(10.0f)));
    auto warped = scene.add(ScalarVolumeNode::create("warped preop image", filled<ScalarImage>(20.0f)));
    auto fmri = scene.add(ScalarVolumeNode::create("warped fmri", filled<ScalarImage>(3.0f)));
    auto labels = scene.add(LabelMapVolumeNode::create("warped preop labels", filled<LabelImage>(2)));
    auto surface = scene.add(ModelNode::create("brain surface", testing::makeTetrahedronSurface()));
    scene.add(LandmarksNode::create("landmarks", {{"a", point(1, 2, 3), point(1.5, 2, 3)}, {"b", point(4, 5, 6), point(4, 5.5, 6)}}));

    // Without layers, no view nodes: a scene saved from elsewhere keeps Slicer's own views.
    writeScene(scene, folder / "plain.mrml");
    BS_CHECK(WrittenScene(folder / "plain.mrml").byTag.count("SliceComposite") == 0);
    BS_CHECK(WrittenScene(folder / "plain.mrml").byTag.count("Layout") == 0);

    SliceViewLayers layers;
    layers.backgroundVolumeId = intraop->id();
    layers.foregroundVolumeId = fmri->id();
    layers.labelVolumeId = labels->id();
    BS_CHECK_THROWS(scene.setSliceViewLayers(SliceViewLayers{surface->id(), "", 0.5, "", 1.0}), std::invalid_argument,
                    surface->id());
    scene.setSliceViewLayers(layers);
    writeScene(scene, folder / "scene.mrml");
    const WrittenScene xml(folder / "scene.mrml");
    checkSliceViews(xml, "warped fmri");
    checkLandmarksLocked(xml, folder);

    // The layers come back from the file, on the read scene's own ids.
    Scene reread;
    reread.add(ScalarVolumeNode::create("occupies an id", filled<ScalarImage>(0.0f)));
    readScene(reread, folder / "scene.mrml");
    const SliceViewLayers& read = reread.sliceViewLayers();
    BS_CHECK(reread.node(read.backgroundVolumeId) && reread.node(read.backgroundVolumeId)->name() == "intraop image");
    BS_CHECK(reread.node(read.foregroundVolumeId) && reread.node(read.foregroundVolumeId)->name() == "warped fmri");
    BS_CHECK(reread.node(read.labelVolumeId) && reread.node(read.labelVolumeId)->name() == "warped preop labels");
    BS_CHECK_NEAR(read.foregroundOpacity, 0.5, 1e-12);
    BS_CHECK_NEAR(read.labelOpacity, 0.6, 1e-12);

    // Removing the overlay empties its layer; the views then name only what is in the file.
    scene.remove(fmri->id());
    BS_CHECK(scene.sliceViewLayers().foregroundVolumeId.empty());
    scene.setSliceViewLayers(SliceViewLayers{intraop->id(), warped->id(), 0.5, labels->id(), 0.6});
    writeScene(scene, folder / "scene.mrml");
    checkSliceViews(WrittenScene(folder / "scene.mrml"), "warped preop image");
  });
}
