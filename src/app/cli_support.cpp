// SPDX-License-Identifier: MIT
#include "app/cli_support.h"

#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <mutex>

#include "core/error.h"
#include "core/timing.h"

namespace voxlight::app {

std::atomic<bool>& cancelFlag() {
    static std::atomic<bool> flag{false};
    return flag;
}

namespace {
extern "C" void onSignal(int) { cancelFlag().store(true); }
}  // namespace

void installSignalHandlers() {
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
    // A closed terminal or a dropped SSH connection cancels as Ctrl-C does (temporaries removed,
    // the viewer's --record session saved) — unless the run was started to ignore it (nohup).
    if (std::signal(SIGHUP, onSignal) == SIG_IGN) std::signal(SIGHUP, SIG_IGN);
}

void throwIfCancelled() {
    if (cancelFlag().load()) throw CancelledError();
}

namespace {
/// The terminal's width in characters (stderr's), 80 when it cannot be asked.
std::size_t terminalColumns() {
    winsize ws{};
    if (::ioctl(STDERR_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 0) return ws.ws_col;
    return 80;
}
}  // namespace

core::Progress terminalProgress(bool quiet) {
    if (quiet) return core::Progress({}, &cancelFlag());
    const bool tty = ::isatty(STDERR_FILENO);
    struct State {
        std::mutex m;
        std::string stage;
        std::chrono::steady_clock::time_point start;
        int lastTenth = -1;
        int lastPercent = -1;
        long long lastSecond = -1;
        /// Characters of the bar's last line, to blank what a shorter one leaves.
        std::size_t lastWidth = 0;
    };
    // Work that finishes within kQuietSeconds shows nothing: progress is for long work, and a quick
    // failure stays one line on stderr.
    constexpr double kQuietSeconds = 1.0;
    auto state = std::make_shared<State>();
    return core::Progress::detailed(
        [state, tty](const std::string& stage, double f, const std::string& detail) {
            std::lock_guard<std::mutex> lock(state->m);
            const auto now = std::chrono::steady_clock::now();
            if (stage != state->stage) {
                if (tty && state->lastPercent >= 0 && state->lastPercent < 100)
                    std::fputc('\n', stderr);
                state->stage = stage;
                state->start = now;
                state->lastTenth = state->lastPercent = -1;
                state->lastSecond = -1;
                state->lastWidth = 0;
            }
            const double elapsed = std::chrono::duration<double>(now - state->start).count();
            if (elapsed < kQuietSeconds) return;
            const int percent = int(f * 100.0 + 0.5);
            if (tty) {
                // Redrawn when the percentage or the elapsed second changes (long stages tick).
                const long long second = (long long)elapsed;
                if (percent == state->lastPercent && second == state->lastSecond) return;
                if (state->lastPercent >= 100) return;  // finished: its line is ended
                state->lastPercent = percent;
                state->lastSecond = second;
                const int filled = std::clamp(percent, 0, 100) * 30 / 100;
                char bar[256];
                const int n = std::snprintf(
                    bar, sizeof bar, "\r%-12s [%.*s%*s] %3d%%  %s%s%s", stage.c_str(), filled,
                    "##############################", 30 - filled, "", percent, detail.c_str(),
                    detail.empty() ? "" : ", ", core::progressTimes(elapsed, f).c_str());
                const std::size_t width = n > 0 ? std::min<std::size_t>(n, sizeof bar - 1) : 0;
                // One terminal row: a line wider than the terminal wraps, and \r then redraws
                // only its last row. Cut at the width, counted in characters (UTF-8: "≈").
                const std::size_t columns = terminalColumns();
                std::size_t bytes = 0, shown = 0;
                for (; bytes < width && shown + 1 < columns; ++bytes)
                    if ((static_cast<unsigned char>(bar[bytes]) & 0xC0) != 0x80 &&
                        bar[bytes] != '\r')
                        ++shown;
                while (bytes < width && (static_cast<unsigned char>(bar[bytes]) & 0xC0) == 0x80)
                    ++bytes;  // never cut inside a character
                std::fwrite(bar, 1, bytes, stderr);
                if (shown < state->lastWidth)
                    std::fprintf(stderr, "%*s", int(state->lastWidth - shown), "");
                state->lastWidth = shown;
                if (percent >= 100) std::fputc('\n', stderr);
            } else {
                const int tenth = int(f * 10.0);
                if (tenth == state->lastTenth) return;
                state->lastTenth = tenth;
                std::fprintf(stderr, "%s: %d%% (%s%s%s)\n", stage.c_str(), tenth * 10,
                             detail.c_str(), detail.empty() ? "" : ", ",
                             core::progressTimes(elapsed, f).c_str());
            }
            std::fflush(stderr);
        },
        &cancelFlag());
}

std::vector<std::pair<std::string, std::filesystem::path>> sceneFileInputs(const io::Scene& s) {
    std::vector<std::pair<std::string, std::filesystem::path>> inputs = {
        {"the scene's volume", s.volume.path}};
    for (std::size_t i = 0; i < s.lights.size(); ++i)
        inputs.emplace_back("lights[" + std::to_string(i) + "].path", s.lights[i].path);
    return inputs;
}

int runGuarded(const std::function<int()>& body) {
    try {
        return body();
    } catch (const InputError& e) {
        std::cerr << "voxlight: error: " << blameLoadedOverrides(e).what() << "\n";
        return kExitBadInput;
    } catch (const CancelledError&) {
        std::cerr << "\nvoxlight: cancelled; nothing was written\n";
        return kExitCancelled;
    } catch (const std::bad_alloc&) {
        std::cerr << "voxlight: error: out of memory; try a smaller volume or image\n";
        return kExitBadInput;
    } catch (const std::exception& e) {
        std::cerr << "voxlight: internal error: " << e.what() << " (please report this)\n";
        return kExitInternal;
    }
}

const std::vector<std::string>& viewNames() {
    static const std::vector<std::string> names = [] {
        std::vector<std::string> n;
        for (const io::NamedView& v : io::namedViews()) n.push_back(v.name);
        return n;
    }();
    return names;
}

namespace {
/// The option named `name` (CLI11's get_name()) in `app`, its subcommands or option groups.
const CLI::Option* findOption(const CLI::App& app, const std::string& name) {
    for (const CLI::Option* o : app.get_options())
        if (o->get_name() == name) return o;
    for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
        if (const CLI::Option* o = findOption(*sub, name)) return o;
    return nullptr;
}
}  // namespace

std::string repeatedOption(const CLI::ParseError& e, const CLI::App& app, int argc,
                           const char* const* argv) {
    // CLI11 (2.1) words it "NAME: At Most N required but received M" (ArgumentMismatch::AtMost)
    // — for a list option (--dims) too, where it counts values, not occurrences: so the
    // occurrences are counted on the command line, under every name of the option.
    if (dynamic_cast<const CLI::ArgumentMismatch*>(&e) == nullptr) return {};
    const std::string what = e.what();
    const std::size_t at = what.find(": At Most ");
    if (at == std::string::npos || at == 0) return {};
    const std::string name = what.substr(0, at);
    const CLI::Option* o = findOption(app, name);
    if (!o) return {};
    std::vector<std::string> spellings;
    for (const std::string& l : o->get_lnames()) spellings.push_back("--" + l);
    for (const std::string& s : o->get_snames()) spellings.push_back("-" + s);
    int given = 0;
    for (int i = 1; i < argc; ++i)
        for (const std::string& sp : spellings) {
            const std::string_view arg = argv[i];
            if (arg == sp ||
                (arg.size() > sp.size() && arg.substr(0, sp.size()) == sp && arg[sp.size()] == '='))
                ++given;
        }
    return given > 1 ? name : std::string();
}

std::string optionWithEmptyValue(const CLI::App& app) {
    for (const CLI::Option* o : app.get_options())
        if (o->get_expected_min() > 0)  // flags take no value
            for (const std::string& r : o->results())
                if (r.empty()) return o->get_name();
    // Every subcommand and option group (those not used hold no results).
    for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
        if (const std::string name = optionWithEmptyValue(*sub); !name.empty()) return name;
    return {};
}

CLI::Validator wholeNumber() {
    return CLI::Validator(
        [](std::string& text) -> std::string {
            if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos)
                return "'" + text + "' is not a non-negative whole number";
            std::uint64_t v = 0;
            const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            if (ec != std::errc() || end != text.data() + text.size())
                return "'" + text + "' is larger than 18446744073709551615";
            return {};
        },
        "UINT");
}

CLI::Validator finiteNumber() {
    return CLI::Validator(
        [](std::string& text) -> std::string {
            char* end = nullptr;
            const double v = std::strtod(text.c_str(), &end);
            if (!text.empty() && end == text.c_str() + text.size() && !std::isfinite(v))
                return "'" + text + "' is not a finite number";
            return {};  // anything else is the option's own parser's to refuse
        },
        "");
}

std::string jsonForStdout(const nlohmann::json& doc, const std::string& input) {
    try {
        return doc.dump(2);
    } catch (const nlohmann::json::type_error&) {
        throw InputError(input, "path",
                         "holds bytes that are not UTF-8, which JSON output cannot carry unchanged",
                         "rename the file or folder to a UTF-8 name (render, iso and info without "
                         "--json read it as it is)");
    }
}

bool inputIsVolume(const std::string& input) {
    std::error_code ec;
    const std::filesystem::path p(input);
    if (std::filesystem::is_directory(p, ec)) return true;
    std::string ext = p.extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext != ".json";
}

namespace {
/// The overrides of every scene loadInput made, by the scene's source: an InputError a later
/// stage throws for that source (a method parameter, an image size the renderer refuses) names the
/// override it comes from (runGuarded).
std::vector<std::pair<std::string, std::vector<io::OverrideRecord>>>& loadedOverrides() {
    static std::vector<std::pair<std::string, std::vector<io::OverrideRecord>>> loaded;
    return loaded;
}
std::mutex loadedOverridesMutex;
}  // namespace

io::Scene loadInput(const std::string& input, const std::vector<std::string>& overrides,
                    const std::string& view) {
    const bool volume = inputIsVolume(input);
    std::vector<std::string> all;
    if (!view.empty()) {
        if (!volume)  // the scene's own placement gives way to the named view
            for (const char* k : {"camera.azimuth=null", "camera.elevation=null", "camera.eye=null",
                                  "camera.up=null"})
                all.push_back(k);
        all.push_back("camera.view=" + view);
    }
    const std::size_t fromView = all.size();  // the first ones stand for --view
    all.insert(all.end(), overrides.begin(), overrides.end());
    io::Scene s;
    try {
        s = volume ? io::volumeScene(input, all) : io::loadScene(input, all);
    } catch (const InputError& e) {
        // The overrides standing for --view are named as the user gave them.
        for (std::size_t i = 0; i < fromView; ++i)
            if (e.source() == "--set " + all[i])
                throw InputError("--view " + view, e.field(), e.problem(), e.fix());
        throw;
    }
    for (std::size_t i = 0; i < fromView && i < s.overrides.size(); ++i)
        s.overrides[i].said = "--view " + view;
    rememberOverrides(s);
    return s;
}

void rememberOverrides(const io::Scene& scene) {
    const std::lock_guard lock(loadedOverridesMutex);
    auto& loaded = loadedOverrides();
    // The latest load of a source is the one its errors come from (a viewer reopening a file
    // without overrides forgets the earlier ones).
    std::erase_if(loaded, [&](const auto& entry) { return entry.first == scene.source; });
    if (!scene.overrides.empty()) loaded.emplace_back(scene.source, scene.overrides);
}

InputError blameLoadedOverrides(const InputError& e) {
    const std::lock_guard lock(loadedOverridesMutex);
    for (auto it = loadedOverrides().rbegin(); it != loadedOverrides().rend(); ++it)
        if (it->first == e.source()) return io::blameOverride(e, it->first, it->second);
    return e;
}

}  // namespace voxlight::app
