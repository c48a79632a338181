// SPDX-License-Identifier: MIT
#pragma once
// Artifacts and where they are kept between stages, frames and processes.
//
// An Artifact is a stage's product: an immutable object behind a shared_ptr (so a frame, the cache
// and a viewer can hold it at once), its type, and its size in bytes (for the memory budget).
//
// ArtifactCache keeps artifacts by (stage name, 64-bit key):
// * in memory, up to a byte budget; beyond it the least recently used entries are dropped (an
//   artifact still held by someone stays alive, the cache just forgets it);
// * on disk, when a directory is given (`--cache DIR`), for stages that have a Codec. One file per
//   artifact, `<stage>-<key>.vlcache`: a header (magic, cache format version, codec version, stage
//   name, key, payload size, payload hash) and the payload. Reading checks every header field and
//   the payload hash; a damaged, truncated, foreign-version or mismatched file is reported through
//   warn() and treated as a miss (the stage recomputes and rewrites it), never trusted. Writing goes
//   to a unique temporary name in the same directory, then rename(): another process sees the old
//   file, the new one, or none — never a partial one — so processes may share a directory.
// * small records: identity → 64-bit value (a volume file's identity → its content hash), so a new
//   process can name the keys of the volume's artifacts before it has read the volume (--explain).
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <typeindex>
#include <typeinfo>

#include "core/error.h"
#include "pipeline/byte_io.h"

namespace voxlight::pipeline {

struct Artifact {
    std::shared_ptr<const void> object;
    std::type_index type = typeid(void);
    std::size_t bytes = 0;

    template <class T>
    static Artifact of(std::shared_ptr<const T> p, std::size_t bytes) {
        return {std::static_pointer_cast<const void>(std::move(p)), typeid(T), bytes};
    }
    template <class T>
    std::shared_ptr<const T> as() const {
        if (type != typeid(T))
            throw InternalError(std::string("artifact holds ") + type.name() + ", not " +
                                typeid(T).name());
        return std::static_pointer_cast<const T>(object);
    }
    bool empty() const { return !object; }
};

/// How a stage's artifact is written to and read from a cache file. Bump `version` whenever the
/// encoding or the meaning of the artifact changes: files of another version are recomputed.
struct Codec {
    std::uint32_t version = 1;
    std::function<void(const Artifact&, ByteWriter&)> write;
    /// Throws CacheFormatError when the payload does not decode to a valid artifact.
    std::function<Artifact(ByteReader&)> read;
};

/// Format of the cache files themselves (header layout); bump when it changes.
inline constexpr std::uint32_t kCacheFormatVersion = 1;
/// Default in-process budget: a quarter of this kind of machine's 24 GB, enough for the tables of
/// a few 512³ CTs; sweeps and the viewer may set their own.
inline constexpr std::size_t kDefaultMemoryBudget = std::size_t(6) << 30;
/// A temporary cache file older than this belongs to a process that died mid-write (writing even
/// gigabytes takes seconds to minutes): setDirectory() removes it.
inline constexpr std::chrono::hours kStaleTemporaryAge{1};
/// Largest payload a cache file may claim (guards the read allocation).
inline constexpr std::uint64_t kMaxPayloadBytes = std::uint64_t(64) << 30;

class ArtifactCache {
  public:
    explicit ArtifactCache(std::size_t memoryBudget = kDefaultMemoryBudget);

    /// Keep artifacts with a Codec on disk in `dir` too (created if missing; InputError naming
    /// `--cache` when it cannot be). Removes temporaries older than kStaleTemporaryAge.
    void setDirectory(const std::filesystem::path& dir);
    const std::optional<std::filesystem::path>& directory() const { return dir_; }
    void setMemoryBudget(std::size_t bytes);
    std::size_t memoryBudget() const { return budget_; }
    std::size_t memoryBytes() const;
    std::size_t memoryEntries() const;
    /// Where cache problems are reported (default: one line on stderr).
    void setWarn(std::function<void(const std::string&)> warn) { warn_ = std::move(warn); }

    std::optional<Artifact> findInMemory(const std::string& stage, std::uint64_t key);
    bool inMemory(const std::string& stage, std::uint64_t key) const;
    void putInMemory(const std::string& stage, std::uint64_t key, const Artifact& artifact);
    void clearMemory();

    /// The artifact from its cache file, or nullopt (no directory, no file, or a bad file —
    /// reported through warn()).
    std::optional<Artifact> readDisk(const std::string& stage, std::uint64_t key,
                                     const Codec& codec);
    /// Whether a file for (stage, key) exists with a header that fits this codec and its size
    /// (the payload's checksum is checked only when it is read; for --explain).
    bool onDisk(const std::string& stage, std::uint64_t key, const Codec& codec) const;
    /// Writes atomically; a failure (disk full, permissions) is reported through warn(), not
    /// thrown: the render does not depend on the cache.
    void writeDisk(const std::string& stage, std::uint64_t key, const Codec& codec,
                   const Artifact& artifact);
    std::filesystem::path fileFor(const std::string& stage, std::uint64_t key) const;

    /// Small records (memory, and disk when a directory is set and `onDisk`; a record that only
    /// points at a memory-only artifact — the last field of a lineage — is kept in memory only).
    std::optional<std::uint64_t> record(const std::string& kind, std::uint64_t key);
    void putRecord(const std::string& kind, std::uint64_t key, std::uint64_t value,
                   bool onDisk = true);

  private:
    using Id = std::pair<std::string, std::uint64_t>;
    struct Entry {
        Artifact artifact;
        std::list<Id>::iterator lru;
    };
    void evict();  // caller holds mutex_
    void warn(const std::string& message) const;

    mutable std::mutex mutex_;
    std::size_t budget_;
    std::size_t bytes_ = 0;
    std::map<Id, Entry> entries_;
    std::list<Id> lru_;  // front = most recently used
    std::map<Id, std::uint64_t> records_;
    std::optional<std::filesystem::path> dir_;
    std::function<void(const std::string&)> warn_;
};

}  // namespace voxlight::pipeline
