// SPDX-License-Identifier: MIT
#include "app/ranks.h"

#include <fcntl.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>

#include "app/cli_support.h"
#include "core/error.h"
#include "io/module_loader.h"

namespace voxlight::app {

Ranks::Ranks() {
    const char* n = std::getenv("OMPI_COMM_WORLD_SIZE");
    if (!n || std::atoi(n) <= 1) return;
    static const io::detail::LoadedModule loaded = io::detail::loadModule(
        mpi_module::kFileName, mpi_module::kEntryPoint, mpi_module::kAbiVersion);
    if (!loaded.api)
        throw InputError("command line", "mpirun",
                         "this voxlight cannot run as MPI ranks: " + loaded.error,
                         "install libopenmpi-dev and rebuild (tools/setup.sh), or run without "
                         "mpirun");
    api_ = static_cast<const mpi_module::Api*>(loaded.api);
    std::string error;
    if (!api_->init(&rank_, &size_, &error))
        throw InputError("command line", "mpirun", error, "check the MPI launch");
    if (rank_ != 0) {
        const int null = ::open("/dev/null", O_WRONLY);
        if (null >= 0) ::dup2(null, STDERR_FILENO), ::close(null);
    }
}

Ranks::~Ranks() {
    if (api_) api_->finalize();
}

bool Ranks::allTrue(bool ok) const { return api_ ? api_->allTrue(ok) : ok; }

std::vector<std::string> Ranks::gather(const std::string& mine) const {
    if (!api_) return {mine};
    std::vector<std::string> all;
    api_->gather(mine, &all);
    return all;
}

std::string runRankWork(const Ranks& ranks, const std::function<void()>& work) {
    if (ranks.size() == 1) {
        work();
        return "";
    }
    auto line = [](int code, std::string m) {
        for (char& c : m)
            if (c == '\n' || c == '\r') c = ' ';
        return "!" + std::to_string(code) + " " + m;
    };
    try {
        work();
    } catch (const CancelledError&) {
        return line(kExitCancelled, "cancelled");
    } catch (const InputError& e) {
        return line(kExitBadInput, e.what());
    } catch (const std::exception& e) {
        return line(kExitInternal, std::string("internal error: ") + e.what());
    }
    return "";
}

int collectRankLines(const std::vector<std::string>& all, std::vector<std::string>& lines) {
    int code = kExitOk;
    for (std::size_t r = 0; r < all.size(); ++r) {
        std::size_t at = 0;
        while (at < all[r].size()) {
            std::size_t nl = all[r].find('\n', at);
            if (nl == std::string::npos) nl = all[r].size();
            const std::string line = all[r].substr(at, nl - at);
            at = nl + 1;
            if (line.empty()) continue;
            if (line[0] != '!') {
                lines.push_back(line);
                continue;
            }
            const auto space = line.find(' ');
            const std::string msg = space == std::string::npos ? "" : line.substr(space + 1);
            std::fprintf(stderr, "voxlight: error: rank %zu: %s\n", r, msg.c_str());
            if (code == kExitOk) code = std::atoi(line.c_str() + 1);
        }
    }
    return code;
}

}  // namespace voxlight::app
