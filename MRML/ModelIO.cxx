#include "ModelIO.h"

#include "AtomicFile.h"
#include "FileNames.h"
#include "BrainShiftErrors.h"

#include <vtkCallbackCommand.h>
#include <vtkCommand.h>
#include <vtkDataSetReader.h>
#include <vtkNew.h>
#include <vtkFieldData.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataWriter.h>
#include <vtkStringArray.h>
#include <vtkUnstructuredGrid.h>
#include <vtkUnstructuredGridWriter.h>
#include <vtkXMLPolyDataReader.h>
#include <vtkXMLPolyDataWriter.h>
#include <vtkXMLUnstructuredGridReader.h>
#include <vtkXMLUnstructuredGridWriter.h>

#include <algorithm>
#include <fstream>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
// 3D Slicer 5 records a model's coordinate system in .vtp/.vtu files as a one-value string array
// "SPACE" in the field data ("LPS" or "RAS"), and in legacy .vtk files as "SPACE=LPS" in the
// header line. Without a tag Slicer assumes RAS, so BrainShift always writes one.
constexpr const char* SpaceArrayName = "SPACE";


std::string spaceTagOf(vtkPointSet* model)
{
  auto* tag = vtkStringArray::SafeDownCast(model->GetFieldData()->GetAbstractArray(SpaceArrayName));
  return tag && tag->GetNumberOfValues() == 1 ? tag->GetValue(0) : std::string();
}

std::string legacyHeaderSpace(const fs::path& path)
{
  std::ifstream in(path);
  std::string line;
  std::getline(in, line); // "# vtk DataFile Version x.y"
  std::getline(in, line); // the header line
  if (line.find("SPACE=RAS") != std::string::npos) return "RAS";
  if (line.find("SPACE=LPS") != std::string::npos) return "LPS";
  return "";
}

void flipXY(vtkPointSet* model)
{
  vtkPoints* points = model->GetPoints();
  for (vtkIdType i = 0; i < points->GetNumberOfPoints(); ++i) {
    double p[3];
    points->GetPoint(i, p);
    p[0] = -p[0];
    p[1] = -p[1];
    points->SetPoint(i, p);
  }
  points->Modified();
}
} // namespace

vtkSmartPointer<vtkPointSet> readModel(const fs::path& path)
{
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    throw InputError(path.string() + ": no such file");
  }
  const std::string ext = lowerCaseFileName(path.extension());
  vtkSmartPointer<vtkPointSet> model;
  std::string space;
  if (ext == ".vtp" || ext == ".vtu") {
    vtkSmartPointer<vtkXMLReader> reader;
    if (ext == ".vtp") reader = vtkSmartPointer<vtkXMLPolyDataReader>::New();
    else reader = vtkSmartPointer<vtkXMLUnstructuredGridReader>::New();
    if (!reader->CanReadFile(path.c_str())) {
      throw InputError(path.string() + ": not a VTK XML " + (ext == ".vtp" ? "polydata" : "unstructured grid") + " file");
    }
    reader->SetFileName(path.c_str());
    // VTK prints its parser's complaints to the console; the caller gets one error instead.
    bool failed = false;
    vtkNew<vtkCallbackCommand> onError;
    onError->SetClientData(&failed);
    onError->SetCallback([](vtkObject*, unsigned long, void* flag, void*) { *static_cast<bool*>(flag) = true; });
    reader->AddObserver(vtkCommand::ErrorEvent, onError);
    const int display = vtkObject::GetGlobalWarningDisplay();
    vtkObject::GlobalWarningDisplayOff();
    reader->Update();
    vtkObject::SetGlobalWarningDisplay(display);
    if (failed || reader->GetErrorCode() != 0) {
      throw InputError(path.string() + ": cannot read the model (truncated or corrupt?)");
    }
    model = vtkPointSet::SafeDownCast(reader->GetOutputDataObject(0));
    if (model) space = spaceTagOf(model);
  } else if (ext == ".vtk") {
    auto reader = vtkSmartPointer<vtkDataSetReader>::New();
    reader->SetFileName(path.c_str());
    reader->Update();
    model = vtkPointSet::SafeDownCast(reader->GetOutput());
    space = legacyHeaderSpace(path);
  } else {
    throw InputError(path.string() + ": not a model file (expected .vtp, .vtu or .vtk)");
  }
  if (!model || !model->GetPoints() || model->GetNumberOfPoints() == 0) {
    throw InputError(path.string() + ": the model has no points (not a valid model file?)");
  }
  // Detach from the reader, drop the tag (it describes the file, not the data), convert to LPS.
  vtkSmartPointer<vtkPointSet> copy;
  copy.TakeReference(model->NewInstance());
  copy->DeepCopy(model);
  copy->GetFieldData()->RemoveArray(SpaceArrayName);
  if (space == "RAS") flipXY(copy);
  return copy;
}

void writeModel(vtkPointSet* model, const fs::path& path)
{
  if (!model) throw std::invalid_argument("writeModel: no model for " + path.string());
  const std::string ext = lowerCaseFileName(path.extension());
  const bool isPolyData = vtkPolyData::SafeDownCast(model) != nullptr;
  const bool isGrid = vtkUnstructuredGrid::SafeDownCast(model) != nullptr;
  if ((ext == ".vtp" && !isPolyData) || (ext == ".vtu" && !isGrid) || (ext == ".vtk" && !isPolyData && !isGrid) ||
      (ext != ".vtp" && ext != ".vtu" && ext != ".vtk")) {
    throw std::invalid_argument("cannot write a " + std::string(model->GetClassName()) + " to " + path.string() +
                                " (surfaces to .vtp, tetrahedral meshes to .vtu)");
  }
  vtkSmartPointer<vtkPointSet> tagged;
  tagged.TakeReference(model->NewInstance());
  tagged->ShallowCopy(model);
  auto fieldData = vtkSmartPointer<vtkFieldData>::New();
  fieldData->DeepCopy(model->GetFieldData());
  tagged->SetFieldData(fieldData);

  // VTK's writers return 1 on a full disk, and crash (double free) when a large compressed write
  // fails midway: they write into memory here, and the bytes go to the file through a checked
  // stream, atomically.
  bool failed = false;
  vtkNew<vtkCallbackCommand> onError;
  onError->SetClientData(&failed);
  onError->SetCallback([](vtkObject*, unsigned long, void* flag, void*) { *static_cast<bool*>(flag) = true; });
  const int display = vtkObject::GetGlobalWarningDisplay();
  vtkObject::GlobalWarningDisplayOff();
  int written = 0;
  std::string bytes;
  if (ext == ".vtk") {
    vtkSmartPointer<vtkDataWriter> writer;
    if (isPolyData) {
      auto w = vtkSmartPointer<vtkPolyDataWriter>::New();
      w->SetInputData(tagged);
      writer = w;
    } else {
      auto w = vtkSmartPointer<vtkUnstructuredGridWriter>::New();
      w->SetInputData(tagged);
      writer = w;
    }
    writer->SetHeader("BrainShift output. SPACE=LPS");
    writer->WriteToOutputStringOn();
    writer->SetFileTypeToBinary();
    writer->AddObserver(vtkCommand::ErrorEvent, onError);
    written = writer->Write() && writer->GetErrorCode() == 0;
    bytes = writer->GetOutputStdString();
  } else {
    auto tag = vtkSmartPointer<vtkStringArray>::New();
    tag->SetName(SpaceArrayName);
    tag->InsertNextValue("LPS");
    fieldData->AddArray(tag);
    vtkSmartPointer<vtkXMLWriter> writer;
    if (isPolyData) {
      auto w = vtkSmartPointer<vtkXMLPolyDataWriter>::New();
      w->SetInputData(tagged);
      writer = w;
    } else {
      auto w = vtkSmartPointer<vtkXMLUnstructuredGridWriter>::New();
      w->SetInputData(tagged);
      writer = w;
    }
    writer->WriteToOutputStringOn();
    writer->SetDataModeToBinary();
    writer->SetCompressorTypeToZLib();
    // zlib's fastest level: a later scan writes the 96,000-node mesh twice (the mesh, then the
    // solved mesh) and the surface once; six mesh writes of a watch session 0.66 -> 0.36 s, the
    // files 5 % larger (mesh.vtu 2.75 -> 2.90 MB).
    writer->SetCompressionLevel(1);
    writer->AddObserver(vtkCommand::ErrorEvent, onError);
    written = writer->Write() && writer->GetErrorCode() == 0;
    bytes = writer->GetOutputString();
  }
  vtkObject::SetGlobalWarningDisplay(display);
  if (!written || failed || bytes.empty()) throw MethodError("cannot write " + path.string() + ": VTK could not encode the model");
  writeTextFileAtomically(path, bytes); // checked, verified, renamed
}

} // namespace brainshift
