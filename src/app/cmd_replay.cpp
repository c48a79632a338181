// SPDX-License-Identifier: MIT
// voxlight replay SESSION.json --out DIR [--fps N] [--set key=value]... [--size WxH]
//                 [--stats STATS.json] [--video OUT.mp4] [--cache DIR] [-q]
// Re-renders a recorded session (session/session.h, docs/sessions.md): every keyframe, or a fixed
// frame rate between the first and the last keyframe, with the scene's method or the one --set
// names. Each frame goes through the same pipeline run as `voxlight render` (one pipeline session
// for all frames, so a frame reuses what the frames before computed: a camera-only change reruns
// only the camera and render stages) and is written as DIR/frame_NNNNN.png atomically.
//
// Everything that can be checked is checked before the first frame: the outputs, the session,
// every frame's scene with the overrides, every frame's plan (method and params), the volume
// file. So bad input leaves DIR as it was. A Ctrl-C (or a failure) during the frames keeps the
// frames already written — each complete, none half-written — and writes no stats or video.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <thread>

#include "app/cli_support.h"
#include "app/output_files.h"
#include "app/ranks.h"
#include "app/render_output.h"
#include "core/timing.h"
#include "io/image.h"
#include "pipeline/pipeline.h"
#include "session/session.h"

extern char** environ;

namespace voxlight::app {

namespace {
namespace fs = std::filesystem;
using nlohmann::json;

/// "frame_00042.png": five digits cover session::kMaxFrames.
std::string frameName(std::size_t i) {
    char b[32];
    std::snprintf(b, sizeof b, "frame_%05zu.png", i);
    return b;
}

/// --size WxH → the two overrides image.width / image.height.
std::vector<std::string> sizeOverrides(const std::string& size) {
    // Digits, 'x', digits — parsed by hand: std::regex recurses once per character (a long
    // argument overflowed the stack).
    const std::size_t x = size.find('x');
    const auto digits = [](std::string_view d) {
        return !d.empty() && d.find_first_not_of("0123456789") == std::string_view::npos;
    };
    const std::string shown = size.size() > 24 ? size.substr(0, 21) + "..." : size;
    if (x == std::string::npos || !digits(std::string_view(size).substr(0, x)) ||
        !digits(std::string_view(size).substr(x + 1)))
        throw InputError("command line", "--size", "'" + shown + "' is not WIDTHxHEIGHT",
                         "e.g. --size 256x256");
    // The scene's image limits, said here: as overrides they would be blamed on a "--set" the
    // user never typed. (More than five digits after leading zeros: past the limit.)
    constexpr int kMaxSide = 16384;  // io::parseScene's image.width/height
    const auto side = [&](std::string d) {
        d.erase(0, std::min(d.find_first_not_of('0'), d.size() - 1));
        return d.size() > 5 ? kMaxSide + 1 : std::stoi(d);
    };
    const int w = side(size.substr(0, x)), h = side(size.substr(x + 1));
    if (w < 1 || h < 1)
        throw InputError("command line", "--size", "'" + shown + "' has a side of 0 pixels",
                         "e.g. --size 256x256");
    if (w > kMaxSide || h > kMaxSide)
        throw InputError(
            "command line", "--size",
            "'" + shown + "' is larger than " + std::to_string(kMaxSide) + " pixels on a side",
            "e.g. --size 1920x1080");
    return {"image.width=" + std::to_string(w), "image.height=" + std::to_string(h)};
}

/// The executable `name` on PATH, or empty.
fs::path findOnPath(const std::string& name) {
    const char* path = std::getenv("PATH");
    if (!path) return {};
    std::string dirs = path;
    std::size_t start = 0;
    while (start <= dirs.size()) {
        const std::size_t colon = std::min(dirs.find(':', start), dirs.size());
        const fs::path candidate = fs::path(dirs.substr(start, colon - start)) / name;
        if (colon > start && ::access(candidate.c_str(), X_OK) == 0) return candidate;
        start = colon + 1;
    }
    return {};
}

/// Runs a program to its end, its stderr in `errFile`; killed when the cancel flag rises
/// (CancelledError then). Returns the exit status (−1: did not start or ended by a signal).
int runProgram(const std::vector<std::string>& args, const fs::path& errFile) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, errFile.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid = -1;
    const int rc = ::posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) return -1;
    int status = 0;
    while (true) {
        const pid_t w = ::waitpid(pid, &status, WNOHANG);
        if (w == pid) break;
        if (w < 0 && errno != EINTR) return -1;
        if (cancelFlag().load()) {
            ::kill(pid, SIGKILL);
            ::waitpid(pid, &status, 0);
            throw CancelledError();
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// The first line of a file (ffmpeg's first complaint), at most 200 bytes.
std::string firstLine(const fs::path& file) {
    std::FILE* f = std::fopen(file.c_str(), "r");
    if (!f) return {};
    char b[201] = {};
    const bool got = std::fgets(b, sizeof b, f) != nullptr;
    std::fclose(f);
    std::string s = got ? b : "";
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
    return s;
}

}  // namespace

Command addReplayCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("replay", "Re-render a recorded session (docs/sessions.md)");
    auto sessionFile = std::make_shared<std::string>();
    auto outDir = std::make_shared<std::string>();
    auto fps = std::make_shared<double>(0.0);
    auto sets = std::make_shared<std::vector<std::string>>();
    auto size = std::make_shared<std::string>();
    auto stats = std::make_shared<std::string>();
    auto video = std::make_shared<std::string>();
    auto cacheDir = std::make_shared<std::string>();
    auto quiet = std::make_shared<bool>(false);
    c.sub->add_option("SESSION", *sessionFile, "Session JSON (docs/sessions.md)")->required();
    c.sub->add_option("--out", *outDir, "Folder for frame_00000.png, ... (created if missing)")
        ->required();
    CLI::Option* fpsOption =
        c.sub->add_option("--fps", *fps,
                          "Frames per second between the first and last keyframe (interpolated); "
                          "default: one frame per keyframe");
    c.sub->add_option("--set", *sets, "Override a scene key in every frame, e.g. --set method=mip")
        ->allow_extra_args(false);
    c.sub->add_option("--size", *size, "Image size WxH (same as --set image.width/height)");
    c.sub->add_option("--stats", *stats,
                      "Write every frame's stages (ran, cached or not needed) and times as JSON");
    c.sub->add_option("--video", *video,
                      "Also assemble the frames into a video with ffmpeg (when on PATH) at --fps "
                      "(1 frame per second without --fps)");
    c.sub->add_option("--cache", *cacheDir,
                      "Keep precomputed stages in DIR across runs (as render --cache)");
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output");
    c.run = [=] {
        core::Stopwatch total;
        const Ranks ranks;  // mpirun -n K: the frames split over K ranks (app/ranks.h)
        // Outputs first (nothing is rendered for a path that cannot be written).
        checkOutputs({{"--stats", *stats, {".json"}},
                      {"--video", *video, {".mp4", ".mkv", ".mov", ".webm"}}},
                     {{"SESSION", *sessionFile}});
        const fs::path dir(*outDir);
        std::error_code ec;
        if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
            throw InputError("command line", "--out", "'" + *outDir + "' is not a folder",
                             "give a folder for the frames (it is created if missing)");
        const fs::path parent = dir.parent_path().empty() ? fs::path(".") : dir.parent_path();
        if (!fs::exists(dir, ec) && !fs::is_directory(parent, ec))
            throw InputError("command line", "--out",
                             "the folder '" + parent.string() + "' does not exist",
                             "create it first, or give another --out");
        if (::access((fs::exists(dir, ec) ? dir : parent).c_str(), W_OK) != 0)
            throw InputError(
                "command line", "--out",
                "'" + (fs::exists(dir, ec) ? dir : parent).string() + "' is not writable",
                "choose a folder you can write to");

        // The session and every frame's scene, validated before anything is rendered.
        const session::Session ses = session::loadSession(*sessionFile);
        std::vector<std::string> overrides = *sets;
        if (!size->empty()) {
            const auto s = sizeOverrides(*size);
            overrides.insert(overrides.end(), s.begin(), s.end());
        }
        const bool interpolate = fpsOption->count() > 0;
        std::vector<double> times;
        if (interpolate) {
            times = session::frameTimes(ses, *fps);
        } else {
            for (const auto& k : ses.keyframes) times.push_back(k.time);
        }
        std::vector<io::Scene> scenes;
        scenes.reserve(times.size());
        for (std::size_t i = 0; i < times.size(); ++i)
            scenes.push_back(interpolate ? ses.sceneAtTime(times[i], overrides)
                                         : ses.sceneAt(i, overrides));
        rememberOverrides(scenes.back());
        pipeline::Session pipe;
        if (!cacheDir->empty()) pipe.cache().setDirectory(*cacheDir);
        // An error the session's frame i raises, named by the --set that set its field, else by
        // the keyframe that did (errors of other files name those files).
        const auto frameError = [&](const InputError& raw, std::size_t i) {
            // An environment map of the frame's that does not read: its own message, named by
            // the keyframe (or --set) that set the light's path.
            InputError e = raw;
            const auto& lights = scenes[i].lights;
            for (std::size_t k = 0; k < lights.size() && raw.source() != ses.source; ++k)
                if (!lights[k].path.empty() && fs::path(raw.source()).lexically_normal() ==
                                                   lights[k].path.lexically_normal()) {
                    e = InputError(ses.source, "lights[" + std::to_string(k) + "].path",
                                   "'" + raw.source() + "' " + raw.field() + ": " + raw.problem(),
                                   raw.fix());
                    break;
                }
            if (e.source() != ses.source) return e;
            if (io::blamedOverride(scenes[i].overrides, e.field()))
                return io::blameOverride(e, ses.source, scenes[i].overrides);
            return InputError(
                ses.source,
                interpolate ? ses.fieldAtTime(times[i], e.field()) : ses.fieldAt(i, e.field()),
                e.problem(), e.fix());
        };
        for (std::size_t i = 0; i < scenes.size(); ++i) {
            try {
                (void)pipe.plan(scenes[i]);  // the method's strict params
            } catch (const InputError& e) {
                throw frameError(e, i);
            }
        }
        // The session's scene file as a path from here ("" when the scene is inline).
        const fs::path sceneFile = ses.scenePath.empty() || fs::path(ses.scenePath).is_absolute()
                                       ? fs::path(ses.scenePath)
                                       : fs::path(ses.source).parent_path() / ses.scenePath;
        {
            // Named by the file that holds the volume key: the session, or its scene file.
            const io::VolumeSource& v = scenes.front().volume;
            if (v.phantom.empty() && !fs::exists(v.path, ec)) {
                // A --set volume(.path)=… gave it: that override is named (the path was made
                // absolute against the current directory, where it was typed).
                if (const io::OverrideRecord* r =
                        io::blamedOverride(scenes.front().overrides, "volume.path"))
                    throw InputError(
                        r->said, "volume", "names '" + v.path.string() + "', which does not exist",
                        "fix the path; a relative one is read from the current directory");
                throw InputError(ses.scenePath.empty() ? ses.source : sceneFile.string(),
                                 ses.scenePath.empty() ? "scene.volume" : "volume",
                                 "names '" + v.path.string() + "', which does not exist",
                                 ses.scenePath.empty()
                                     ? "fix the path (relative paths resolve against the "
                                       "session file's folder)"
                                     : "fix the path in " + ses.scenePath +
                                           " (relative to that scene file's folder)");
            }
        }
        {
            // The files the frames read (the session's scene file, every frame's volume and
            // maps): --stats or --video over one of them would replace it.
            std::vector<std::pair<std::string, fs::path>> inputs = {{"SESSION", *sessionFile}};
            inputs.emplace_back("the session's scene file", sceneFile);
            for (const io::Scene& s : scenes)
                for (auto& in : sceneFileInputs(s))
                    if (std::find(inputs.begin(), inputs.end(), in) == inputs.end())
                        inputs.push_back(std::move(in));
            checkOutputs({{"--stats", *stats, {}}, {"--video", *video, {}}}, inputs);
        }
        fs::path ffmpeg;
        if (!video->empty()) ffmpeg = findOnPath("ffmpeg");

        // OpenImageIO loads beside the first frame's stages after its volume read (io/image.h).
        std::optional<io::ImageModulePreload> imageSupport;
        pipeline::RunOptions runOptions;
        runOptions.afterStage = preloadImagesAfterInputs(imageSupport);
        // The frames: one pipeline session, each frame written as soon as it is done.
        // Rank 0 makes the folder; with MPI the others wait for it.
        const bool created = !fs::exists(dir, ec);
        if (ranks.lead()) fs::create_directories(dir, ec);
        if (!ranks.allTrue(!ec)) {
            if (!ranks.lead()) return kExitBadInput;  // rank 0 says why
            throw InputError("command line", "--out",
                             "cannot create '" + *outDir + "': " + ec.message(),
                             "create it first, or give another --out");
        }
        json frames = json::array();
        std::size_t done = 0;
        std::vector<fs::path> added;  // frames this run wrote where none was before
        std::vector<double> frameSeconds;
        // One frame: rendered, written atomically, its stats entry returned.
        auto renderFrame = [&](std::size_t i) {
            core::Stopwatch sw;
            // A frame's stages show a bar on a terminal, one per frame so that only a frame
            // taking over a second shows one; elsewhere the line per frame is the progress
            // (plain lines for every stage of every frame would drown it).
            const core::Progress progress = terminalProgress(*quiet || !::isatty(STDERR_FILENO));
            pipeline::RunResult r = pipe.run(scenes[i], runOptions, progress);
            throwIfCancelled();
            const fs::path file = dir / frameName(i);
            const bool isNew = !fs::exists(file, ec);
            OutputFiles files;
            files.write(file, "--out",
                        [&](const fs::path& p) { writeDisplayImage(r, scenes[i], p); });
            throwIfCancelled();
            files.commit();
            if (isNew) added.push_back(file);
            ++done;
            const double seconds = sw.seconds();
            std::vector<std::string> ran, cached;
            json stages = json::array();
            for (const auto& st : r.stages) {
                stages.push_back(pipeline::toJson(st));
                if (st.ran) ran.push_back(st.name);
                if (st.reason.rfind("cached", 0) == 0) cached.push_back(st.name);
            }
            for (const auto& w : r.warnings)
                std::fprintf(stderr, "voxlight: warning: frame %zu: %s\n", i, w.c_str());
            if (!*quiet)
                std::fprintf(stderr, "frame %zu/%zu (t = %.3f s): %.2f s, ran: %s\n", i + 1,
                             scenes.size(), times[i], seconds, ran.empty() ? "-" : [&] {
                                 std::string s;
                                 for (const auto& n : ran) s += (s.empty() ? "" : " ") + n;
                                 return s;
                             }().c_str());
            return json{
                {"index", i}, {"time", times[i]}, {"file", frameName(i)},   {"seconds", seconds},
                {"ran", ran}, {"cached", cached}, {"warnings", r.warnings}, {"stages", stages}};
        };
        if (ranks.size() == 1) {
            std::size_t current = 0;
            try {
                for (; current < scenes.size(); ++current) {
                    frames.push_back(renderFrame(current));
                    frameSeconds.push_back(frames.back()["seconds"].get<double>());
                }
            } catch (const InputError& e) {
                // Bad input only a frame's stages find (an environment map that does not read, an
                // isovalue outside the data): the frames this run added go again, as does a
                // folder it created — DIR as it was (frames it replaced stay replaced).
                for (const fs::path& f : added) fs::remove(f, ec);
                if (created) fs::remove(dir, ec);  // only when empty
                throw frameError(e, current);
            } catch (const CancelledError&) {
                if (done == 0 && created) fs::remove(dir, ec);  // empty: as if never run
                std::fprintf(stderr,
                             "\nvoxlight: cancelled after %zu of %zu frames; the %zu written are "
                             "complete, nothing is half-written\n",
                             done, scenes.size(), done);
                return kExitCancelled;
            } catch (...) {
                // A failure in the first frame (a volume file that does not read) leaves no
                // folder behind that this run created; later ones keep the whole frames before.
                if (done == 0 && created) fs::remove(dir, ec);
                throw;
            }
        } else {
            // MPI ranks: rank r renders the contiguous block [n·r/K, n·(r+1)/K), so consecutive
            // frames keep reusing one pipeline session's stages as in one process; rank 0 gathers
            // every frame's stats entry and writes the stats and the video.
            const std::size_t n = scenes.size(), k = std::size_t(ranks.size()),
                              r = std::size_t(ranks.rank());
            std::string mine;
            const std::string error = runRankWork(ranks, [&] {
                for (std::size_t i = n * r / k; i < n * (r + 1) / k; ++i)
                    mine +=
                        renderFrame(i).dump(-1, ' ', false, json::error_handler_t::replace) + "\n";
            });
            if (!error.empty()) mine += error + "\n";
            const std::vector<std::string> all = ranks.gather(mine);
            if (!ranks.lead()) return error.empty() ? kExitOk : std::atoi(error.c_str() + 1);
            std::vector<std::string> lines;
            const int code = collectRankLines(all, lines);
            std::vector<json> entries;
            for (const auto& l : lines) entries.push_back(json::parse(l));
            std::sort(entries.begin(), entries.end(), [](const json& a, const json& b) {
                return a["index"].get<std::size_t>() < b["index"].get<std::size_t>();
            });
            for (auto& e : entries) {
                frameSeconds.push_back(e["seconds"].get<double>());
                frames.push_back(std::move(e));
            }
            if (code != kExitOk) {
                std::fprintf(stderr,
                             "voxlight: %zu of %zu frames written (complete); no stats or "
                             "video\n",
                             frames.size(), scenes.size());
                return code;
            }
            if (!*quiet) std::fprintf(stderr, "%zu ranks rendered %zu frames\n", k, frames.size());
        }

        // Frames of an earlier, longer replay into the same folder would join a video made from
        // a pattern: said, and the video takes exactly this run's frames.
        std::size_t stale = 0;
        for (std::size_t i = scenes.size(); fs::exists(dir / frameName(i), ec); ++i) ++stale;
        if (stale > 0)
            std::fprintf(stderr,
                         "voxlight: warning: %s also holds %zu frames after this run's %zu "
                         "(from an earlier replay); they are not part of this one\n",
                         outDir->c_str(), stale, scenes.size());

        OutputFiles files;
        std::string videoNote;
        if (!video->empty()) {
            if (ffmpeg.empty()) {
                videoNote =
                    "--video skipped: ffmpeg is not on PATH (Debian: apt-get install "
                    "ffmpeg); the frames are in " +
                    *outDir;
            } else {
                const double rate = interpolate ? *fps : 1.0;
                try {
                    files.write(*video, "--video", [&](const fs::path& p) {
                        const fs::path err = p.string() + ".log";
                        int code = -1;
                        try {
                            code = runProgram(
                                {ffmpeg.string(), "-y", "-loglevel", "error", "-framerate",
                                 std::to_string(rate), "-i", (dir / "frame_%05d.png").string(),
                                 "-frames:v", std::to_string(scenes.size()), "-vf",
                                 "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p",
                                 p.string()},
                                err);
                        } catch (const CancelledError&) {
                            fs::remove(err, ec);  // goes with the video's temporary
                            throw;
                        }
                        const std::string why = firstLine(err);
                        fs::remove(err, ec);
                        if (code != 0)
                            throw InputError(
                                *video, "", "ffmpeg failed" + (why.empty() ? "" : ": " + why),
                                "the frames are in " + *outDir + "; run ffmpeg on them by hand");
                    });
                } catch (const CancelledError&) {
                    // Ctrl-C while ffmpeg runs: the frames, all written, stay (runGuarded's line
                    // would say nothing was written).
                    std::fprintf(stderr,
                                 "\nvoxlight: cancelled while making the video; the %zu frames "
                                 "are complete in %s, no video or stats were written\n",
                                 scenes.size(), outDir->c_str());
                    return kExitCancelled;
                }
            }
        }
        if (!stats->empty()) {
            std::vector<double> sorted = frameSeconds;
            std::sort(sorted.begin(), sorted.end());
            json j = {{"session", ses.source},
                      {"frames_total", scenes.size()},
                      {"fps", interpolate ? json(*fps) : json(nullptr)},
                      {"method", scenes.front().method.name},
                      {"ranks", ranks.size()},
                      {"frame_seconds_min", sorted.front()},
                      {"frame_seconds_median", sorted[sorted.size() / 2]},
                      {"frame_seconds_max", sorted.back()},
                      {"total_seconds", total.seconds()},
                      {"frames", frames}};
            const std::string text =
                j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
            files.write(*stats, "--stats", [&](const fs::path& p) { writeTextFile(p, text); });
        }
        throwIfCancelled();
        files.commit();
        if (!videoNote.empty()) std::fprintf(stderr, "voxlight: %s\n", videoNote.c_str());
        if (!*quiet) {
            // Every method the frames used, in order of first use (a keyframe may switch it).
            std::string methods;
            for (const io::Scene& sc : scenes)
                if (("," + methods + ",").find("," + sc.method.name + ",") == std::string::npos)
                    methods += (methods.empty() ? "" : ",") + sc.method.name;
            std::fprintf(stderr, "wrote %zu frames to %s%s (%s, total %.2f s)\n", scenes.size(),
                         outDir->c_str(),
                         !video->empty() && videoNote.empty() ? (" and " + *video).c_str() : "",
                         methods.c_str(), total.seconds());
        }
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
