// SPDX-License-Identifier: MIT
// voxlight view [SCENE.json | VOLUME] [--set key=value]... [--screenshot OUT.png --frames N] [--log]
//               [--script STEPS.json] [--record SESSION.json] [--renderer auto|gpu|cpu]
// The interactive viewer (viewer/viewer.h). The input given on the command line is loaded and
// checked before the window opens, so a bad scene or a missing volume fails as every command does
// (one line, exit 2). --screenshot renders N frames without interaction, waits for the
// full-resolution image and writes the window's content (.png), or the image area's linear
// radiance as `render --exr` writes it (.exr) (temporary file, then rename).
// --script runs UI steps (viewer/view_state.h ScriptStep) through the mouse's code paths;
// --record writes the exploration as a session (`voxlight replay` re-renders it) on exit.
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>

#include "app/cli_support.h"
#include "app/output_files.h"
#include "app/volume_options.h"
#include "io/image.h"
#include "io/scene.h"
#include "pipeline/scene_inputs.h"
#include "session/session.h"
#include "viewer/viewer.h"

namespace voxlight::app {

Command addViewCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("view", "Open the interactive viewer (GLFW + OpenGL + Dear ImGui)");
    auto input = std::make_shared<std::string>();
    auto sets = std::make_shared<std::vector<std::string>>();
    auto screenshot = std::make_shared<std::string>();
    auto frames = std::make_shared<int>(1);
    auto log = std::make_shared<bool>(false);
    auto script = std::make_shared<std::string>();
    auto record = std::make_shared<std::string>();
    auto quiet = std::make_shared<bool>(false);
    auto renderer = std::make_shared<std::string>("auto");
    auto glSliceMs = std::make_shared<double>(viewer::kDefaultGlSliceSeconds * 1e3);
    c.sub->add_option("INPUT", *input,
                      "Scene JSON, or a volume file / DICOM folder to view with defaults");
    c.sub->add_option("--set", *sets, "Override a scene key, e.g. --set camera.azimuth=45")
        ->allow_extra_args(false);
    auto shorthands = addVolumeShorthands(*c.sub);
    c.sub->add_option("--screenshot", *screenshot,
                      "Scripted run: write the window (.png) or the image's linear radiance "
                      "(.exr) once the full-resolution image shows, then exit");
    c.sub->add_option("--frames", *frames, "Scripted run: draw at least N UI frames first")
        ->check(CLI::Range(1, 100000));
    c.sub->add_option(
        "--script", *script,
        "Run UI steps from a JSON file ([{\"orbit\": [40, 0]}, {\"view\": \"L\"}, "
        "{\"window\": [30, -20]}, {\"drag\": {\"kind\": \"window\", \"by\": [30, -20], "
        "\"frames\": 60}}, {\"zoom\": 2}, {\"pan\": [10, 0]}, "
        "{\"clip_add\": {\"normal\": \"camera\"}}, {\"clip_drag\": {\"index\": 0, "
        "\"by\": [0, -40], \"frames\": 30}}, {\"light_add\": {\"type\": "
        "\"directional\"}}, {\"light_turn\": {\"index\": 0, \"azimuth\": 30}}]) as "
        "the mouse, keys and panels would; every step: README, Viewer");
    c.sub->add_option("--record", *record,
                      "Record the exploration as a session (JSON) for voxlight replay; written "
                      "when the viewer closes");
    c.sub
        ->add_option("--renderer", *renderer,
                     "Which path draws the image: auto (measure both when a volume is loaded, "
                     "keep the faster), gpu (the GLSL ray caster where it can), cpu")
        ->check(CLI::IsMember({"auto", "gpu", "cpu"}));
    c.sub
        ->add_option("--gl-slice-ms", *glSliceMs,
                     "GLSL path: GL time per UI frame; a longer frame is rendered in slices of "
                     "rows over several UI frames (0: whole frames, the UI waits for each)")
        ->check(finiteNumber())
        ->check(CLI::Range(0.0, 10000.0));
    c.sub->add_flag("--log", *log, "Log UI frame times and render times on stderr");
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output while loading");
    c.run = [=] {
        // The files the run reads: --record over --script replaced the script with the session.
        std::vector<std::pair<std::string, std::filesystem::path>> inputs = {{"INPUT", *input},
                                                                             {"--script", *script}};
        const std::vector<OutputSpec> outputs = {{"--screenshot", *screenshot, {".png", ".exr"}},
                                                 {"--record", *record, {".json"}}};
        checkOutputs(outputs, inputs);
        if (!screenshot->empty()) {
            if (input->empty())
                throw InputError("command line", "--screenshot", "needs a scene or volume",
                                 "give SCENE.json or a volume before --screenshot");
        }
        if (!record->empty()) {
            if (input->empty())
                throw InputError("command line", "--record", "needs a scene or volume",
                                 "give SCENE.json or a volume before --record");
        }
        std::vector<viewer::ScriptStep> steps;
        if (!script->empty()) steps = viewer::parseScript(io::readJsonFile(*script), *script);
        std::optional<viewer::LoadedScene> initial;
        if (!input->empty()) {
            io::Scene scene = loadInput(*input, shorthands->overrides(*sets));
            for (auto& in : sceneFileInputs(scene)) inputs.push_back(std::move(in));
            checkOutputs(outputs, inputs);  // the scene's volume and maps
            // What is cheap to refuse first, then the display: before a load that may take
            // minutes (a missing display was said only after it; probe).
            if (!screenshot->empty()) viewer::checkScreenshotSize(scene);
            pipeline::checkSceneVolumeExists(scene);
            viewer::requireDisplay();
            initial = viewer::prepareScene(std::move(scene), terminalProgress(*quiet));
        }
        // A session written under Ctrl-C is said to be there (runGuarded would say nothing was).
        std::error_code ec;
        const auto recordTime = [&] {
            return record->empty() || !std::filesystem::exists(*record, ec)
                       ? std::filesystem::file_time_type::min()
                       : std::filesystem::last_write_time(*record, ec);
        };
        const auto recordBefore = recordTime();
        viewer::ViewerOptions options;
        options.screenshot = *screenshot;
        options.frames = *frames;
        options.log = *log;
        options.renderer = viewer::rendererChoiceFromString(*renderer);
        options.glSliceSeconds = *glSliceMs * 1e-3;
        options.script = std::move(steps);
        options.record = *record;
        options.quit = &cancelFlag();
        options.openInput = [](const std::string& path) { return loadInput(path, {}); };
        // A path typed in the panel replaces no file the run reads: the command line's inputs and
        // the files of the scene on screen (which may have been opened since).
        const auto checkPanelOutput = [inputs](const OutputSpec& out, const io::Scene& current) {
            auto all = inputs;
            all.emplace_back("the scene file", current.source);
            for (auto& in : sceneFileInputs(current)) all.push_back(std::move(in));
            checkOutputs({out}, all);
        };
        options.saveScreenshot = [checkPanelOutput](const core::ImageRGBA& image,
                                                    const std::string& path,
                                                    const io::Scene& current) {
            checkPanelOutput(
                {"screenshot", path, {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".exr"}},
                current);
            OutputFiles files;
            files.write(path, "screenshot",
                        [&](const std::filesystem::path& p) { io::writeImage(image, p); });
            files.commit();
        };
        // --record and the panel's Save: the same checked, atomic write as every output.
        options.saveSession = [checkPanelOutput, record = *record](const session::Session& s,
                                                                   const std::string& path,
                                                                   const io::Scene& current) {
            const std::string option = path == record ? "--record" : "session";
            checkPanelOutput({option, path, {".json"}}, current);
            OutputFiles files;
            files.write(path, option, [&](const std::filesystem::path& p) {
                writeTextFile(p, session::sessionText(s));
            });
            files.commit();
        };
        std::optional<core::ImageRGBA> shot = viewer::runViewer(options, std::move(initial));
        if (cancelFlag().load() && recordTime() != recordBefore) {
            std::fprintf(stderr, "\nvoxlight: cancelled; the session so far is in %s\n",
                         record->c_str());
            return kExitCancelled;
        }
        throwIfCancelled();
        if (!screenshot->empty()) {
            if (!shot)
                throw InputError("view", "--screenshot",
                                 "the window closed before the image was ready");
            OutputFiles files;
            files.write(*screenshot, "--screenshot",
                        [&](const std::filesystem::path& p) { io::writeImage(*shot, p); });
            files.commit();
            // A PNG is the window (panel at the right); an EXR the image area's linear radiance.
            std::string ext = std::filesystem::path(*screenshot).extension().string();
            for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
            if (!*quiet && ext != ".exr" && shot->width > viewer::kPanelWidth)
                std::fprintf(stderr, "wrote %s (%dx%d, image area %dx%d at the left)\n",
                             screenshot->c_str(), shot->width, shot->height,
                             shot->width - viewer::kPanelWidth, shot->height);
            else if (!*quiet)
                std::fprintf(stderr, "wrote %s (%dx%d, linear radiance of the image area)\n",
                             screenshot->c_str(), shot->width, shot->height);
        }
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
