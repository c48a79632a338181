// SPDX-License-Identifier: MIT
#pragma once
// Input paths that are not files: a FIFO blocks its reader in open() until a writer appears (and
// Ctrl-C cannot end it: the signal handler's flag is only read between steps), a character device
// streams without end. Every reader of user-named paths asks this first.
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>

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

/// Bytes this process may still write on the file system holding directory `dir` (statvfs:
/// the blocks available to everyone, or every free block for root, who may use the reserved
/// ones); -1 when it cannot be asked or the file system counts no blocks at all (procfs, some
/// FUSE file systems: they say nothing about space).
inline std::int64_t freeBytes(const std::filesystem::path& dir) {
    struct statvfs st {};
    if (::statvfs(dir.empty() ? "." : dir.c_str(), &st) != 0 || st.f_blocks == 0) return -1;
    const std::uint64_t blocks = ::geteuid() == 0 ? st.f_bfree : st.f_bavail;
    return std::int64_t(std::min<std::uint64_t>(blocks * st.f_frsize, INT64_MAX));
}

/// Whether the file system holding `dir` has no block left for this process. Writers that ignore
/// a failed write (OpenImageIO's PNG and BMP, VTK's MetaImage, tinygltf) leave a short file and
/// report success: a file system full right after the write is how that failure shows (a file
/// that filled it exactly is refused too — the disk is full either way).
inline bool fileSystemFull(const std::filesystem::path& dir) { return freeBytes(dir) == 0; }

/// The InputError for a file that could not be written whole because its disk is full.
inline InputError noSpaceLeft(const std::string& file) {
    return InputError(file, "", "cannot be written: no space left on the device (the disk is full)",
                      "free disk space, or write it to another disk");
}

/// Writes `data` to `path` (created or truncated) with every write checked; InputError naming
/// `path` with the system's reason when it cannot be created or written whole (a library's own
/// file writer may report success over a short file: serialise to memory, then write here).
inline void writeWholeFile(const std::filesystem::path& path, std::string_view data) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f)
        throw InputError(path.string(), "",
                         std::string("cannot be created: ") + std::strerror(errno),
                         "check the directory's permissions");
    const bool written =
        std::fwrite(data.data(), 1, data.size(), f) == data.size() && std::fflush(f) == 0;
    const int writeErrno = errno;
    const bool closed = std::fclose(f) == 0;
    if (!written || !closed)
        throw InputError(
            path.string(), "",
            std::string("cannot be written: ") + std::strerror(!written ? writeErrno : errno),
            "check free disk space, disk quotas and permissions");
}

}  // namespace voxlight::core
