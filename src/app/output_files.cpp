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

namespace voxlight::app {

namespace {
namespace fs = std::filesystem;

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
    const fs::path dir = directoryOf(o.path);
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
    // Unique per process and output; hidden, and ending in the target's name (and extension).
    static std::atomic<int> counter{0};
    const fs::path temporary =
        directoryOf(target) / (".voxlight-partial-" + std::to_string(::getpid()) + "-" +
                               std::to_string(counter++) + "-" + target.filename().string());
    entries_.push_back({temporary, target, option});
    try {
        writer(temporary);
    } catch (const InputError& e) {
        if (e.source() != temporary.string()) throw;
        throw InputError(target.string(), e.field(), e.problem(), e.fix());
    }
}

void OutputFiles::commit() {
    for (std::size_t i = 0; i < entries_.size(); ++i) {
        const Entry& e = entries_[i];
        std::error_code ec;
        fs::rename(e.temporary, e.target, ec);
        if (!ec) continue;
        // All or nothing: take back what this commit already moved (the destructor removes the
        // temporaries still waiting).
        for (std::size_t j = 0; j < i; ++j) {
            std::error_code ignored;
            fs::remove(entries_[j].target, ignored);
        }
        throw InputError("command line", e.option,
                         "cannot move the written file into place as '" + e.target.string() +
                             "': " + ec.message(),
                         "check the directory's permissions and free space");
    }
    entries_.clear();
}

void writeTextFile(const fs::path& path, const std::string& text) {
    const std::string name = path.string();
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f)
        throw InputError(name, "", std::string("cannot be created: ") + std::strerror(errno),
                         "check the directory's permissions");
    const bool written = std::fwrite(text.data(), 1, text.size(), f) == text.size() &&
                         std::fputc('\n', f) != EOF && std::fflush(f) == 0;
    const int writeErrno = errno;
    const bool closed = std::fclose(f) == 0;
    if (!written || !closed)
        throw InputError(
            name, "",
            std::string("cannot be written: ") + std::strerror(!written ? writeErrno : errno),
            "check free disk space");
}

}  // namespace voxlight::app
