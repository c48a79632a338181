// SPDX-License-Identifier: MIT
// voxlight sweep SWEEP.json --out DIR [--only LABEL,...] [--cache DIR] [--no-images] [-q]
// What accuracy costs in time (analysis/sweep.h, docs/sweeps.md): renders the path-traced
// reference of the sweep's scene (kept in the pipeline's disk cache, DIR/cache unless --cache),
// then every variant of every run, and writes
//   DIR/results.csv          one row per variant: params, precompute s, frame s, memory, metrics
//   DIR/reference.png, .json the reference's display image; its spp, estimated error, seconds
//   DIR/images/ID.png        each variant's display image        (unless --no-images)
//   DIR/maps/ID.png          its FLIP error map (magma, 0..0.5)   (unless --no-images)
// tools/sweep_report.py DIR then draws the plots (error against time per method, the Pareto front)
// and writes DIR/report.md.
//
// Every variant is validated and planned before the reference renders, so a bad sweep fails at
// once with one line and writes nothing. Files are written atomically as they are made, and
// results.csv is rewritten once the reference is written (the rows --only keeps, or just the header)
// and after every variant: a Ctrl-C keeps every row finished so far.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <set>

#include "analysis/sweep.h"
#include "app/cli_support.h"
#include "app/output_files.h"
#include "app/ranks.h"
#include "app/render_output.h"
#include "core/timing.h"
#include "io/image.h"

namespace voxlight::app {

namespace {
namespace fs = std::filesystem;

/// Writes `writer`'s file to `target` via a temporary (complete or absent, never half-written).
void writeAtomically(const fs::path& target, const std::function<void(const fs::path&)>& writer) {
    OutputFiles files;
    files.write(target, "--out", writer);
    files.commit();
}

/// `rows` and the `kept` lines of an earlier run (index, line), in sweep order.
void writeCsv(const fs::path& path, const std::vector<analysis::SweepRow>& rows,
              const std::vector<std::pair<std::size_t, std::string>>& kept = {}) {
    std::vector<std::pair<std::size_t, std::string>> lines = kept;
    for (const auto& r : rows) lines.emplace_back(r.item.index, analysis::sweepCsvRow(r));
    std::stable_sort(lines.begin(), lines.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    std::string text = analysis::sweepCsvHeader();
    for (const auto& l : lines) text += "\n" + l.second;
    writeAtomically(path, [&](const fs::path& p) { writeTextFile(p, text); });
}

/// --only into a folder holding an earlier results.csv of the same sweep (same scene in its
/// reference.json, same header): the rows of the runs not chosen now, to keep (they were dropped,
/// their images left in images/ without rows; probe). A row is kept when its index and id are
/// that item's in this sweep's expansion.
std::vector<std::pair<std::size_t, std::string>> rowsToKeep(
    const fs::path& dir, const analysis::SweepSpec& spec,
    const std::vector<analysis::SweepItem>& all, const std::vector<std::string>& only) {
    std::vector<std::pair<std::size_t, std::string>> kept;
    try {
        std::ifstream ref(dir / "reference.json");
        if (!ref || nlohmann::json::parse(ref).value("scene", nlohmann::json()) != spec.scene)
            return kept;
    } catch (const std::exception&) {
        return kept;
    }
    std::ifstream in(dir / "results.csv");
    std::string line;
    if (!in || !std::getline(in, line) || line != analysis::sweepCsvHeader()) return kept;
    while (std::getline(in, line)) {
        char* end = nullptr;
        const std::size_t index = std::strtoull(line.c_str(), &end, 10);
        if (end == line.c_str() || index >= all.size()) continue;
        const analysis::SweepItem& it = all[index];
        if (std::find(only.begin(), only.end(), it.label) != only.end()) continue;
        if (line.rfind(std::to_string(index) + "," + it.id + ",", 0) == 0)
            kept.emplace_back(index, line);
    }
    return kept;
}

std::string describe(const analysis::SweepItem& it) {
    if (!it.axis.empty()) return it.label + " " + it.axis + "=" + it.value.dump();
    if (it.id.find("-grid-") != std::string::npos) return it.label + " " + it.params.dump();
    return it.label + " (base)";
}

}  // namespace

Command addSweepCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand(
        "sweep",
        "What accuracy costs in time: render every variant of a sweep and measure it against the "
        "path-traced reference (CSV, images, error maps; docs/sweeps.md)");
    auto sweepPath = std::make_shared<std::string>();
    auto outDir = std::make_shared<std::string>();
    auto only = std::make_shared<std::vector<std::string>>();
    auto cacheDir = std::make_shared<std::string>();
    auto noImages = std::make_shared<bool>(false);
    auto quiet = std::make_shared<bool>(false);
    c.sub->add_option("SWEEP", *sweepPath, "Sweep file (JSON)")->required();
    c.sub->add_option("--out", *outDir, "Folder for results.csv, images and maps (created)")
        ->required();
    c.sub->add_option("--only", *only, "Run only the runs with these labels (comma-separated)")
        ->delimiter(',');
    c.sub->add_option("--cache", *cacheDir,
                      "Disk cache for the reference (default: DIR/cache; shared safely)");
    c.sub->add_flag("--no-images", *noImages, "Write only results.csv and the reference");
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output");
    c.run = [=] {
        core::Stopwatch total;
        const Ranks ranks;  // before anything prints: the other ranks report through rank 0
        const bool lead = ranks.rank() == 0;
        const bool talk = lead && !*quiet;
        const fs::path dir = *outDir;
        std::error_code ec;
        if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
            throw InputError("command line", "--out", "'" + *outDir + "' is not a folder",
                             "give a folder (it is created if missing)");
        // The files the sweep writes into DIR must not be the sweep file it reads (a sweep kept
        // as DIR/reference.json was replaced by the first run's reference.json).
        for (const char* written : {"results.csv", "reference.json", "reference.png"})
            if (fs::equivalent(dir / written, *sweepPath, ec))
                throw InputError("command line", "--out",
                                 "'" + *outDir + "' would get a " + written +
                                     " that replaces the sweep file " + *sweepPath,
                                 "move the sweep file out of the folder, or give another --out");
        const analysis::SweepSpec spec = analysis::loadSweep(*sweepPath);
        std::vector<analysis::SweepItem> items = analysis::expandSweep(spec);
        std::vector<std::pair<std::size_t, std::string>> kept;
        if (!only->empty() && ranks.size() == 1) kept = rowsToKeep(dir, spec, items, *only);
        if (!only->empty()) {
            std::set<std::string> labels;
            for (const auto& r : spec.runs) labels.insert(r.label);
            for (const auto& l : *only)
                if (!labels.count(l))
                    throw InputError("command line", "--only", "no run is labelled '" + l + "'",
                                     "labels in " + *sweepPath + ": " +
                                         joinNames({labels.begin(), labels.end()}));
            std::erase_if(items, [&](const analysis::SweepItem& it) {
                return std::find(only->begin(), only->end(), it.label) == only->end();
            });
        }
        pipeline::Session variants, references;
        analysis::validateSweep(spec, items, variants);
        // OpenImageIO loads beside the stages after the first volume read (io/image.h; rank 0
        // writes the reference's PNG even with --no-images, the other ranks only variant images).
        std::optional<io::ImageModulePreload> imageSupport;

        // A bar on a terminal; in a log, one line per variant is enough (no 10 % lines).
        const core::Progress progress = talk && isatty(STDERR_FILENO)
                                            ? terminalProgress(false)
                                            : core::Progress({}, &cancelFlag());
        // What this run adds before the first variant: removed again when the reference meets
        // bad input only its stages find (an environment map that does not read), so that a
        // mistake leaves nothing written. The folders in creation order.
        std::vector<fs::path> added;
        // The outermost folder --out's creation makes (its missing parents are made too).
        fs::path outermost = fs::absolute(dir, ec).lexically_normal();
        while (!fs::exists(outermost.parent_path(), ec) && outermost.has_relative_path() &&
               outermost.parent_path() != outermost)
            outermost = outermost.parent_path();
        for (const fs::path& p :
             {outermost, dir / "images", dir / "maps", dir / "cache", dir / "reference.json"})
            if (!fs::exists(p, ec)) added.push_back(p);
        try {
            references.cache().setDirectory(cacheDir->empty() ? dir / "cache"
                                                              : fs::path(*cacheDir));
        } catch (const InputError&) {
            if (!cacheDir->empty()) throw;
            // DIR/cache is --out's folder: name the option that was given.
            throw InputError("command line", "--out", "cannot create folders in '" + *outDir + "'",
                             "choose a folder you can write to");
        }
        analysis::SweepRunner runner(spec, variants, references);
        if (lead || !*noImages) runner.setAfterStage(preloadImagesAfterInputs(imageSupport));

        // Rank 0 makes the folders and the reference (into the disk cache, where the other ranks
        // find it); the others wait for it, and stop when it failed.
        bool ok = true;
        std::exception_ptr failure;
        // Bad input only the reference's stages find, or a Ctrl-C there: what this run added goes.
        auto undo = [&] {
            ok = false;
            for (auto p = added.rbegin(); p != added.rend(); ++p) fs::remove_all(*p, ec);
        };
        if (lead) try {
                fs::create_directories(dir, ec);
                if (!*noImages) {
                    fs::create_directories(dir / "images", ec);
                    fs::create_directories(dir / "maps", ec);
                }
                if (ec || !fs::is_directory(dir))
                    throw InputError("command line", "--out", "cannot create '" + *outDir + "'",
                                     ec ? ec.message() : "check the path and its permissions");
                // Every reference a variant of this run needs: the sweep's first (reference.png),
                // then the runs' own (reference-N.png).
                std::set<std::size_t> needed = {0};
                for (const auto& it : items) needed.insert(it.reference);
                // Every reference rendered before any is written: a Ctrl-C or bad input while a
                // run's own reference renders left an earlier sweep's reference.png replaced
                // under its old results (probe).
                for (const std::size_t k : needed) (void)runner.reference(k, progress);
                nlohmann::json refJson;
                for (const std::size_t k : needed) {
                    const analysis::SweepReference& ref = runner.reference(k, progress);
                    const std::string png =
                        k == 0 ? "reference.png" : "reference-" + std::to_string(k) + ".png";
                    if (!fs::exists(dir / png, ec)) added.push_back(dir / png);
                    writeAtomically(dir / png,
                                    [&](const fs::path& p) { io::writeImage(ref.display, p); });
                    const auto& rs = spec.references[k];
                    nlohmann::json j = {
                        {"image", png},
                        {"method", rs.method},
                        {"params", rs.params},
                        {"effects", rs.effects ? nlohmann::json(*rs.effects) : nlohmann::json()},
                        {"spp", ref.spp},
                        {"relative_std_error", std::isfinite(ref.relativeStdError)
                                                   ? nlohmann::json(ref.relativeStdError)
                                                   : nlohmann::json()},
                        // The floor of its nrmse plots (the CSV's reference_error).
                        {"expected_nrmse", std::isfinite(ref.expectedNrmse)
                                               ? nlohmann::json(ref.expectedNrmse)
                                               : nlohmann::json()},
                        {"seconds", ref.seconds},
                        {"cached", ref.cached},
                        {"warnings", ref.warnings}};
                    if (k == 0) {
                        refJson = j;
                        refJson["sweep"] = spec.name;
                        refJson["frames"] = spec.frames;
                        refJson["ranks"] = ranks.size();
                        refJson["scene"] = spec.scene;
                        refJson["others"] = nlohmann::json::array();
                    } else {
                        refJson["others"].push_back(j);
                    }
                    if (talk)
                        std::fprintf(
                            stderr, "%s: reference %s %s: %s (%s)\n", spec.name.c_str(),
                            std::to_string(k).c_str(), rs.method.c_str(),
                            rs.method == "pathtrace"
                                ? (std::to_string(ref.spp) + " spp, estimated error " +
                                   std::to_string(100.0 * ref.relativeStdError) + " %")
                                      .c_str()
                                : rs.params.dump().c_str(),
                            ref.cached ? "cached" : (std::to_string(ref.seconds) + " s").c_str());
                    for (const std::string& w : ref.warnings)
                        std::fprintf(stderr, "voxlight: warning: %s: reference %zu: %s\n",
                                     spec.name.c_str(), k, w.c_str());
                }
                writeAtomically(dir / "reference.json", [&](const fs::path& p) {
                    writeTextFile(
                        p, refJson.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
                });
                // The folder's results.csv now belongs to this reference: the rows --only keeps
                // and nothing else. An earlier sweep's rows, measured against the reference just
                // replaced, stayed beside it when this run stopped before its first row (probe).
                writeCsv(dir / "results.csv", {}, kept);
            } catch (const InputError&) {
                failure = std::current_exception();
                undo();
            } catch (const CancelledError&) {
                // Ctrl-C before the first variant: as if never run ("nothing was written").
                failure = std::current_exception();
                undo();
            } catch (...) {
                ok = false;
                failure = std::current_exception();
            }
        if (!ranks.allTrue(ok)) {
            if (failure) std::rethrow_exception(failure);
            return kExitBadInput;  // rank 0 says why
        }

        // Rank r runs the contiguous block [n·r/K, n·(r+1)/K) of the variants (static: the same
        // split for the same sweep and K). Neighbours are mostly one run's variants, which share
        // stages (the volume's tables, a base field): a block keeps that reuse inside a rank.
        std::vector<analysis::SweepRow> rows;
        const std::size_t n = items.size(), k = std::size_t(ranks.size()),
                          r = std::size_t(ranks.rank());
        std::string error;
        try {
            error = runRankWork(ranks, [&] {
                for (std::size_t i = n * r / k; i < n * (r + 1) / k; ++i) {
                    throwIfCancelled();
                    analysis::SweepImages images;
                    analysis::SweepRow row =
                        runner.run(items[i], progress, *noImages ? nullptr : &images);
                    if (!*noImages) {
                        const std::string file = row.item.id + ".png";
                        writeAtomically(dir / "images" / file, [&](const fs::path& p) {
                            io::writeImage(images.display, p);
                        });
                        writeAtomically(dir / "maps" / file, [&](const fs::path& p) {
                            io::writeImage(images.errorMap, p);
                        });
                    }
                    for (const auto& w : row.warnings)
                        std::fprintf(stderr, "voxlight: warning: %s: %s\n", row.item.id.c_str(),
                                     w.c_str());
                    if (talk)
                        std::fprintf(
                            stderr,
                            "[%zu/%zu] %-40s precompute %7.2f s  frame %6.3f s  NRMSE %.4f  "
                            "FLIP %.4f  SSIM %.4f\n",
                            i + 1, items.size(), describe(row.item).c_str(), row.precomputeSeconds,
                            row.frameSeconds, row.nrmse, row.flip, row.ssim);
                    rows.push_back(std::move(row));
                    if (ranks.size() == 1) writeCsv(dir / "results.csv", rows, kept);
                }
            });
        } catch (const CancelledError&) {
            // One rank (several report through rank 0 below): what was finished stays, as the
            // header says; runGuarded's line would say nothing was written.
            const std::string kept =
                rows.empty() ? "" : (dir / "results.csv").string() + " holds the finished ones, ";
            std::fprintf(stderr,
                         "\nvoxlight: cancelled after %zu of %zu variants; %sthe reference is in "
                         "%s\n",
                         rows.size(), items.size(), kept.c_str(), dir.c_str());
            return kExitCancelled;
        }
        if (ranks.size() > 1) {
            std::string mine;
            for (const auto& r : rows) mine += analysis::sweepCsvRow(r) + "\n";
            if (!error.empty()) mine += error + "\n";
            const std::vector<std::string> all = ranks.gather(mine);
            if (!lead) return error.empty() ? kExitOk : std::atoi(error.c_str() + 1);
            // Rank 0: every rank's rows back in sweep order; the first failure decides the exit.
            std::vector<std::string> gathered;
            const int code = collectRankLines(all, gathered);
            std::vector<std::pair<std::size_t, std::string>> lines;
            for (const auto& l : gathered)
                lines.emplace_back(std::strtoull(l.c_str(), nullptr, 10), l);
            std::sort(lines.begin(), lines.end());
            std::string text = analysis::sweepCsvHeader();
            for (const auto& [index, line] : lines) text += "\n" + line;
            writeAtomically(dir / "results.csv",
                            [&](const fs::path& p) { writeTextFile(p, text); });
            if (code != kExitOk) return code;
            if (talk)
                std::fprintf(stderr, "%zu ranks; rows of the other ranks are in the CSV\n",
                             all.size());
        }
        if (talk)
            std::fprintf(stderr,
                         "wrote %s (%zu variants, %.1f s); plots and report: "
                         "tools/sweep_report.py %s\n",
                         (dir / "results.csv").c_str(), items.size(), total.seconds(), dir.c_str());
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
