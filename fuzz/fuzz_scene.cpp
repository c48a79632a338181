// SPDX-License-Identifier: MIT
// Scene JSON as `voxlight scene SCENE.json` reads it: io::loadScene (parse, depth and number
// checks, validation), the pipeline's plan of it (method, parameters, effects, presets), and the
// resolved document printed back.
#include "fuzz_common.h"
#include "io/scene.h"
#include "pipeline/pipeline.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace voxlight;
    const auto path = fuzz::writeParts(data, size, {"in.json"});
    fuzz::runLoader([&] {
        const io::Scene s = io::loadScene(path);
        (void)pipeline::Session().plan(s);
        (void)s.document.dump(2);
    });
    return 0;
}
