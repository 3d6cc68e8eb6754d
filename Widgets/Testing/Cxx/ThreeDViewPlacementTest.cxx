// The 3D view's geometry: a model under the rigid intraop_to_preop transform is drawn in the
// world (intraoperative) frame through the transform's inverse, also under two transforms; a
// displacement field on the way is not drawn through; arrows start at each point's initial
// position and end at its final one; the slice planes pass through the cursor across the
// background's bounds.
#include "BrainShiftTestingSupport.h"
#include "SyntheticData.h"
#include "ThreeDView.h"
#include "TransformIO.h"
#include "TransformNode.h"

#include <itkEuler3DTransform.h>
#include <vtkActor.h>
#include <vtkDoubleArray.h>
#include <vtkMatrix4x4.h>
#include <vtkPointData.h>

#include <QApplication>
#include <QSurfaceFormat>
#include <QTest>

#include <cmath>
#include <iostream>

int ThreeDViewPlacementTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("ThreeDViewPlacementTest", [] {
    using namespace brainshift;
    Scene scene;
    // intraop_to_preop: y -> R y + t, a 90 degree turn about S and a shift.
    auto rigid = itk::Euler3DTransform<double>::New();
    rigid->SetRotation(0.0, 0.0, M_PI / 2);
    itk::Euler3DTransform<double>::OutputVectorType t;
    t[0] = 10.0;
    t[1] = -20.0;
    t[2] = 5.0;
    rigid->SetTranslation(t);
    auto transform = scene.add(TransformNode::create("rigid intraop_to_preop", rigid.GetPointer()));
    auto surface = ModelNode::create("brain surface", testing::makeTetrahedronSurface());
    ModelDisplay display;
    display.scalarVisibility = true;
    surface->setDisplay(display);
    surface->setParentTransformId(transform->id());
    scene.add(surface);

    // A point of the model (preoperative frame) is drawn at R^-1 (x - t).
    vtkSmartPointer<vtkMatrix4x4> toWorld = childToWorldMatrix(scene, *surface);
    BS_CHECK(toWorld);
    double x[4] = {30.5, 0.0, 1.0, 1.0}, shown[4];
    toWorld->MultiplyPoint(x, shown);
    const auto inverse = rigid->GetInverseTransform();
    itk::Point<double, 3> p;
    p[0] = x[0];
    p[1] = x[1];
    p[2] = x[2];
    const auto expected = inverse->TransformPoint(p);
    for (int d = 0; d < 3; ++d) BS_CHECK_NEAR(shown[d], expected[d], 1e-9);

    // Under two transforms: the inner one first, then the outer one's inverse.
    auto outer = itk::Euler3DTransform<double>::New();
    itk::Euler3DTransform<double>::OutputVectorType shift;
    shift[0] = 0.0;
    shift[1] = 0.0;
    shift[2] = 100.0;
    outer->SetTranslation(shift);
    auto outerNode = scene.add(TransformNode::create("table", outer.GetPointer()));
    transform->setParentTransformId(outerNode->id());
    toWorld = childToWorldMatrix(scene, *surface);
    toWorld->MultiplyPoint(x, shown);
    BS_CHECK_NEAR(shown[2], expected[2] - 100.0, 1e-9);
    transform->setParentTransformId("");

    // A displacement field on the way has no matrix: not drawn through (null), not guessed.
    auto field = testing::grid({4, 4, 4}, {10, 10, 10}, testing::point(-20, -20, -20)).allocate<DisplacementFieldImage>();
    field->FillBuffer(DisplacementVector(0.0f));
    auto warp = scene.add(TransformNode::create("intraop_to_preop", makeDisplacementFieldTransform(field)));
    auto warped = ModelNode::create("warped model", testing::makeTetrahedronSurface());
    warped->setParentTransformId(warp->id());
    scene.add(warped);
    BS_CHECK(!childToWorldMatrix(scene, *warped));
    auto orphan = ModelNode::create("orphan model", testing::makeTetrahedronSurface());
    orphan->setParentTransformId("vtkMRMLLinearTransformNode404"); // a transform the scene lacks
    scene.add(orphan);
    BS_CHECK(!childToWorldMatrix(scene, *orphan));

    ThreeDView view;
    view.resize(300, 300);
    view.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&view));
    view.setModels({surface}, [&scene](const ModelNode& model) { return childToWorldMatrix(scene, model); });
    double bounds[6];
    view.modelActor(0)->GetBounds(bounds);
    std::cout << "drawn bounds " << bounds[0] << ".." << bounds[1] << ", " << bounds[2] << ".." << bounds[3] << ", " << bounds[4]
              << ".." << bounds[5] << '\n';
    BS_CHECK(bounds[0] <= expected[0] + 1e-6 && expected[0] <= bounds[1] + 1e-6);
    BS_CHECK(bounds[2] <= expected[1] + 1e-6 && expected[1] <= bounds[3] + 1e-6);
    // A model that cannot be placed is not drawn (not drawn in the wrong frame), and said.
    view.setModels({warped, surface}, [&scene](const ModelNode& model) { return childToWorldMatrix(scene, model); });
    BS_CHECK(view.modelActor(0) && !view.modelActor(1));
    BS_CHECK(view.problems().size() == 1 && view.problems().front().contains("warped model"));
    // Without placement, where the data are.
    view.setModels({surface});
    view.modelActor(0)->GetBounds(bounds);
    BS_CHECK_NEAR(bounds[1], 30.5, 1e-6);

    // Arrows: from initial (point - d) to final (point), only for points that moved.
    vtkNew<vtkDoubleArray> displacement;
    displacement->SetName("Displacement");
    displacement->SetNumberOfComponents(3);
    const double d[4][3] = {{0, 0, 0}, {0, 0, 5}, {0, 0, 5}, {0, 0, 5}};
    for (const auto& v : d) displacement->InsertNextTuple(v);
    surface->mesh()->GetPointData()->AddArray(displacement);
    view.setModels({surface});
    BS_CHECK(view.displacementArrowCount() == 0); // hidden until asked for
    view.setDisplacementArrowsVisible(true);
    BS_CHECK_MSG(view.displacementArrowCount() == 3, view.displacementArrowCount());
    view.setDisplacementArrowsVisible(false);
    BS_CHECK(view.displacementArrowCount() == 0);

    // The slice planes through the cursor, across the bounds.
    PhysicalPoint cursor;
    cursor[0] = 4.0;
    cursor[1] = -7.0;
    cursor[2] = 12.0;
    view.setSlicePlanes(cursor, {-50, 50, -60, 60, -30, 30});
    view.setSlicePlanesVisible(true);
    for (int axis = 0; axis < 3; ++axis) {
      vtkActor* plane = view.slicePlaneActor(axis);
      BS_CHECK(plane->GetVisibility());
      plane->GetBounds(bounds);
      BS_CHECK_NEAR(bounds[2 * axis], cursor[unsigned(axis)], 1e-9);
      BS_CHECK_NEAR(bounds[2 * axis + 1], cursor[unsigned(axis)], 1e-9);
      const int u = (axis + 1) % 3;
      BS_CHECK_NEAR(bounds[2 * u + 1] - bounds[2 * u], u == 0 ? 100.0 : u == 1 ? 120.0 : 60.0, 1e-9);
    }
    view.setSlicePlanesVisible(false);
    BS_CHECK(!view.slicePlaneActor(2)->GetVisibility());
  });
}
