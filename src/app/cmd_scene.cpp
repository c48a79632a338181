// SPDX-License-Identifier: MIT
// voxlight scene SCENE.json [--set key=value]...: validate a scene (after overrides) and print it
// resolved.
#include <iostream>
#include <memory>

#include "app/cli_support.h"
#include "io/scene.h"
#include "pipeline/pipeline.h"

namespace voxlight::app {

Command addSceneCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("scene",
                               "Validate a scene file (with --set overrides) and print the result");
    auto path = std::make_shared<std::string>();
    auto sets = std::make_shared<std::vector<std::string>>();
    c.sub->add_option("SCENE", *path, "Scene JSON")->required();
    c.sub->add_option("--set", *sets, "Override a key by dotted path, e.g. --set camera.azimuth=45")
        ->allow_extra_args(false);
    c.run = [=] {
        const io::Scene s = io::loadScene(*path, *sets);
        // Everything `render` checks before loading the volume (method, params, effects, preset),
        // so that "valid" here means the scene renders.
        const pipeline::Plan plan = pipeline::Session().plan(s);
        std::cout << s.document.dump(2) << "\n";
        std::cerr << s.source << ": valid (method " << plan.method << ", " << s.lights.size()
                  << " light(s), " << s.clipPlanes.size() << " clip plane(s))\n";
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
