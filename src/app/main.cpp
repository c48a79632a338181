// SPDX-License-Identifier: MIT
// voxlight: medical direct volume rendering with realistic illumination. Thin main: subcommands
// live beside it.
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <string>

#include "app/cli_support.h"
#include "core/timing.h"

int main(int argc, char** argv) {
    using namespace voxlight::app;
    installSignalHandlers();
    voxlight::core::retainFreedMemory();  // repeated TF updates reuse their fields' pages
    CLI::App app{"voxlight: medical direct volume rendering with realistic illumination"};
    app.require_subcommand(1);
    app.set_version_flag("--version", "voxlight 0.1.0");
    // An option given twice is a mistake to point out, not a value to drop silently (CLI11 would
    // keep the last); options that take any number of values (--set, --only) take every
    // occurrence, flags keep CLI11's own policy (-q -q is -q).
    app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::Throw);
    std::vector<Command> commands = {
        addInfoCommand(app),   addPhantomCommand(app), addSceneCommand(app),
        addRenderCommand(app), addIsoCommand(app),     addReplayCommand(app),
        addViewCommand(app),   addCompareCommand(app), addSweepCommand(app)};
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::string names;
        bool known = false;
        for (const auto* s : app.get_subcommands({})) {
            names += (names.empty() ? "" : ", ") + s->get_name();
            known = known || (argc > 1 && s->get_name() == argv[1]);
        }
        if (argc > 1 && argv[1][0] != '-' && !known) {
            std::cerr << "voxlight: error: unknown command '" << argv[1]
                      << "' (choose one of: " << names << ")\n";
            return kExitBadInput;
        }
        if (const std::string twice = repeatedOption(e, app, argc, argv); !twice.empty()) {
            std::cerr << "voxlight: error: " << twice
                      << " is given more than once (give it once: which value was meant?)\n";
            return kExitBadInput;
        }
        std::cerr << "voxlight: error: " << e.what() << " (see voxlight --help)\n";
        return kExitBadInput;
    }
    // An empty value ("--isovalue ''") reads as 0 for a number in CLI11: a mistake to name.
    if (const std::string empty = optionWithEmptyValue(app); !empty.empty()) {
        std::cerr << "voxlight: error: " << empty
                  << " is given an empty value (give a value, or leave the option out)\n";
        return kExitBadInput;
    }
    for (auto& c : commands)
        if (c.sub->parsed()) {
            const int code = runGuarded(c.run);
            // What a command printed (scene --init > scene.json, info --json) must have reached
            // its file: a full disk or /dev/full made the writes fail silently, exit 0 over an
            // empty file.
            errno = 0;
            std::cout.flush();
            const bool failed = std::fflush(stdout) != 0 || std::ferror(stdout) || !std::cout;
            const int error = errno;  // 0 when an earlier write failed (its errno is gone)
            if (failed && code == kExitOk) {
                std::cerr << "voxlight: error: standard output: cannot be written"
                          << (error ? std::string(": ") + std::strerror(error)
                                    : std::string(" (a write to it failed)"))
                          << " (free disk space, or redirect the output elsewhere)\n";
                return kExitBadInput;
            }
            return code;
        }
    return kExitBadInput;
}
