// SPDX-License-Identifier: MIT
#include "pipeline/artifact_cache.h"

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <system_error>

#include "core/hash.h"

namespace voxlight::pipeline {

namespace fs = std::filesystem;

namespace {
constexpr char kMagic[16] = {'V', 'O', 'X', 'L', 'I', 'G', 'H',  'T',
                             '-', 'C', 'A', 'C', 'H', 'E', '\0', '\n'};
constexpr std::size_t kMaxStageName = 256;

/// What a cache file's header says, checked against what the caller expects.
struct Header {
    bool exists = false;
    std::string problem;  ///< empty: the header fits (the payload is not checked yet)
    std::uint64_t payloadSize = 0, payloadHash = 0;
    std::streamoff payloadOffset = 0;
};

/// Reads and checks only the header (magic, versions, stage, key, declared size against the
/// file's size): cheap, so --explain can use it, and no allocation trusts a damaged length.
Header readHeader(const fs::path& path, const std::string& stage, std::uint64_t key,
                  std::uint32_t codecVersion) {
    Header h;
    std::ifstream in(path, std::ios::binary);
    if (!in) return h;
    h.exists = true;
    in.seekg(0, std::ios::end);
    const std::streamoff fileSize = in.tellg();
    in.seekg(0);
    constexpr std::size_t kMaxHeader = sizeof kMagic + 4 + 4 + 8 + kMaxStageName + 8 + 8 + 8;
    std::vector<unsigned char> head(kMaxHeader);
    in.read(reinterpret_cast<char*>(head.data()), std::streamsize(head.size()));
    head.resize(std::size_t(in.gcount()));
    try {
        ByteReader r(head.data(), head.size());
        char magic[sizeof kMagic];
        for (char& c : magic) c = r.pod<char>();
        if (std::memcmp(magic, kMagic, sizeof kMagic) != 0) {
            h.problem = "is not a voxlight cache file";
            return h;
        }
        const auto format = r.pod<std::uint32_t>();
        if (format != kCacheFormatVersion) {
            h.problem = "has cache format " + std::to_string(format) + ", this build reads " +
                        std::to_string(kCacheFormatVersion);
            return h;
        }
        const auto version = r.pod<std::uint32_t>();
        if (version != codecVersion) {
            h.problem = "holds " + stage + " version " + std::to_string(version) +
                        ", this build writes " + std::to_string(codecVersion);
            return h;
        }
        if (r.string(kMaxStageName) != stage || r.pod<std::uint64_t>() != key) {
            h.problem = "belongs to another stage or key";
            return h;
        }
        h.payloadSize = r.pod<std::uint64_t>();
        h.payloadHash = r.pod<std::uint64_t>();
        h.payloadOffset = std::streamoff(head.size() - r.remaining());
        const std::uint64_t actual = std::uint64_t(fileSize - h.payloadOffset);
        if (h.payloadSize > kMaxPayloadBytes || h.payloadSize != actual)
            h.problem = "is truncated or padded (" + std::to_string(actual) + " of " +
                        std::to_string(h.payloadSize) + " payload bytes)";
    } catch (const CacheFormatError&) {
        h.problem = "is truncated (header incomplete)";
    }
    return h;
}

/// Records are one 64-bit value.
const Codec& recordCodec() {
    static const Codec c{1, [](const Artifact& a, ByteWriter& w) { w.pod(*a.as<std::uint64_t>()); },
                         [](ByteReader& r) {
                             return Artifact::of(
                                 std::make_shared<const std::uint64_t>(r.pod<std::uint64_t>()), 8);
                         }};
    return c;
}

/// A temporary name no other process or thread uses: pid, a per-process counter, the clock.
fs::path temporaryBeside(const fs::path& target) {
    static std::atomic<std::uint64_t> counter{0};
    const std::uint64_t n = counter.fetch_add(1);
    const auto t = std::uint64_t(std::chrono::steady_clock::now().time_since_epoch().count());
    return target.parent_path() /
           ("." + target.filename().string() + "." + std::to_string(::getpid()) + "." +
            std::to_string(n) + "." + core::hexKey(t) + ".tmp");
}

/// Writes bytes to path atomically (temporary file, then rename). Returns an error text or "".
std::string writeAtomically(const fs::path& path, const std::vector<unsigned char>& bytes) {
    const fs::path tmp = temporaryBeside(path);
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out) return "cannot create " + tmp.string();
        out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
        out.flush();
        if (!out) {
            std::error_code ec;
            fs::remove(tmp, ec);
            return "cannot write " + tmp.string() + " (disk full?)";
        }
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        return "cannot rename into " + path.string() + ": " + ec.message();
    }
    return {};
}
}  // namespace

ArtifactCache::ArtifactCache(std::size_t memoryBudget) : budget_(memoryBudget) {}

void ArtifactCache::setDirectory(const fs::path& dir) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec || !fs::is_directory(dir))
        throw InputError("command line", "--cache",
                         "'" + dir.string() + "' is not a directory that can be created",
                         "give a writable directory");
    dir_ = dir;
    // Temporaries of processes killed mid-write: old enough that no live writer owns them.
    const auto now = fs::file_time_type::clock::now();
    for (const auto& e : fs::directory_iterator(dir, ec)) {
        const std::string name = e.path().filename().string();
        if (name.size() < 5 || name[0] != '.' || name.compare(name.size() - 4, 4, ".tmp") != 0)
            continue;
        std::error_code tec;
        const auto t = fs::last_write_time(e.path(), tec);
        if (!tec && now - t > kStaleTemporaryAge) fs::remove(e.path(), tec);
    }
}

void ArtifactCache::setMemoryBudget(std::size_t bytes) {
    std::lock_guard lock(mutex_);
    budget_ = bytes;
    evict();
}

std::size_t ArtifactCache::memoryBytes() const {
    std::lock_guard lock(mutex_);
    return bytes_;
}

std::size_t ArtifactCache::memoryEntries() const {
    std::lock_guard lock(mutex_);
    return entries_.size();
}

void ArtifactCache::warn(const std::string& message) const {
    if (warn_)
        warn_(message);
    else
        std::fprintf(stderr, "voxlight: %s\n", message.c_str());
}

std::optional<Artifact> ArtifactCache::findInMemory(const std::string& stage, std::uint64_t key) {
    std::lock_guard lock(mutex_);
    const auto it = entries_.find({stage, key});
    if (it == entries_.end()) return std::nullopt;
    lru_.splice(lru_.begin(), lru_, it->second.lru);
    return it->second.artifact;
}

bool ArtifactCache::inMemory(const std::string& stage, std::uint64_t key) const {
    std::lock_guard lock(mutex_);
    return entries_.count({stage, key}) > 0;
}

void ArtifactCache::putInMemory(const std::string& stage, std::uint64_t key,
                                const Artifact& artifact) {
    std::lock_guard lock(mutex_);
    const Id id{stage, key};
    if (const auto it = entries_.find(id); it != entries_.end()) {
        bytes_ -= it->second.artifact.bytes;
        lru_.erase(it->second.lru);
        entries_.erase(it);
    }
    lru_.push_front(id);
    entries_.emplace(id, Entry{artifact, lru_.begin()});
    bytes_ += artifact.bytes;
    evict();
}

void ArtifactCache::clearMemory() {
    std::lock_guard lock(mutex_);
    entries_.clear();
    lru_.clear();
    bytes_ = 0;
}

void ArtifactCache::evict() {
    // The newest entry stays even when it alone exceeds the budget: it is about to be used.
    while (bytes_ > budget_ && lru_.size() > 1) {
        const Id victim = lru_.back();
        lru_.pop_back();
        const auto it = entries_.find(victim);
        bytes_ -= it->second.artifact.bytes;
        entries_.erase(it);
    }
}

fs::path ArtifactCache::fileFor(const std::string& stage, std::uint64_t key) const {
    VL_CHECK(dir_.has_value());
    return *dir_ / (stage + "-" + core::hexKey(key) + ".vlcache");
}

bool ArtifactCache::onDisk(const std::string& stage, std::uint64_t key, const Codec& codec) const {
    if (!dir_) return false;
    const Header h = readHeader(fileFor(stage, key), stage, key, codec.version);
    return h.exists && h.problem.empty();
}

std::optional<Artifact> ArtifactCache::readDisk(const std::string& stage, std::uint64_t key,
                                                const Codec& codec) {
    if (!dir_) return std::nullopt;
    const fs::path path = fileFor(stage, key);
    auto bad = [&](const std::string& why) -> std::optional<Artifact> {
        warn("cache file " + path.string() + " " + why + "; recomputing " + stage);
        return std::nullopt;
    };
    const Header h = readHeader(path, stage, key, codec.version);
    if (!h.exists) return std::nullopt;
    if (!h.problem.empty()) return bad(h.problem);
    try {
        // The declared size matches the file's (readHeader), so this allocation is the file's.
        std::vector<unsigned char> payload(static_cast<std::size_t>(h.payloadSize));
        std::ifstream in(path, std::ios::binary);
        in.seekg(h.payloadOffset);
        in.read(reinterpret_cast<char*>(payload.data()), std::streamsize(payload.size()));
        if (!in) return bad("cannot be read to its end");
        if (core::hashBytes(payload.data(), payload.size(), key) != h.payloadHash)
            return bad("fails its checksum (damaged)");
        ByteReader body(payload.data(), payload.size());
        Artifact a = codec.read(body);
        body.expectEnd();
        return a;
    } catch (const std::exception& e) {
        // CacheFormatError, an InputError/InternalError from a constructor's checks, bad_alloc.
        return bad(std::string("does not decode (") + e.what() + ")");
    }
}

void ArtifactCache::writeDisk(const std::string& stage, std::uint64_t key, const Codec& codec,
                              const Artifact& artifact) {
    if (!dir_) return;
    ByteWriter payload;
    codec.write(artifact, payload);
    ByteWriter file;
    for (char c : kMagic) file.pod(c);
    file.pod(kCacheFormatVersion);
    file.pod(codec.version);
    file.string(stage);
    file.pod(key);
    file.pod(std::uint64_t(payload.bytes().size()));
    file.pod(core::hashBytes(payload.bytes().data(), payload.bytes().size(), key));
    auto& bytes = file.bytes();
    bytes.insert(bytes.end(), payload.bytes().begin(), payload.bytes().end());
    if (const std::string err = writeAtomically(fileFor(stage, key), bytes); !err.empty())
        warn("cannot write the cache: " + err);
}

std::optional<std::uint64_t> ArtifactCache::record(const std::string& kind, std::uint64_t key) {
    {
        std::lock_guard lock(mutex_);
        if (const auto it = records_.find({kind, key}); it != records_.end()) return it->second;
    }
    if (auto a = readDisk(kind, key, recordCodec())) {
        const std::uint64_t v = *a->as<std::uint64_t>();
        std::lock_guard lock(mutex_);
        records_[{kind, key}] = v;
        return v;
    }
    return std::nullopt;
}

void ArtifactCache::putRecord(const std::string& kind, std::uint64_t key, std::uint64_t value,
                              bool onDisk) {
    {
        std::lock_guard lock(mutex_);
        records_[{kind, key}] = value;
    }
    // Always rewritten (atomically): a damaged or stale record is repaired by the next load.
    if (dir_ && onDisk)
        writeDisk(kind, key, recordCodec(),
                  Artifact::of(std::make_shared<const std::uint64_t>(value), 8));
}

}  // namespace voxlight::pipeline
