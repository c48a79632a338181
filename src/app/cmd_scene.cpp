// SPDX-License-Identifier: MIT
// voxlight scene SCENE.json|VOLUME [--set key=value]... [--view V] [--init]: validate a scene
// (after overrides) and print it resolved. --init prints a complete starter scene — every key at
// its value, defaults included, the transfer function chosen from the data — so that users edit a
// file instead of reading a header; rendering it renders what `render VOLUME` renders.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>

#include "app/cli_support.h"
#include "app/volume_options.h"
#include "core/files.h"
#include "io/scene.h"
#include "optics/presets.h"
#include "pipeline/pipeline.h"
#include "pipeline/registry.h"
#include "pipeline/scene_inputs.h"

namespace voxlight::app {

Command addSceneCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand(
        "scene", "Validate a scene (with --set overrides) and print it; --init writes a starter");
    auto path = std::make_shared<std::string>();
    auto sets = std::make_shared<std::vector<std::string>>();
    auto view = std::make_shared<std::string>();
    auto init = std::make_shared<bool>(false);
    c.sub->add_option("INPUT", *path, "Scene JSON, or a volume file / DICOM folder")->required();
    c.sub->add_option("--set", *sets, "Override a key by dotted path, e.g. --set camera.azimuth=45")
        ->allow_extra_args(false);
    auto shorthands = addVolumeShorthands(*c.sub);
    c.sub->add_option("--view", *view, "Look from this side of the patient")
        ->check(CLI::IsMember(viewNames()));
    c.sub->add_flag("--init", *init,
                    "Print a complete scene with every key at its default (reads the volume to "
                    "choose the transfer function): voxlight scene --init ct.nii.gz > scene.json");
    c.run = [=] {
        const io::Scene s = loadInput(*path, shorthands->overrides(*sets), *view);
        // Everything `render` checks before loading the volume (method, params, effects, preset),
        // so that "valid" here means the scene renders.
        const pipeline::Plan plan = pipeline::Session().plan(s);
        // ... and the volume it names is there (loading it is render's work; a missing file or
        // a FIFO is not a valid scene).
        if (!s.volume.path.empty()) {
            std::error_code ec;
            if (!std::filesystem::exists(s.volume.path, ec))
                throw InputError(s.volume.path.string(), "path", "does not exist",
                                 "check the path (relative to the scene file's folder)");
            core::refuseSpecialFile(s.volume.path);
        }
        // ... and its lights build: an environment map that is missing, 8-bit or too small is
        // refused here as render refuses it (the map is read and projected: a second or so).
        (void)pipeline::buildLights(s);
        if (!*init) {
            std::cout << jsonForStdout(s.document, *path) << "\n";
            std::cerr << s.source << ": valid (method " << plan.method << ", " << s.lights.size()
                      << " light(s), " << s.clipPlanes.size() << " clip plane(s))\n";
            return kExitOk;
        }
        nlohmann::json doc = io::sceneDocument(s);
        if (!doc.contains("description"))
            doc["description"] =
                "Starter scene written by voxlight scene --init. Every key is at its default; "
                "\"lights\": [] means a headlight that follows the camera. Schema: src/io/scene.h.";
        if (s.transferFunction.preset.empty() && s.transferFunction.points.empty()) {
            const core::Volume v = pipeline::loadSceneVolume(s, terminalProgress(true));
            // The loader's warnings (a tilted DICOM series resampled, ...), as `info` and
            // `render` print them: stderr, so that stdout stays the scene.
            for (const auto& w : v.warnings)
                std::fprintf(stderr, "voxlight: warning: %s\n", w.c_str());
            doc["transfer_function"]["preset"] = optics::defaultPresetName(v);
        }
        doc["method"]["params"] = plan.params;
        if (!s.effectsGiven)
            if (const auto* m = pipeline::MethodRegistry::instance().find(s.method.name))
                doc["effects"] = m->effects;
        // A path's non-UTF-8 bytes replaced would name no file: refused (jsonForStdout).
        std::cout << jsonForStdout(doc, *path) << "\n";
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
