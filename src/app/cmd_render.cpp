// SPDX-License-Identifier: MIT
// voxlight render SCENE.json|VOLUME -o OUT.png [--view V] [--exr OUT.exr] [--std-error E.exr]
//                 [--display-exr D.exr] [--stats STATS.json] [--set key=value]... [--cache DIR]
//                 [--frames N] [--explain]
// Renders a scene through the pipeline (its method's plan of stages): display-mapped PNG, linear
// EXR, stats JSON. A volume file or DICOM folder is a scene on its own (io::volumeScene: the
// modality's preset, an anterior view fitted to what it shows, a headlight). --explain prints the
// plan and what each stage would do, and renders nothing.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>

#include "app/cli_support.h"
#include "app/output_files.h"
#include "app/render_output.h"
#include "app/volume_options.h"
#include "core/timing.h"
#include "io/image.h"
#include "io/scene.h"
#include "pipeline/pipeline.h"

namespace voxlight::app {

namespace {
namespace fs = std::filesystem;

std::string fixed(double v, int decimals) {
    char b[32];
    std::snprintf(b, sizeof b, "%.*f", decimals, v);
    return b;
}
/// Narrowest stage column of --explain (the names of the ray caster's own stages fit).
constexpr int kExplainNameWidth = 18;

/// The record of an output stage (written after the pipeline's stages, by this command).
pipeline::StageRecord outputRecord(const std::string& name, const std::string& path,
                                   const std::string& option) {
    pipeline::StageRecord r;
    r.name = name;
    r.kind = pipeline::StageKind::Frame;
    r.ran = !path.empty();
    r.inputs = {"render"};
    r.reason = path.empty() ? "not needed: no " + option + " given" : "computed: " + path;
    return r;
}

}  // namespace

Command addRenderCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("render", "Render a scene (or a volume with defaults)");
    auto scene = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto exr = std::make_shared<std::string>();
    auto stdErr = std::make_shared<std::string>();
    auto displayExr = std::make_shared<std::string>();
    auto stats = std::make_shared<std::string>();
    auto sets = std::make_shared<std::vector<std::string>>();
    auto quiet = std::make_shared<bool>(false);
    auto frames = std::make_shared<int>(1);
    auto cacheDir = std::make_shared<std::string>();
    auto explain = std::make_shared<bool>(false);
    auto view = std::make_shared<std::string>();
    c.sub
        ->add_option("INPUT", *scene,
                     "Scene JSON, or a volume file / DICOM folder to render with defaults")
        ->required();
    c.sub->add_option("-o,--output", *out,
                      "Display image (.png, .jpg, .tif, .bmp; image.display picks the mapping)");
    c.sub
        ->add_option("--view", *view,
                     "Look from this side of the patient (replaces the scene's camera placement)")
        ->check(CLI::IsMember(viewNames()));
    c.sub->add_option("--exr", *exr, "Also write the linear radiance (+ alpha) as OpenEXR");
    c.sub->add_option("--std-error", *stdErr,
                      "Also write the per-pixel standard error of the radiance as OpenEXR "
                      "(method pathtrace)");
    c.sub->add_option("--display-exr", *displayExr,
                      "Also write the linear image the display image is made from as OpenEXR "
                      "(pathtrace: denoised when the denoiser ran; otherwise the --exr image)");
    c.sub->add_option("--stats", *stats, "Write stages, timings and parameters as JSON");
    c.sub->add_option("--set", *sets, "Override a scene key, e.g. --set camera.azimuth=45")
        ->allow_extra_args(false);
    auto shorthands = addVolumeShorthands(*c.sub);
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
            const io::Scene s = loadInput(*scene, shorthands->overrides(*sets), *view);
            std::vector<pipeline::StageRecord> plan = session.explain(s);
            plan.push_back(outputRecord("write_image", *out, "-o"));
            plan.push_back(outputRecord("write_exr", *exr, "--exr"));
            plan.push_back(outputRecord("write_std_error", *stdErr, "--std-error"));
            plan.push_back(outputRecord("write_display_exr", *displayExr, "--display-exr"));
            plan.push_back(outputRecord("write_stats", *stats, "--stats"));
            // The stage column fits the longest name (hierarchical_visibility is 23 characters).
            int width = kExplainNameWidth;
            for (const auto& r : plan) width = std::max(width, int(r.name.size()));
            std::printf("%-*s %-10s %-8s %-16s %s\n", width, "stage", "kind", "runs", "key",
                        "reason");
            for (const auto& r : plan) {
                std::string inputs;
                for (const auto& i : r.inputs) inputs += (inputs.empty() ? "" : ", ") + i;
                std::printf("%-*s %-10s %-8s %-16s %s  [reads: %s]\n", width, r.name.c_str(),
                            pipeline::toString(r.kind).c_str(), r.ran ? "yes" : "no",
                            r.key.empty() ? "-" : r.key.c_str(), r.reason.c_str(), inputs.c_str());
            }
            return kExitOk;
        }
        if (out->empty())
            throw InputError("command line", "--output", "is required",
                             "give -o OUT.png (or --explain to only print the plan)");
        // Every output is checked before the work and committed together after it
        // (output_files.h): a bad path fails now, and a failure or Ctrl-C leaves nothing behind.
        checkOutputs({{"--output", *out, {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"}},
                      {"--exr", *exr, {".exr"}},
                      {"--std-error", *stdErr, {".exr"}},
                      {"--display-exr", *displayExr, {".exr"}},
                      {"--stats", *stats, {".json"}}},
                     {{"INPUT", *scene}});
        const io::Scene s = loadInput(*scene, shorthands->overrides(*sets), *view);
        {
            // The files the scene reads: an environment map written over by -o or --exr.
            std::vector<std::pair<std::string, std::filesystem::path>> inputs = sceneFileInputs(s);
            inputs.emplace_back("INPUT", *scene);
            checkOutputs({{"--output", *out, {}},
                          {"--exr", *exr, {}},
                          {"--std-error", *stdErr, {}},
                          {"--display-exr", *displayExr, {}},
                          {"--stats", *stats, {}}},
                         inputs);
        }
        if (!stdErr->empty() && s.method.name != "pathtrace")
            throw InputError("command line", "--std-error",
                             "method '" + s.method.name + "' makes no standard-error image",
                             "use --std-error with --set method.name=pathtrace, or leave it out");
        // OpenImageIO loads beside the stages after the volume read (io/image.h; not beside it:
        // a reading child's fork waits for a background load).
        std::optional<io::ImageModulePreload> imageSupport;
        pipeline::RunOptions runOptions;
        runOptions.frames = *frames;
        runOptions.afterStage = preloadImagesAfterInputs(imageSupport);
        pipeline::RunResult r = session.run(s, runOptions, terminalProgress(*quiet));

        OutputFiles files;
        core::Stopwatch sw;
        throwIfCancelled();
        // The display image: pathtrace's denoised one when it made one (the EXR stays the raw
        // linear estimate).
        const core::ImageRGBA& shown = shownImage(r);
        files.write(*out, "--output", [&](const fs::path& p) { writeDisplayImage(r, s, p); });
        r.stages.push_back(outputRecord("write_image", *out, "-o"));
        r.stages.back().seconds = sw.seconds();
        sw.restart();
        if (!exr->empty()) {
            throwIfCancelled();
            files.write(*exr, "--exr", [&](const fs::path& p) { io::writeImage(r.image, p); });
        }
        r.stages.push_back(outputRecord("write_exr", *exr, "--exr"));
        r.stages.back().seconds = sw.seconds();
        sw.restart();
        if (!stdErr->empty()) {
            throwIfCancelled();
            const auto it = r.images.find("std_error");
            if (it == r.images.end())
                throw InternalError("method '" + r.method + "' made no std_error image");
            files.write(*stdErr, "--std-error",
                        [&](const fs::path& p) { io::writeImage(it->second, p); });
            const auto& px = it->second.pixels;
            if (std::any_of(px.begin(), px.end(), [](float v) { return std::isnan(v); }))
                std::fprintf(stderr,
                             "voxlight: warning: --std-error: pixels with one sample have no "
                             "error estimate and are written as NaN (raise method.params.spp to "
                             "2 or more)\n");
        }
        r.stages.push_back(outputRecord("write_std_error", *stdErr, "--std-error"));
        r.stages.back().seconds = sw.seconds();
        sw.restart();
        if (!displayExr->empty()) {
            throwIfCancelled();
            files.write(*displayExr, "--display-exr",
                        [&](const fs::path& p) { io::writeImage(shown, p); });
        }
        r.stages.push_back(outputRecord("write_display_exr", *displayExr, "--display-exr"));
        r.stages.back().seconds = sw.seconds();
        if (!stats->empty()) {
            throwIfCancelled();
            nlohmann::json j = pipeline::statsJson(r, total.seconds());
            j["scene"] = s.document;
            // Paths from the command line may be any bytes: replaced, not a failure after the work.
            const std::string text =
                j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
            files.write(*stats, "--stats", [&](const fs::path& p) { writeTextFile(p, text); });
        }
        throwIfCancelled();
        files.commit();
        for (const auto& w : r.warnings) std::fprintf(stderr, "voxlight: warning: %s\n", w.c_str());
        if (!*quiet) {
            // The image's own time: a cached reference's frame only copies it, so name that.
            std::string when = "render " + fixed(r.stage(r.imageStage).seconds, 3) + " s";
            for (const auto& st : r.stages)
                if (st.name == "reference")
                    when = st.ran ? "reference " + fixed(st.seconds, 1) + " s" : "reference cached";
            std::fprintf(stderr, "wrote %s (%dx%d, %s, %s, total %.2f s)\n", out->c_str(),
                         r.image.width, r.image.height, s.method.name.c_str(), when.c_str(),
                         total.seconds());
        }
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
