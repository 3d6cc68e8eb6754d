// brainshift bench read-scene: reads a .mrml scene and its data files as the host-free side of
// BrainShift does (MRML/SceneIO), and lists its nodes. The seeded fuzz run of issue 18
// (Testing/Benchmarks/fuzz/run.sh) feeds it corrupted scenes: a bad scene is one line on stderr
// and exit 2, never a crash.
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "SceneIO.h"

#include <iostream>
#include <memory>

namespace brainshift::cli {
namespace fs = std::filesystem;

void addFuzzBenchCommand(CLI::App& bench)
{
  auto scene = std::make_shared<fs::path>();
  CLI::App* command = bench.add_subcommand(
    "read-scene", "Read a .mrml scene and its data files (as 3D Slicer would load them) and list its nodes; "
                  "the reader the fuzz run (Testing/Benchmarks/fuzz) feeds corrupted scenes");
  command->add_option("--scene", *scene, "the .mrml file")->required();
  command->callback([scene] {
    std::error_code ec;
    if (!fs::is_regular_file(*scene, ec)) throw InputError(scene->string() + ": not a file");
    Scene read;
    readScene(read, *scene);
    for (const auto& node : read.nodes()) std::cout << node->slicerClassName() << ' ' << node->id() << ' ' << node->name() << '\n';
    std::cout << read.nodes().size() << " nodes\n";
  });
}

} // namespace brainshift::cli
