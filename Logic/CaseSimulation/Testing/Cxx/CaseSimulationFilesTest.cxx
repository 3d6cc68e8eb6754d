// The case on disk: every file of CaseFiles, readable, and the same case when read back.
#include "BrainShiftTestingSupport.h"
#include "CaseSimulationTestSupport.h"
#include "LandmarkEvaluation.h"
#include "TransformIO.h"
#include "VolumeIO.h"

#include <nlohmann/json.hpp>

#include <fstream>

int CaseSimulationFilesTest(int, char*[])
{
  return brainshift::testing::runTest("CaseSimulationFilesTest", [] {
    using namespace brainshift;
    namespace fs = std::filesystem;
    const SimulatedCase& c = testing::smallCase();
    const fs::path folder = testing::temporaryFolder("CaseSimulationFilesTest");
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    writeCase(c, parameters, folder);
    const CaseFiles files(folder);
    for (const fs::path& f : {files.preopImage, files.preopLabels, files.preopFmri, files.intraopImage, files.landmarks,
                              files.truthIntraopLabels, files.truthTransform, files.truthRigidTransform, files.description}) {
      BS_CHECK_MSG(fs::is_regular_file(f) && fs::file_size(f) > 0, f);
    }
    for (const auto& entry : fs::directory_iterator(folder)) {
      BS_CHECK_MSG(entry.path().filename().string().rfind(".tmp-", 0) != 0, "left over: " << entry.path());
    }
    // The intraoperative scan is stored as int16, as a scanner would.
    const ScalarImage::Pointer intraop = readScalarVolume(files.intraopImage);
    BS_CHECK(ImageGeometry::of(intraop.GetPointer()).sameGridAs(ImageGeometry::of(c.intraopImage.GetPointer())));
    BS_CHECK_NEAR(intraop->GetPixel({{40, 50, 15}}), c.intraopImage->GetPixel({{40, 50, 15}}), 0.5);

    // The truth read back maps the landmarks as the one in memory does.
    const std::vector<LandmarkPair> landmarks = readLandmarksCsv(files.landmarks);
    BS_CHECK(landmarks.size() == c.landmarks.size());
    const SpatialTransform::Pointer truth = readTransform(files.truthTransform);
    BS_CHECK_MSG(evaluateTransform(*truth, landmarks).overall.maxMm < 0.02, "truth read back");
    for (std::size_t i = 0; i < landmarks.size(); ++i) {
      BS_CHECK(landmarks[i].preop.EuclideanDistanceTo(c.landmarks[i].preop) < 1e-9);
    }

    std::ifstream description(files.description);
    const nlohmann::json json = nlohmann::json::parse(description);
    BS_CHECK(json["parameters"]["seed"].get<std::uint64_t>() == parameters.seed);
    BS_CHECK_NEAR(json["figures"]["max_brain_displacement_mm"].get<double>(), c.figures.maxBrainDisplacementMm, 1e-9);
  });
}
