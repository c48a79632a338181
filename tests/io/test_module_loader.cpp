// SPDX-License-Identifier: MIT
// The lazily loaded modules (src/io/module_loader.h): found from a test executable's directory,
// refused when stale, and a missing one is an error that says where it looked.
#include <gtest/gtest.h>

#include <tuple>

#include "io/dicom_module.h"
#include "io/image_module.h"
#include "io/module_loader.h"
#include "io/volume_module.h"

using namespace voxlight;

TEST(ModuleLoader, EveryModuleOfThisBuildLoads) {
    for (const auto& [file, entry, abi] :
         {std::tuple{io::image_module::kFileName, io::image_module::kEntryPoint,
                     io::image_module::kAbiVersion},
          std::tuple{io::dicom_module::kFileName, io::dicom_module::kEntryPoint,
                     io::dicom_module::kAbiVersion},
          std::tuple{io::volume_module::kFileName, io::volume_module::kEntryPoint,
                     io::volume_module::kAbiVersion}}) {
        const auto m = io::detail::loadModule(file, entry, abi);
        EXPECT_NE(m.api, nullptr) << file << ": " << m.error;
        EXPECT_TRUE(m.error.empty()) << m.error;
    }
}

TEST(ModuleLoader, MissingModuleListsWhereItLooked) {
    const auto m = io::detail::loadModule("libvoxlight_no_such_module.so", "entry", 1);
    EXPECT_EQ(m.api, nullptr);
    EXPECT_NE(m.error.find("libvoxlight_no_such_module.so (not found)"), std::string::npos)
        << m.error;
    // Beside the test executable, then the build directory: two places.
    EXPECT_NE(m.error.find(", "), std::string::npos) << m.error;
}

TEST(ModuleLoader, StaleModuleIsRefused) {
    const auto wrongAbi =
        io::detail::loadModule(io::image_module::kFileName, io::image_module::kEntryPoint,
                               io::image_module::kAbiVersion + 1);
    EXPECT_EQ(wrongAbi.api, nullptr);
    EXPECT_NE(wrongAbi.error.find("ABI version"), std::string::npos) << wrongAbi.error;
    const auto wrongEntry =
        io::detail::loadModule(io::image_module::kFileName, "voxlight_no_such_entry", 1);
    EXPECT_EQ(wrongEntry.api, nullptr);
    EXPECT_NE(wrongEntry.error.find("no entry point"), std::string::npos) << wrongEntry.error;
}
