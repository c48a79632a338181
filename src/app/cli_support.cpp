// SPDX-License-Identifier: MIT
#include "app/cli_support.h"

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <iostream>
#include <mutex>

#include "core/error.h"

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
}

core::Progress terminalProgress(bool quiet) {
    if (quiet) return core::Progress({}, &cancelFlag());
    const bool tty = ::isatty(STDERR_FILENO);
    struct State {
        std::mutex m;
        std::string stage;
        int lastTenth = -1;
        int lastPercent = -1;
    };
    auto state = std::make_shared<State>();
    return core::Progress(
        [state, tty](const std::string& stage, double f) {
            std::lock_guard<std::mutex> lock(state->m);
            if (stage != state->stage) {
                if (tty && !state->stage.empty()) std::fputc('\n', stderr);
                state->stage = stage;
                state->lastTenth = state->lastPercent = -1;
            }
            const int percent = int(f * 100.0 + 0.5);
            if (tty) {
                if (percent == state->lastPercent) return;
                state->lastPercent = percent;
                const int filled = percent * 30 / 100;
                std::fprintf(stderr, "\r%-12s [%.*s%*s] %3d%%", stage.c_str(), filled,
                             "##############################", 30 - filled, "", percent);
                if (percent >= 100) {
                    std::fputc('\n', stderr);
                    state->stage.clear();
                }
            } else {
                const int tenth = int(f * 10.0);
                if (tenth == state->lastTenth) return;
                state->lastTenth = tenth;
                std::fprintf(stderr, "%s: %d%%\n", stage.c_str(), tenth * 10);
            }
            std::fflush(stderr);
        },
        &cancelFlag());
}

int runGuarded(const std::function<int()>& body) {
    try {
        return body();
    } catch (const InputError& e) {
        std::cerr << "voxlight: error: " << e.what() << "\n";
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

}  // namespace voxlight::app
