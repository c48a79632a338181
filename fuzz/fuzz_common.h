// SPDX-License-Identifier: MIT
#pragma once
// Shared by the libFuzzer targets: the input is written to files in a per-process temporary
// directory and handed to the public loader `voxlight info` uses (io::readVolume) or `voxlight
// scene` uses (io::loadScene). An InputError (exit 2 in the CLI) is a normal outcome; anything
// else is a finding: a signal or sanitizer report (libFuzzer), an exception of another type
// (reported here, then abort), an InputError spanning several lines (the CLI promises one), a
// timeout (-timeout) or memory beyond the budget (-rss_limit_mb / -malloc_limit_mb).
//
// Multi-file formats (detached NRRD, .mhd + raw, DICOM series) take one input split at
// kPartSeparator into the files of `names`, in order: separator-delimited parts survive libFuzzer's
// insertions and deletions better than length prefixes (the dictionaries list the separator).
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/error.h"

namespace voxlight::fuzz {

inline constexpr std::string_view kPartSeparator = "VXLFUZZSPLIT";

/// This process's scratch directory (mkdtemp under $TMPDIR or /tmp), emptied before each input and
/// removed at normal exit. A crash leaves it behind with the crashing input's files.
inline const std::filesystem::path& scratchDir() {
    static const std::filesystem::path dir = [] {
        const char* base = std::getenv("TMPDIR");
        std::string templ = std::string(base && *base ? base : "/tmp") + "/voxlight-fuzz-XXXXXX";
        if (!::mkdtemp(templ.data())) {
            std::perror("voxlight fuzz: mkdtemp");
            std::abort();
        }
        std::atexit([] {
            std::error_code ec;
            std::filesystem::remove_all(scratchDir(), ec);
        });
        return std::filesystem::path(templ);
    }();
    return dir;
}

/// Empties the scratch directory (a previous input's files must not leak into this one).
inline void clearScratch() {
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(scratchDir(), ec))
        std::filesystem::remove_all(e.path(), ec);
}

inline void writeFile(const std::filesystem::path& p, const void* data, std::size_t size) {
    std::ofstream f(p, std::ios::binary);
    f.write(static_cast<const char*>(data), std::streamsize(size));
    if (!f) {
        std::fprintf(stderr, "voxlight fuzz: cannot write %s\n", p.c_str());
        std::abort();
    }
}

/// Splits at kPartSeparator into at most `maxParts` parts (the last takes the rest).
inline std::vector<std::string_view> splitParts(const std::uint8_t* data, std::size_t size,
                                                std::size_t maxParts) {
    std::vector<std::string_view> parts;
    std::string_view rest(reinterpret_cast<const char*>(data), size);
    while (parts.size() + 1 < maxParts) {
        const std::size_t at = rest.find(kPartSeparator);
        if (at == std::string_view::npos) break;
        parts.push_back(rest.substr(0, at));
        rest.remove_prefix(at + kPartSeparator.size());
    }
    parts.push_back(rest);
    return parts;
}

/// Writes the parts of the input to scratchDir()/names[i]; returns the first file's path.
inline std::filesystem::path writeParts(const std::uint8_t* data, std::size_t size,
                                        const std::vector<std::string>& names) {
    clearScratch();
    const auto parts = splitParts(data, size, names.size());
    for (std::size_t i = 0; i < parts.size(); ++i)
        writeFile(scratchDir() / names[i], parts[i].data(), parts[i].size());
    return scratchDir() / names.front();
}

/// Runs the loader; InputError is the expected outcome of bad input, anything else aborts.
inline void runLoader(const std::function<void()>& load) {
    try {
        load();
    } catch (const InputError& e) {
        const std::string msg = e.what();
        if (msg.find('\n') != std::string::npos || msg.find('\r') != std::string::npos) {
            std::fprintf(stderr, "voxlight fuzz: InputError spans several lines:\n%s\n",
                         msg.c_str());
            std::abort();
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "voxlight fuzz: uncaught non-input exception: %s\n", e.what());
        std::abort();
    } catch (...) {
        std::fprintf(stderr, "voxlight fuzz: uncaught exception of unknown type\n");
        std::abort();
    }
}

}  // namespace voxlight::fuzz
