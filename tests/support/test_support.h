// SPDX-License-Identifier: MIT
#pragma once
// Helpers shared by the test executables: temporary directories, shared-data lookup with a clear
// skip.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

namespace voxlight::test {

/// Whether this build runs under AddressSanitizer, whose shadow memory rules out the reading
/// children's address-space caps (tests of those caps skip).
constexpr bool kAddressSanitized =
#if defined(__SANITIZE_ADDRESS__)
    true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
    true;
#else
    false;
#endif
#else
    false;
#endif

/// A fresh directory under the system temp dir, removed when the object dies. Tests never write to
/// the source tree.
class TempDir {
  public:
    TempDir();
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    const std::filesystem::path& path() const { return path_; }
    std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

  private:
    std::filesystem::path path_;
};

/// The project source directory (from VOXLIGHT_SOURCE_DIR, set by CTest; falls back to the current
/// directory).
std::filesystem::path sourceDir();

/// Path of a file under ../shared/datasets relative to the project root, or nullopt if absent.
std::optional<std::filesystem::path> sharedDataset(const std::string& relative);

/// DICOM bytes for tests that write files by hand: little-endian 16/32-bit words appended to s,
/// a 16-bit word as a string, and one explicit-VR little-endian element with `value` padded to
/// even length (the 4-byte length form for OB, OW, SQ and UN).
void putU16(std::string& s, unsigned v);
void putU32(std::string& s, std::uint32_t v);
std::string u16(unsigned v);
std::string element(unsigned group, unsigned elem, const char* vr, std::string value);

/// Writes `dir`/hang.mhd, a MetaImage whose second slice file (s1.raw) is a FIFO nobody writes:
/// MetaIO blocks in open(2) on it forever, as on a hung network share. Returns the header's path.
std::filesystem::path writeBlockedMetaImage(const std::filesystem::path& dir);

/// Writes a small CT series into `dir` (created if missing), one file per slice: `slices` slices of
/// 12×8 int16 pixels (0.5 × 0.75 mm, rescale −1024), 2 mm apart and each sheared 2·tan 15° mm
/// further in y — a 15° gantry tilt, which the loader resamples with one warning line (unless
/// ReadOptions::strictGeometry). Explicit VR little endian written byte by byte: no GDCM needed.
void writeTiltedCtSeries(const std::filesystem::path& dir, int slices = 4);

/// What a shell command line did: exit code (−1 when it did not exit), stdout, stderr.
struct ShellResult {
    int code;
    std::string out, err;
};
/// Runs a shell command line (through popen), its stdout read and its last command's stderr
/// captured through a file in `dir` (removed afterwards).
ShellResult runShell(const std::string& line, const std::filesystem::path& dir);

}  // namespace voxlight::test

/// Skips the current test with a clear message when a shared dataset is missing; else binds `var`
/// to its path.
#define VL_REQUIRE_SHARED(var, relative)                                                    \
    auto var##_opt = ::voxlight::test::sharedDataset(relative);                             \
    if (!var##_opt)                                                                         \
        GTEST_SKIP() << "shared dataset ../shared/datasets/" << (relative)                  \
                     << " is absent on this machine; this test needs it (see MANIFEST.md)"; \
    const std::filesystem::path var = *var##_opt

/// Same for an absolute system path (e.g. Debian's mricron-data templates).
#define VL_REQUIRE_FILE(var, absolute)                                                         \
    if (!std::filesystem::exists(absolute))                                                    \
        GTEST_SKIP() << (absolute)                                                             \
                     << " is absent; install Debian's package that ships it (tools/setup.sh)"; \
    const std::filesystem::path var = (absolute)
