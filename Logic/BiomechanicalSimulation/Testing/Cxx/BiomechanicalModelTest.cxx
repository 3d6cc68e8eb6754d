// The model as the simulate stage meets it: a tetrahedral mesh with "Label" and a brain surface
// with "MeshNodeId", "Displacement", "Imposed", through the files, the worker and back onto the
// mesh: an infinitesimal rigid motion imposed on the surface (no strain, so exact for any mix of
// materials) is reproduced inside (the patch test, end to end, across two tissues);
// free surface points impose nothing; what is wrong in the files is named. Leaves a small case in
// Testing/Temporary/SimulateStageCase for the command line's simulate test.
#include "BiomechanicalModel.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"
#include "ModelIO.h"

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkDoubleArray.h>
#include <vtkIntArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>

int BiomechanicalModelTest(int, char*[])
{
  return brainshift::testing::runTest("BiomechanicalModelTest", [] {
    using namespace brainshift;
    const double side = 40.0;
    const testing::Field linear = [](const double* x) { // c + w x x
      const double w[3] = {0.001, -0.002, 0.0015};
      return std::array<double, 3>{0.2 + w[1] * x[2] - w[2] * x[1], -0.3 + w[2] * x[0] - w[0] * x[2], 0.1 + w[0] * x[1] - w[1] * x[0]};
    };
    // The mesh: the cube, tissue 2 below z = 20 mm and tissue 4 above.
    FiniteElementJob cube = testing::cubeMesh(6, side, 0.2);
    vtkNew<vtkPoints> points;
    points->SetDataTypeToDouble(); // the exact positions the imposed values were computed at
    for (std::size_t v = 0; v < cube.nodeCount(); ++v) points->InsertNextPoint(&cube.nodes[3 * v]);
    auto mesh = vtkSmartPointer<vtkUnstructuredGrid>::New();
    mesh->SetPoints(points);
    vtkNew<vtkIntArray> label;
    label->SetName("Label");
    for (std::size_t t = 0; t < cube.tetrahedronCount(); ++t) {
      const vtkIdType ids[4] = {cube.tetrahedra[4 * t], cube.tetrahedra[4 * t + 1], cube.tetrahedra[4 * t + 2], cube.tetrahedra[4 * t + 3]};
      mesh->InsertNextCell(VTK_TETRA, 4, ids);
      label->InsertNextValue(cube.nodes[3 * std::size_t(ids[0]) + 2] < side / 2 ? 2 : 4);
    }
    mesh->GetCellData()->AddArray(label);
    // The surface: the cube's boundary nodes, imposed; and one interior node listed as free.
    testing::imposeOnBoundary(cube, side, linear);
    auto surface = vtkSmartPointer<vtkPolyData>::New();
    vtkNew<vtkPoints> surfacePoints;
    surfacePoints->SetDataTypeToDouble();
    vtkNew<vtkIntArray> nodeIds, imposed;
    vtkNew<vtkDoubleArray> displacement;
    nodeIds->SetName("MeshNodeId");
    imposed->SetName("Imposed");
    displacement->SetName("Displacement");
    displacement->SetNumberOfComponents(3);
    for (std::size_t f = 0; f < cube.fixedNodes.size(); ++f) {
      surfacePoints->InsertNextPoint(&cube.nodes[3 * std::size_t(cube.fixedNodes[f])]);
      nodeIds->InsertNextValue(cube.fixedNodes[f]);
      imposed->InsertNextValue(1);
      displacement->InsertNextTuple(&cube.fixedDisplacements[3 * f]);
    }
    const int interior = 3 + 7 * (3 + 7 * 3); // node (3, 3, 3), inside
    surfacePoints->InsertNextPoint(&cube.nodes[3 * interior]);
    nodeIds->InsertNextValue(interior);
    imposed->InsertNextValue(0);
    const double wrong[3] = {99, 99, 99};
    displacement->InsertNextTuple(wrong);
    surface->SetPoints(surfacePoints);
    surface->GetPointData()->AddArray(nodeIds);
    surface->GetPointData()->AddArray(imposed);
    surface->GetPointData()->AddArray(displacement);

    const auto folder = testing::temporaryFolder("SimulateStageCase");
    writeModel(mesh, folder / "mesh.vtu");
    writeModel(surface, folder / "brain_surface.vtp");
    vtkSmartPointer<vtkUnstructuredGrid> readMesh = vtkUnstructuredGrid::SafeDownCast(readModel(folder / "mesh.vtu"));
    vtkSmartPointer<vtkPolyData> readSurface = vtkPolyData::SafeDownCast(readModel(folder / "brain_surface.vtp"));
    BS_CHECK(readMesh && readSurface);

    Configuration configuration;
    FiniteElementJob job = finiteElementJobFromModel(readMesh, readSurface, configuration, "mesh.vtu", "brain_surface.vtp");
    BS_CHECK(job.fixedNodes.size() == cube.fixedNodes.size()); // the free point imposes nothing
    BS_CHECK(job.materials.size() == 2);
    BS_CHECK_NEAR(job.materials[0].youngsModulus, 3000.0 * 1e-6, 1e-15); // Pa -> N/mm^2
    job.solverOptions = "-ksp_type preonly -pc_type lu";
    const FiniteElementResult result = solveWithWorker(job, testing::workerOptions());
    BS_CHECK_MSG(testing::maximumNodalError(job, result, linear) < 1e-10, testing::maximumNodalError(job, result, linear));
    attachDisplacements(readMesh, result);
    vtkDataArray* attached = readMesh->GetPointData()->GetArray("Displacement");
    BS_CHECK(attached && attached->GetNumberOfComponents() == 3);
    const auto expected = linear(&cube.nodes[3 * interior]);
    BS_CHECK_NEAR(attached->GetComponent(interior, 2), expected[2], 1e-10);
    BS_CHECK(readMesh->GetPointData()->GetArray("DisplacementMagnitude"));

    // What is wrong is named.
    Configuration noTumour = configuration;
    noTumour.materials.erase(4);
    BS_CHECK_THROWS(finiteElementJobFromModel(readMesh, readSurface, noTumour, "mesh.vtu", "brain_surface.vtp"), InputError,
                    "mesh.vtu: tissue label 4 has no material");
    auto unlabelled = vtkSmartPointer<vtkUnstructuredGrid>::New();
    unlabelled->DeepCopy(readMesh);
    unlabelled->GetCellData()->RemoveArray("Label");
    BS_CHECK_THROWS(finiteElementJobFromModel(unlabelled, readSurface, configuration, "mesh.vtu", "brain_surface.vtp"), InputError,
                    "no cell array \"Label\"");
    auto farSurface = vtkSmartPointer<vtkPolyData>::New();
    farSurface->DeepCopy(readSurface);
    farSurface->GetPointData()->GetArray("MeshNodeId")->SetComponent(0, 0, 1e6);
    BS_CHECK_THROWS(finiteElementJobFromModel(readMesh, farSurface, configuration, "mesh.vtu", "brain_surface.vtp"), InputError,
                    "brain_surface.vtp: point 0 moves mesh node");
    auto freeSurface = vtkSmartPointer<vtkPolyData>::New();
    freeSurface->DeepCopy(readSurface);
    freeSurface->GetPointData()->GetArray("Imposed")->Fill(0);
    BS_CHECK_THROWS(finiteElementJobFromModel(readMesh, freeSurface, configuration, "mesh.vtu", "brain_surface.vtp"), InputError,
                    "no point is imposed");
    auto inverted = vtkSmartPointer<vtkUnstructuredGrid>::New();
    inverted->DeepCopy(readMesh);
    vtkIdType ids[4];
    {
      vtkNew<vtkIdList> cell;
      inverted->GetCellPoints(0, cell);
      for (int k = 0; k < 4; ++k) ids[k] = cell->GetId(k);
    }
    std::swap(ids[1], ids[2]);
    inverted->ReplaceCell(0, 4, ids);
    BS_CHECK_THROWS(finiteElementJobFromModel(inverted, readSurface, configuration, "mesh.vtu", "brain_surface.vtp"), InputError,
                    "mesh.vtu: tetrahedron 0 is inverted");
  });
}
