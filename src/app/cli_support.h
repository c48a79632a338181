// SPDX-License-Identifier: MIT
#pragma once
// What every voxlight subcommand shares: progress display, Ctrl-C cancellation, exit codes.
//   0    success
//   1    internal error (a bug: please report)
//   2    bad input (one line on stderr)
//   130  cancelled (Ctrl-C)
#include <CLI/CLI.hpp>
#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "core/progress.h"
#include "io/scene.h"

namespace voxlight::app {

inline constexpr int kExitOk = 0, kExitInternal = 1, kExitBadInput = 2, kExitCancelled = 130;

/// Cancel flag raised by SIGINT/SIGTERM/SIGHUP (installed by installSignalHandlers(); SIGHUP not
/// where the run ignores it, as under nohup).
std::atomic<bool>& cancelFlag();
void installSignalHandlers();
/// Throws CancelledError when the cancel flag is raised: for steps between long calls that take no
/// Progress (writing output files).
void throwIfCancelled();

/// Progress sink for the terminal: a redrawn bar when stderr is a TTY, plain lines every 10%
/// otherwise; silent when `quiet`.
core::Progress terminalProgress(bool quiet);

/// The files a scene reads, as checkOutputs names them: its volume and every light's map
/// ("the scene's volume", "lights[i].path"); paths that are empty are left out by checkOutputs.
std::vector<std::pair<std::string, std::filesystem::path>> sceneFileInputs(const io::Scene& s);

/// Runs a subcommand body, mapping exceptions to one line on stderr and the exit codes above.
int runGuarded(const std::function<int()>& body);

/// The named camera views (io/scene.h's camera.view), for --view.
const std::vector<std::string>& viewNames();

/// The scene a command's INPUT names: a scene file (.json) with overrides, or a volume file or
/// DICOM folder that makes a scene on its own (io::volumeScene). `view`, when set, replaces the
/// camera's placement (azimuth/elevation/eye/up) by that named view before the overrides.
io::Scene loadInput(const std::string& input, const std::vector<std::string>& overrides,
                    const std::string& view = "");
/// Keeps `scene`'s overrides for blameLoadedOverrides (loadInput does it for the scenes it loads;
/// a command parsing scenes another way — a session's frames — calls it itself).
void rememberOverrides(const io::Scene& scene);
/// `e` naming the override it comes from (io::blameOverride) when its source is a scene loadInput
/// loaded: runGuarded reports every InputError through this.
InputError blameLoadedOverrides(const InputError& e);
/// For unsigned options: the text must be decimal digits that fit 64 bits. CLI11 read "-1" and
/// numbers past 2^64 as 2^64 − 1 without a word (a seed, a header size).
CLI::Validator wholeNumber();
/// For floating-point options, before their CLI::Range: NaN and infinities refused (a range's
/// comparisons are false for NaN, so "--max-memory-mb nan" turned the guard off).
CLI::Validator finiteNumber();
/// The option `e` refuses because it was given more than once on the command line `argv`
/// (main's Throw policy), or "" for any other parse error.
std::string repeatedOption(const CLI::ParseError& e, const CLI::App& app, int argc,
                           const char* const* argv);
/// The first option of the parsed command (option groups included) given "" as its value, or "".
std::string optionWithEmptyValue(const CLI::App& app);

/// True when INPUT is taken as a volume (a directory, or a file not ending in .json).
bool inputIsVolume(const std::string& input);
/// `doc` as indented JSON text for stdout. A string in it that is not UTF-8 (a file name's bytes)
/// cannot be written as JSON without changing it — a replaced path names no file — so that is an
/// InputError naming `input`, not an internal one.
std::string jsonForStdout(const nlohmann::json& doc, const std::string& input);

/// Subcommand registration: each adds itself to the app and sets `run` when chosen.
struct Command {
    CLI::App* sub = nullptr;
    std::function<int()> run;
};
Command addInfoCommand(CLI::App& app);
Command addPhantomCommand(CLI::App& app);
Command addSceneCommand(CLI::App& app);
Command addRenderCommand(CLI::App& app);
Command addIsoCommand(CLI::App& app);
Command addReplayCommand(CLI::App& app);
Command addViewCommand(CLI::App& app);
Command addCompareCommand(CLI::App& app);
Command addSweepCommand(CLI::App& app);

}  // namespace voxlight::app
