// SPDX-License-Identifier: MIT
// voxlight render SCENE.json -o OUT.png [--exr OUT.exr] [--stats STATS.json] [--set key=value]...
// Renders a scene with the CPU ray caster: tone-mapped sRGB PNG, linear EXR, stats JSON.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

#include "app/cli_support.h"
#include "core/timing.h"
#include "io/image.h"
#include "io/scene.h"
#include "render/scene_render.h"
#include "render/tonemap.h"

namespace voxlight::app {

namespace {
namespace fs = std::filesystem;

std::string lowerExtension(const fs::path& p) {
    std::string e = p.extension().string();
    for (auto& ch : e) ch = char(std::tolower(static_cast<unsigned char>(ch)));
    return e;
}

/// Fails before the work, not after: wrong extension or missing directory.
void checkOutput(const std::string& path, const std::vector<std::string>& extensions,
                 const std::string& option) {
    const fs::path p(path);
    const std::string ext = lowerExtension(p);
    if (std::find(extensions.begin(), extensions.end(), ext) == extensions.end()) {
        std::string list;
        for (const auto& e : extensions) list += (list.empty() ? "" : ", ") + e;
        throw InputError("command line", option, "'" + path + "' has an unsupported extension",
                         "use one of: " + list);
    }
    const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
    if (!fs::is_directory(dir))
        throw InputError("command line", option, "directory '" + dir.string() + "' does not exist",
                         "create it first");
}

/// Writes text to a temporary file beside `path` and renames it (nothing half-written).
void writeTextAtomically(const fs::path& path, const std::string& text) {
    const fs::path tmp = path.string() + ".tmp";
    {
        std::ofstream out(tmp);
        out << text << "\n";
        if (!out) throw InputError(path.string(), "", "cannot be written", "check permissions");
    }
    fs::rename(tmp, path);
}
}  // namespace

Command addRenderCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("render", "Render a scene with the CPU ray caster");
    auto scene = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto exr = std::make_shared<std::string>();
    auto stats = std::make_shared<std::string>();
    auto sets = std::make_shared<std::vector<std::string>>();
    auto quiet = std::make_shared<bool>(false);
    auto frames = std::make_shared<int>(1);
    c.sub->add_option("SCENE", *scene, "Scene JSON")->required();
    c.sub->add_option("-o,--output", *out, "Tone-mapped sRGB image (.png, .jpg, .tif, .bmp)")
        ->required();
    c.sub->add_option("--exr", *exr, "Also write the linear radiance (+ alpha) as OpenEXR");
    c.sub->add_option("--stats", *stats, "Write stages, timings and parameters as JSON");
    c.sub->add_option("--set", *sets, "Override a scene key, e.g. --set camera.azimuth=45")
        ->allow_extra_args(false);
    c.sub
        ->add_option("--frames", *frames,
                     "Render the frame N times; stats report the median and every frame's time")
        ->check(CLI::Range(1, render::kMaxFrames));
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output");
    c.run = [=] {
        core::Stopwatch total;
        checkOutput(*out, {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"}, "--output");
        if (!exr->empty()) checkOutput(*exr, {".exr"}, "--exr");
        if (!stats->empty()) checkOutput(*stats, {".json"}, "--stats");
        const io::Scene s = io::loadScene(*scene, *sets);
        render::SceneRenderResult r = render::renderScene(s, terminalProgress(*quiet), *frames);

        core::Stopwatch sw;
        io::writeImage(render::toDisplay(r.film, float(s.image.exposureStops)), *out);
        r.stages.push_back({"write_image", true, *out, sw.seconds()});
        sw.restart();
        if (!exr->empty()) {
            io::writeImage(r.film, *exr);
            r.stages.push_back({"write_exr", true, *exr, sw.seconds()});
        } else {
            r.stages.push_back({"write_exr", false, "no --exr given", 0.0});
        }
        if (!stats->empty()) {
            nlohmann::json j = render::statsJson(r, total.seconds());
            j["scene"] = s.document;
            writeTextAtomically(*stats, j.dump(2));
        }
        if (!*quiet)
            std::fprintf(stderr, "wrote %s (%dx%d, %s, render %.3f s, total %.2f s)\n",
                         out->c_str(), r.film.width, r.film.height, s.method.name.c_str(),
                         r.stages.size() > 3 ? r.stages[3].seconds : 0.0, total.seconds());
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
