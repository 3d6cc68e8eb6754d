// Surfaces (.vtp) and tetrahedral meshes (.vtu): round trips with their arrays, the LPS tag Slicer
// reads (a field array SPACE), conversion of a file tagged RAS, and the refusals.
#include "BrainShiftTestingSupport.h"
#include "BrainShiftErrors.h"
#include "ModelIO.h"
#include "SyntheticData.h"

#include <vtkCellData.h>
#include <vtkFieldData.h>
#include <vtkFloatArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkStringArray.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLPolyDataReader.h>
#include <vtkXMLPolyDataWriter.h>

#include <fstream>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;

/// The two tetrahedra with a point array as well.
vtkSmartPointer<vtkUnstructuredGrid> makeMesh()
{
  const vtkSmartPointer<vtkUnstructuredGrid> mesh = testing::makeTwoTetrahedra();
  vtkNew<vtkFloatArray> magnitude;
  magnitude->SetName("DisplacementMagnitude");
  for (float value : {0.0f, 0.5f, 1.25f, 2.0f, 3.5f}) magnitude->InsertNextValue(value);
  mesh->GetPointData()->AddArray(magnitude);
  return mesh;
}

void checkSameArray(vtkDataArray* expected, vtkDataArray* actual)
{
  BS_CHECK_MSG(actual != nullptr, "array " << expected->GetName() << " is missing");
  BS_CHECK(actual->GetNumberOfTuples() == expected->GetNumberOfTuples());
  BS_CHECK(actual->GetNumberOfComponents() == expected->GetNumberOfComponents());
  for (vtkIdType t = 0; t < expected->GetNumberOfTuples(); ++t) {
    for (int c = 0; c < expected->GetNumberOfComponents(); ++c) BS_CHECK(actual->GetComponent(t, c) == expected->GetComponent(t, c));
  }
}

void checkSameModel(vtkPointSet* expected, vtkPointSet* actual)
{
  BS_CHECK(actual != nullptr);
  BS_CHECK(std::string(actual->GetClassName()) == expected->GetClassName());
  BS_CHECK(actual->GetNumberOfPoints() == expected->GetNumberOfPoints());
  BS_CHECK(actual->GetNumberOfCells() == expected->GetNumberOfCells());
  for (vtkIdType i = 0; i < expected->GetNumberOfPoints(); ++i) {
    double a[3], b[3];
    expected->GetPoint(i, a);
    actual->GetPoint(i, b);
    for (int k = 0; k < 3; ++k) BS_CHECK_MSG(a[k] == b[k], "point " << i);
  }
  for (vtkIdType c = 0; c < expected->GetNumberOfCells(); ++c) {
    BS_CHECK(actual->GetCellType(c) == expected->GetCellType(c));
    BS_CHECK(actual->GetCell(c)->GetPointId(2) == expected->GetCell(c)->GetPointId(2));
  }
  for (int i = 0; i < expected->GetPointData()->GetNumberOfArrays(); ++i) {
    vtkDataArray* array = expected->GetPointData()->GetArray(i);
    checkSameArray(array, actual->GetPointData()->GetArray(array->GetName()));
  }
  for (int i = 0; i < expected->GetCellData()->GetNumberOfArrays(); ++i) {
    vtkDataArray* array = expected->GetCellData()->GetArray(i);
    checkSameArray(array, actual->GetCellData()->GetArray(array->GetName()));
  }
}

/// The SPACE tag of a .vtp file as VTK reads it ("" if there is none).
std::string spaceTagOfFile(const fs::path& path)
{
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(path.c_str());
  reader->Update();
  auto* tag = vtkStringArray::SafeDownCast(reader->GetOutput()->GetFieldData()->GetAbstractArray("SPACE"));
  return tag && tag->GetNumberOfValues() == 1 ? tag->GetValue(0) : std::string();
}
} // namespace

int ModelIOTest(int, char*[])
{
  return brainshift::testing::runTest("ModelIOTest", [&] {
    const fs::path folder = testing::temporaryFolder("ModelIOTest");

    // A surface: the file is tagged LPS; the tag describes the file and is not returned.
    const vtkSmartPointer<vtkPolyData> surface = testing::makeTriangleSurface();
    const fs::path vtp = folder / "surface.vtp";
    writeModel(surface, vtp);
    BS_CHECK(spaceTagOfFile(vtp) == "LPS");
    BS_CHECK(surface->GetFieldData()->GetAbstractArray("SPACE") == nullptr); // the input is left alone
    const vtkSmartPointer<vtkPointSet> surfaceRead = readModel(vtp);
    checkSameModel(surface, surfaceRead);
    BS_CHECK(surfaceRead->GetFieldData()->GetAbstractArray("SPACE") == nullptr);

    // A tetrahedral mesh.
    const vtkSmartPointer<vtkUnstructuredGrid> mesh = makeMesh();
    const fs::path vtu = folder / "mesh.vtu";
    writeModel(mesh, vtu);
    const vtkSmartPointer<vtkPointSet> meshRead = readModel(vtu);
    checkSameModel(mesh, meshRead);
    BS_CHECK(meshRead->GetFieldData()->GetAbstractArray("SPACE") == nullptr);

    // A surface written in RAS (as older Slicer files are) comes back in LPS: x and y negated.
    vtkNew<vtkPolyData> rasSurface;
    rasSurface->DeepCopy(surface);
    vtkNew<vtkStringArray> rasTag;
    rasTag->SetName("SPACE");
    rasTag->InsertNextValue("RAS");
    rasSurface->GetFieldData()->AddArray(rasTag);
    const fs::path rasFile = folder / "ras.vtp";
    vtkNew<vtkXMLPolyDataWriter> writer;
    writer->SetInputData(rasSurface);
    writer->SetFileName(rasFile.c_str());
    BS_CHECK(writer->Write() == 1);
    const vtkSmartPointer<vtkPointSet> converted = readModel(rasFile);
    BS_CHECK(converted->GetNumberOfPoints() == surface->GetNumberOfPoints());
    for (vtkIdType i = 0; i < surface->GetNumberOfPoints(); ++i) {
      double ras[3], lps[3];
      surface->GetPoint(i, ras);
      converted->GetPoint(i, lps);
      BS_CHECK(lps[0] == -ras[0] && lps[1] == -ras[1] && lps[2] == ras[2]);
    }
    BS_CHECK(converted->GetFieldData()->GetAbstractArray("SPACE") == nullptr);

    // Refusals: a mesh is not a surface; missing and non-model files are input errors.
    BS_CHECK_THROWS(writeModel(mesh, folder / "mesh.vtp"), std::invalid_argument, "mesh.vtp");
    BS_CHECK(!fs::exists(folder / "mesh.vtp"));
    const fs::path missing = folder / "missing.vtp";
    BS_CHECK_THROWS(readModel(missing), InputError, missing.string());
    const fs::path notAModel = folder / "notes.vtp";
    std::ofstream(notAModel) << "just some text\n";
    BS_CHECK_THROWS(readModel(notAModel), InputError, notAModel.string());
    const fs::path wrongKind = folder / "surface_as_mesh.vtu";
    fs::copy_file(vtp, wrongKind);
    BS_CHECK_THROWS(readModel(wrongKind), InputError, wrongKind.string());
  });
}
