// SPDX-License-Identifier: MIT
// voxlight phantom NAME -o FILE [--size N]: synthetic volumes (see core/phantoms.h).
#include <cstdio>
#include <memory>

#include "app/cli_support.h"
#include "app/output_files.h"
#include "core/phantoms.h"
#include "core/timing.h"
#include "io/volume_io.h"

namespace voxlight::app {

Command addPhantomCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("phantom", "Generate a synthetic volume (deterministic)");
    auto name = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto size = std::make_shared<int>(0);
    auto seed = std::make_shared<std::uint64_t>(1);
    auto list = std::make_shared<bool>(false);
    auto quiet = std::make_shared<bool>(false);
    std::string names;
    for (const auto& [n, d] : core::phantomCatalog()) names += "\n  " + n + ": " + d;
    c.sub->add_option("NAME", *name, "Phantom name:" + names);
    c.sub->add_option("-o,--output", *out, "Output volume (.nii.gz, .nii, .vti, .mha)");
    c.sub->add_option("--size", *size, "Voxels per axis (default: the phantom's own)");
    c.sub->add_option("--seed", *seed, "Noise seed (torso)")->check(wholeNumber());
    c.sub->add_flag("--list", *list, "List the phantoms and exit");
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output");
    CLI::App* sub = c.sub;
    c.run = [=] {
        if (*list) {
            for (const auto& [n, d] : core::phantomCatalog())
                std::printf("%-10s %s\n", n.c_str(), d.c_str());
            return kExitOk;
        }
        if (name->empty() || out->empty())
            throw InputError("command line", "phantom", "needs a NAME and -o FILE",
                             "e.g. voxlight phantom torso -o torso.nii.gz (see --list)");
        // Fail before the work, not after: the format, then the path (output_files.h).
        io::checkVolumeOutputPath(*out);
        checkOutputs({{"--output", *out, {}}});
        // 0 means "the phantom's own size" to makePhantom; said on the command line it is a
        // size like any other (-5 and 0 used to give the default silently).
        if (sub->count("--size") && (*size < 8 || *size > 1024))
            throw InputError("phantom " + *name, "--size",
                             "must be between 8 and 1024, got " + std::to_string(*size),
                             "pass --size N with 8 <= N <= 1024, or leave it out for the "
                             "phantom's own size");
        if (sub->count("--seed") && *name != "torso")
            std::fprintf(stderr,
                         "voxlight: warning: --seed changes the torso's noise only; phantom '%s' "
                         "has none\n",
                         name->c_str());
        core::PhantomOptions o;
        o.size = *size;
        o.seed = *seed;
        core::Stopwatch sw;
        const core::Volume v = core::makePhantom(*name, o, terminalProgress(*quiet));
        OutputFiles files;
        throwIfCancelled();
        files.write(*out, "--output",
                    [&](const std::filesystem::path& p) { io::writeVolume(v, p); });
        throwIfCancelled();  // Ctrl-C while VTK wrote: the temporary goes, nothing is left
        files.commit();
        if (!*quiet)
            std::fprintf(stderr, "wrote %s: %s (%.2f s)\n", out->c_str(),
                         (std::ostringstream() << v.geometry()).str().c_str(), sw.seconds());
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
