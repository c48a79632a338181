// SPDX-License-Identifier: MIT
#include "app/output_files.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <system_error>

#include "core/error.h"
#include "core/files.h"

namespace voxlight::app {

namespace {
namespace fs = std::filesystem;

/// The temporaries' names begin so (hidden; a crash's leftovers are recognisable).
const std::string kTemporaryPrefix = ".voxlight-partial-";

std::string lower(std::string s) {
    for (auto& ch : s) ch = char(std::tolower(static_cast<unsigned char>(ch)));
    return s;
}

bool endsWith(const std::string& s, const std::string& suffix) {
    return s.size() > suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

[[noreturn]] void fail(const OutputSpec& o, const std::string& problem, const std::string& fix) {
    throw InputError("command line", o.option, problem, fix);
}

fs::path directoryOf(const fs::path& path) {
    return path.parent_path().empty() ? fs::path(".") : path.parent_path();
}

/// The file a path names once symlinks in its existing part are resolved, for duplicate checks.
fs::path identity(const fs::path& path) {
    std::error_code ec;
    fs::path p = fs::weakly_canonical(fs::absolute(path, ec), ec);
    return ec ? fs::absolute(path, ec).lexically_normal() : p;
}

/// Where an output is written: a symlink to a regular file is written through (the file it
/// names is replaced, the link stays); any other path as given. checkOne probes the folder
/// this gives, OutputFiles::write writes there.
fs::path resolveOutput(const fs::path& path) {
    std::error_code ec;
    if (!fs::is_symlink(fs::symlink_status(path, ec)) || !fs::is_regular_file(fs::status(path, ec)))
        return path;
    const fs::path file = fs::canonical(path, ec);
    return ec ? path : file;
}

/// The ending a temporary keeps so that writers choosing the format by extension still do: the
/// last extension, or the last two when the last is a compression suffix ("a.nii.gz" →
/// ".nii.gz"); short whatever the name (a long name with an early dot stays a long name).
std::string formatSuffix(const fs::path& target) {
    fs::path name = target.filename();
    std::string suffix = name.extension().string();
    if (lower(suffix) == ".gz") suffix = name.stem().extension().string() + suffix;
    return suffix;
}

void checkOne(const OutputSpec& o) {
    const std::string name = o.path.string();
    if (!o.extensions.empty()) {
        const std::string file = lower(o.path.filename().string());
        if (std::none_of(o.extensions.begin(), o.extensions.end(),
                         [&](const std::string& e) { return endsWith(file, e); })) {
            fail(o, "'" + name + "' has an unsupported extension",
                 "use one of: " + joinNames(o.extensions));
        }
    }
    std::error_code ec;
    if (fs::is_directory(o.path, ec))
        fail(o, "'" + name + "' is a directory", "give a file name inside it");
    // A FIFO or device (a symlink to a pipe, /dev/stdout onto a terminal) would be replaced by a
    // regular file, not written to.
    if (core::isSpecialFile(o.path))
        fail(o, "'" + name + "' is a FIFO, socket or device, not a file",
             "give a regular file (redirect to a file, not to a pipe)");
    const fs::path written = resolveOutput(o.path);
    // A name the file system cannot hold fails only at the end of the work otherwise.
    const long nameMax = ::pathconf(directoryOf(written).c_str(), _PC_NAME_MAX);
    const std::size_t nameBytes = o.path.filename().string().size();
    if (nameMax > 0 && nameBytes > std::size_t(nameMax))
        fail(o,
             "the file name of '" + name + "' is " + std::to_string(nameBytes) +
                 " bytes long, more than the " + std::to_string(nameMax) +
                 " its file system allows",
             "give a shorter name");
    const fs::path dir = directoryOf(written);
    const fs::file_status st = fs::status(dir, ec);
    if (!fs::exists(st))
        fail(o, "directory '" + dir.string() + "' does not exist", "create it first");
    if (!fs::is_directory(st))
        fail(o, "'" + dir.string() + "' is not a directory", "give a path inside a directory");
    // Create and remove a file there: unlike access(), this also answers for root and for file
    // systems that refuse new files whatever the permission bits say (read-only, /proc).
    const fs::path probe = dir / (".voxlight-probe-" + std::to_string(::getpid()));
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0)
        fail(o, "cannot create files in directory '" + dir.string() + "': " + std::strerror(errno),
             "choose a writable directory");
    ::close(fd);
    ::unlink(probe.c_str());
}
}  // namespace

void checkOutputs(const std::vector<OutputSpec>& outputs,
                  const std::vector<std::pair<std::string, fs::path>>& inputs) {
    auto sameFile = [](const fs::path& a, const fs::path& b) {
        std::error_code ec;
        return identity(a) == identity(b) || fs::equivalent(a, b, ec);
    };
    std::vector<const OutputSpec*> given;
    for (const auto& o : outputs)
        if (!o.path.empty()) given.push_back(&o);
    for (const OutputSpec* o : given) checkOne(*o);
    for (const OutputSpec* o : given)
        for (const auto& [name, path] : inputs)
            if (!path.empty() && sameFile(o->path, path))
                fail(*o, "'" + o->path.string() + "' is " + name + ", which it would replace",
                     "write the output to another file");
    for (std::size_t i = 0; i < given.size(); ++i) {
        for (std::size_t j = 0; j < i; ++j) {
            const bool same = sameFile(given[i]->path, given[j]->path);
            if (same)
                fail(*given[i],
                     "'" + given[i]->path.string() + "' is the same file as " + given[j]->option,
                     "give each output its own file");
        }
    }
}

OutputFiles::~OutputFiles() {
    for (const auto& e : entries_) {
        std::error_code ec;
        fs::remove(e.temporary, ec);  // already gone after a commit: nothing to report
    }
}

void OutputFiles::write(const fs::path& target, const std::string& option,
                        const std::function<void(const fs::path&)>& writer) {
    // Unique per process and output; hidden, short (a target's name may be near the file system's
    // limit) and ending in the target's format suffix (formatSuffix).
    static std::atomic<int> counter{0};
    // A directory where the file goes would be moved aside by commit() (a replay frame's name
    // taken by a folder: the folder renamed to a hidden name, exit 0; probe).
    if (std::error_code ec; fs::is_directory(target, ec))
        throw InputError("command line", option, "'" + target.string() + "' is a directory",
                         "remove it, or write elsewhere");
    const fs::path file = resolveOutput(target);
    const fs::path dir = directoryOf(file);
    const fs::path temporary = dir / (kTemporaryPrefix + std::to_string(::getpid()) + "-" +
                                      std::to_string(counter++) + formatSuffix(target));
    entries_.push_back({temporary, file, option, target});
    try {
        writer(temporary);
    } catch (const CancelledError&) {
        throw;  // Ctrl-C is Ctrl-C, full disk or not
    } catch (const InputError& e) {
        // A full disk explains the writer's own message (which may name its temporaries).
        if (core::fileSystemFull(dir)) throw core::noSpaceLeft(target.string());
        // The writer's errors name the temporary (or a temporary of its own beside it).
        if (e.source().rfind((dir / kTemporaryPrefix).string(), 0) != 0) throw;
        throw InputError(target.string(), e.field(), e.problem(), e.fix());
    } catch (const std::exception&) {
        if (core::fileSystemFull(dir)) throw core::noSpaceLeft(target.string());
        throw;
    }
    // Writers that ignore a failed write report success over a short file (core::fileSystemFull).
    if (core::fileSystemFull(dir)) throw core::noSpaceLeft(target.string());
}

void OutputFiles::commit() {
    // All or nothing, and a target that existed before keeps its old content unless the whole
    // commit succeeds. Each old target is first kept under a second name — a hard link, so that
    // the target itself never goes missing and the new file replaces it in one atomic rename
    // (renamed aside where the file system refuses the link) — and a failure moves every kept
    // file back. A target that cannot be replaced (immutable: link(2) and rename(2) refuse it, a
    // read-only mount) fails before anything of it changed.
    struct Kept {
        fs::path target, old;  ///< old empty: there was no old file
        bool linked = false;   ///< old is a second link (the target still exists)
    };
    std::vector<Kept> done;
    auto restore = [](const Kept& k) {
        std::error_code ignored;
        if (k.old.empty())
            fs::remove(k.target, ignored);
        else
            fs::rename(k.old, k.target, ignored);
    };
    for (const Entry& e : entries_) {
        std::error_code ec, statusError;  // status sets its error code for a missing file too
        Kept k{e.target, {}};
        const fs::file_status old = fs::symlink_status(e.target, statusError);
        if (fs::exists(old)) {
            k.old = e.temporary.string() + ".old";
            fs::create_hard_link(e.target, k.old, ec);
            k.linked = !ec;
            if (ec) {  // no hard links here (vfat says EPERM, as for an immutable file)
                ec.clear();
                fs::rename(e.target, k.old, ec);
            }
            // The new file keeps a regular old file's permission bits (a private 0600 output
            // stays so; never set-id or sticky bits, never a dangling link's "unknown").
            if (!ec && fs::is_regular_file(old)) {
                std::error_code ignored;
                fs::permissions(e.temporary, old.permissions() & fs::perms::all, ignored);
            }
        }
        if (!ec) fs::rename(e.temporary, e.target, ec);
        if (ec) {
            if (!k.old.empty() && (k.linked || !fs::exists(e.target, statusError))) {
                std::error_code ignored;
                if (k.linked)
                    fs::remove(k.old, ignored);  // the target was never touched
                else
                    fs::rename(k.old, e.target, ignored);
            }
            for (auto d = done.rbegin(); d != done.rend(); ++d) restore(*d);
            throw InputError("command line", e.option,
                             "cannot move the written file into place as '" + e.shown.string() +
                                 "': " + ec.message(),
                             "check the file's and the directory's permissions and free space");
        }
        done.push_back(k);
    }
    for (const Kept& k : done)
        if (!k.old.empty()) {
            std::error_code ignored;
            fs::remove(k.old, ignored);
        }
    entries_.clear();
}

void writeTextFile(const fs::path& path, const std::string& text) {
    core::writeWholeFile(path, text + "\n");
}

}  // namespace voxlight::app
