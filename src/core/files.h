// SPDX-License-Identifier: MIT
#pragma once
// Input paths that are not files: a FIFO blocks its reader in open() until a writer appears (and
// Ctrl-C cannot end it: the signal handler's flag is only read between steps), a character device
// streams without end. Every reader of user-named paths asks this first.
#include <filesystem>
#include <string>

#include "core/error.h"

namespace voxlight::core {

/// Whether `p` exists and is a FIFO, socket or device (not a regular file, directory or symlink
/// to one).
inline bool isSpecialFile(const std::filesystem::path& p) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::file_type t = fs::status(p, ec).type();
    return !ec && (t == fs::file_type::fifo || t == fs::file_type::socket ||
                   t == fs::file_type::character || t == fs::file_type::block);
}

/// InputError naming `p` when isSpecialFile(p); nothing otherwise (missing paths are the
/// caller's to report).
inline void refuseSpecialFile(const std::filesystem::path& p) {
    if (isSpecialFile(p))
        throw InputError(p.string(), "path", "is a FIFO, socket or device, not a file",
                         "give a regular file, or copy the stream to one first");
}

}  // namespace voxlight::core
