// SPDX-License-Identifier: MIT
// voxlight render SCENE.json -o OUT.png [--exr OUT.exr] [--stats STATS.json] [--set key=value]...
//                 [--cache DIR] [--frames N] [--explain]
// Renders a scene through the pipeline (its method's plan of stages): tone-mapped sRGB PNG, linear
// EXR, stats JSON. --explain prints the plan and what each stage would do, and renders nothing.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

#include "app/cli_support.h"
#include "core/timing.h"
#include "io/image.h"
#include "io/scene.h"
#include "pipeline/pipeline.h"
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

/// The record of an output stage (written after the pipeline's stages, by this command).
pipeline::StageRecord outputRecord(const std::string& name, const std::string& path,
                                   const std::string& option) {
    pipeline::StageRecord r{name,      pipeline::StageKind::Frame, !path.empty(), "", 0.0, "",
                            {"render"}};
    r.reason = path.empty() ? "not needed: no " + option + " given" : "computed: " + path;
    return r;
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
    auto cacheDir = std::make_shared<std::string>();
    auto explain = std::make_shared<bool>(false);
    c.sub->add_option("SCENE", *scene, "Scene JSON")->required();
    c.sub->add_option("-o,--output", *out, "Tone-mapped sRGB image (.png, .jpg, .tif, .bmp)");
    c.sub->add_option("--exr", *exr, "Also write the linear radiance (+ alpha) as OpenEXR");
    c.sub->add_option("--stats", *stats, "Write stages, timings and parameters as JSON");
    c.sub->add_option("--set", *sets, "Override a scene key, e.g. --set camera.azimuth=45")
        ->allow_extra_args(false);
    c.sub
        ->add_option("--frames", *frames,
                     "Render the frame N times; stats report the median and every frame's time")
        ->check(CLI::Range(1, pipeline::kMaxFrames));
    c.sub->add_option(
        "--cache", *cacheDir,
        "Keep precomputed stages in DIR across runs (shared safely between processes)");
    c.sub->add_flag("--explain", *explain,
                    "Print the plan: each stage, what it reads, and whether it would run, be "
                    "cached or is not needed; render nothing");
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output");
    c.run = [=] {
        core::Stopwatch total;
        pipeline::Session session;
        if (!cacheDir->empty()) session.cache().setDirectory(*cacheDir);
        if (*explain) {
            const io::Scene s = io::loadScene(*scene, *sets);
            std::printf("%-18s %-10s %-8s %-16s %s\n", "stage", "kind", "runs", "key", "reason");
            std::vector<pipeline::StageRecord> plan = session.explain(s);
            plan.push_back(outputRecord("write_image", *out, "-o"));
            plan.push_back(outputRecord("write_exr", *exr, "--exr"));
            for (const auto& r : plan) {
                std::string inputs;
                for (const auto& i : r.inputs) inputs += (inputs.empty() ? "" : ", ") + i;
                std::printf("%-18s %-10s %-8s %-16s %s  [reads: %s]\n", r.name.c_str(),
                            pipeline::toString(r.kind).c_str(), r.ran ? "yes" : "no",
                            r.key.empty() ? "-" : r.key.c_str(), r.reason.c_str(), inputs.c_str());
            }
            return kExitOk;
        }
        if (out->empty())
            throw InputError("command line", "--output", "is required",
                             "give -o OUT.png (or --explain to only print the plan)");
        checkOutput(*out, {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"}, "--output");
        if (!exr->empty()) checkOutput(*exr, {".exr"}, "--exr");
        if (!stats->empty()) checkOutput(*stats, {".json"}, "--stats");
        const io::Scene s = io::loadScene(*scene, *sets);
        pipeline::RunResult r = session.run(s, {.frames = *frames}, terminalProgress(*quiet));

        core::Stopwatch sw;
        io::writeImage(render::toDisplay(r.image, float(s.image.exposureStops)), *out);
        r.stages.push_back(outputRecord("write_image", *out, "-o"));
        r.stages.back().seconds = sw.seconds();
        sw.restart();
        if (!exr->empty()) io::writeImage(r.image, *exr);
        r.stages.push_back(outputRecord("write_exr", *exr, "--exr"));
        r.stages.back().seconds = sw.seconds();
        if (!stats->empty()) {
            nlohmann::json j = pipeline::statsJson(r, total.seconds());
            j["scene"] = s.document;
            writeTextAtomically(*stats, j.dump(2));
        }
        for (const auto& w : r.warnings) std::fprintf(stderr, "voxlight: warning: %s\n", w.c_str());
        if (!*quiet)
            std::fprintf(stderr, "wrote %s (%dx%d, %s, render %.3f s, total %.2f s)\n",
                         out->c_str(), r.image.width, r.image.height, s.method.name.c_str(),
                         r.stage(r.imageStage).seconds, total.seconds());
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
