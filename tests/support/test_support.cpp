// SPDX-License-Identifier: MIT
#include "support/test_support.h"

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

namespace voxlight::test {

TempDir::TempDir() {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name =
        info ? std::string(info->test_suite_name()) + "." + info->name() : "voxlight";
    for (char& c : name)
        if (c == '/') c = '_';
    path_ =
        std::filesystem::temp_directory_path() / ("voxlight-test-" + std::to_string(::getpid()) +
                                                  "-" + std::to_string(counter++) + "-" + name);
    std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
    std::error_code ec;
    if (!std::getenv("VOXLIGHT_KEEP_TEST_OUTPUT")) std::filesystem::remove_all(path_, ec);
}

std::filesystem::path sourceDir() {
    if (const char* s = std::getenv("VOXLIGHT_SOURCE_DIR")) return s;
    return std::filesystem::current_path();
}

std::optional<std::filesystem::path> sharedDataset(const std::string& relative) {
    const auto p = sourceDir() / ".." / "shared" / "datasets" / relative;
    if (std::filesystem::exists(p)) return std::filesystem::weakly_canonical(p);
    return std::nullopt;
}

void putU16(std::string& s, unsigned v) {
    s += char(v & 0xff);
    s += char(v >> 8 & 0xff);
}
void putU32(std::string& s, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) s += char(v >> (8 * i) & 0xff);
}
std::string u16(unsigned v) {
    std::string s;
    putU16(s, v);
    return s;
}
std::string element(unsigned group, unsigned elem, const char* vr, std::string value) {
    if (value.size() % 2) value += std::strcmp(vr, "UI") == 0 ? '\0' : ' ';
    std::string s;
    putU16(s, group);
    putU16(s, elem);
    s += vr;
    const bool longForm = std::strcmp(vr, "OB") == 0 || std::strcmp(vr, "OW") == 0 ||
                          std::strcmp(vr, "SQ") == 0 || std::strcmp(vr, "UN") == 0;
    if (longForm) {
        putU16(s, 0);
        putU32(s, std::uint32_t(value.size()));
    } else {
        putU16(s, unsigned(value.size()));
    }
    return s + value;
}

std::filesystem::path writeBlockedMetaImage(const std::filesystem::path& dir) {
    const std::filesystem::path header = dir / "hang.mhd";
    std::ofstream(header) << "ObjectType = Image\nNDims = 3\nDimSize = 4 4 2\n"
                             "ElementType = MET_UCHAR\nElementDataFile = LIST\n"
                             "s0.raw\ns1.raw\n";
    std::ofstream(dir / "s0.raw", std::ios::binary) << std::string(16, '\x10');
    EXPECT_EQ(::mkfifo((dir / "s1.raw").c_str(), 0600), 0);
    return header;
}

void writeTiltedCtSeries(const std::filesystem::path& dir, int slices) {
    constexpr int kRows = 8, kColumns = 12;
    constexpr double kGapMm = 2.0, kTiltDegrees = 15.0;
    std::filesystem::create_directories(dir);
    const std::string series = "1.2.826.0.1.3680043.2.1143.99.7";
    for (int k = 0; k < slices; ++k) {
        const std::string sop = series + "." + std::to_string(k + 1);
        std::string meta = element(2, 1, "OB", std::string("\0\1", 2)) +
                           element(2, 2, "UI", "1.2.840.10008.5.1.4.1.1.2") +
                           element(2, 3, "UI", sop) +
                           element(2, 0x10, "UI", "1.2.840.10008.1.2.1") +
                           element(2, 0x12, "UI", "1.2.826.0.1.3680043.2.1143.1");
        std::string groupLength;
        putU32(groupLength, std::uint32_t(meta.size()));
        std::string pixels;
        for (int i = 0; i < kRows * kColumns; ++i)
            putU16(pixels, unsigned((i * 37 + k * 11) % 2000));
        std::ostringstream ipp;
        ipp << "-10\\" << -12.5 + kGapMm * k * std::tan(kTiltDegrees * 3.14159265358979 / 180.0)
            << "\\" << kGapMm * k;
        const std::string ds =
            element(8, 0x16, "UI", "1.2.840.10008.5.1.4.1.1.2") + element(8, 0x18, "UI", sop) +
            element(8, 0x60, "CS", "CT") + element(0x20, 0xd, "UI", series + ".1") +
            element(0x20, 0xe, "UI", series) + element(0x20, 0x13, "IS", std::to_string(k + 1)) +
            element(0x20, 0x32, "DS", ipp.str()) + element(0x20, 0x37, "DS", "1\\0\\0\\0\\1\\0") +
            element(0x28, 2, "US", u16(1)) + element(0x28, 4, "CS", "MONOCHROME2") +
            element(0x28, 0x10, "US", u16(kRows)) + element(0x28, 0x11, "US", u16(kColumns)) +
            element(0x28, 0x30, "DS", "0.75\\0.5") + element(0x28, 0x100, "US", u16(16)) +
            element(0x28, 0x101, "US", u16(12)) + element(0x28, 0x102, "US", u16(11)) +
            element(0x28, 0x103, "US", u16(1)) + element(0x28, 0x1052, "DS", "-1024") +
            element(0x28, 0x1053, "DS", "1") + element(0x7fe0, 0x10, "OW", pixels);
        const std::string bytes =
            std::string(128, '\0') + "DICM" + element(2, 0, "UL", groupLength) + meta + ds;
        std::ofstream f(dir / ("s" + std::to_string(k) + ".dcm"), std::ios::binary);
        f.write(bytes.data(), std::streamsize(bytes.size()));
    }
}

ShellResult runShell(const std::string& line, const std::filesystem::path& dir) {
    const std::filesystem::path errFile = dir / "stderr.txt";
    std::string cmd = line;
    cmd += " 2>'";
    cmd += errFile.string();
    cmd += "'";
    FILE* pipe = ::popen(cmd.c_str(), "r");
    std::string out;
    std::array<char, 4096> buf;
    while (std::size_t n = std::fread(buf.data(), 1, buf.size(), pipe)) out.append(buf.data(), n);
    const int status = ::pclose(pipe);
    std::ifstream ef(errFile);
    std::string err((std::istreambuf_iterator<char>(ef)), {});
    std::filesystem::remove(errFile);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out, err};
}

}  // namespace voxlight::test
