// SPDX-License-Identifier: MIT
#include "support/test_support.h"

#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <random>

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

}  // namespace voxlight::test
