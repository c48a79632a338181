// SPDX-License-Identifier: MIT
// The lazily loaded modules (src/io/module_loader.h): found from a test executable's directory,
// refused when stale, a missing one is an error that says where it looked, and a load on a
// background thread (the image preload) holds back the reading children's forks.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <thread>
#include <tuple>

#include "core/phantoms.h"
#include "io/dicom_module.h"
#include "io/image.h"
#include "io/image_module.h"
#include "io/module_loader.h"
#include "io/volume_io.h"
#include "io/volume_module.h"
#include "support/test_support.h"

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

// The counter the fork sites wait on (a dlopen's lock held by a thread the child lacks):
// awaitModuleLoads returns only once the last load has ended. The counter alone — that the fork
// sites see it is the test after next.
TEST(ModuleLoader, AwaitReturnsOnlyOnceTheLastLoadHasEnded) {
    io::detail::awaitModuleLoads();  // none running: returns at once
    io::detail::beginModuleLoad();
    std::atomic<bool> ended{false};
    std::thread loader([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
        ended = true;
        io::detail::endModuleLoad();
    });
    io::detail::awaitModuleLoads();
    EXPECT_TRUE(ended.load());
    loader.join();
}

// The CLI's preload beside a forked read (MetaImage and VTI are read in a child) and an image write
// right after it: the volume arrives whole, the image is written.
TEST(ModuleLoader, ImagePreloadBesideForkedReadsAndWrites) {
    test::TempDir tmp;
    core::PhantomOptions o;
    o.size = 20;
    const core::Volume v = core::makePhantom("torso", o);
    io::writeVolume(v, tmp / "v.mha");
    io::writeVolume(v, tmp / "v.vti");
    for (int round = 0; round < 2; ++round) {
        const io::ImageModulePreload preload;
        // A progress that can be cancelled: MetaImage is then read in a child too.
        const std::atomic<bool> cancel{false};
        const core::Progress progress({}, &cancel);
        for (const char* name : {"v.mha", "v.vti"}) {
            const core::Volume r = io::readVolume(tmp / name, {}, progress);
            ASSERT_EQ(r.dims(), v.dims()) << name;
            EXPECT_EQ(r.physicalRange(), v.physicalRange()) << name;
        }
        core::ImageRGBA image;
        image.width = image.height = 4;
        image.pixels.assign(4 * 4 * 4, 0.5f);
        io::writeImage(image, tmp / "i.png");
        EXPECT_TRUE(std::filesystem::exists(tmp / "i.png"));
    }
}

// The fork sites themselves wait: a VTI read (in a child when it can be cancelled) started while
// a load is counted finishes only after that load has ended. The VTK reads and their fork sites
// live in libvoxlight_volume_vtk.so, built with its own copy of module_loader.cpp: this holds only
// because io hands the module its counter when loading it (volume_module::Api::useLoadCounter).
TEST(ModuleLoader, AReadingChildIsNotForkedDuringALoad) {
    test::TempDir tmp;
    core::PhantomOptions o;
    o.size = 12;
    io::writeVolume(core::makePhantom("torso", o), tmp / "v.vti");
    io::detail::beginModuleLoad();
    std::atomic<bool> loadEnded{false}, readDone{false}, readBeforeEnd{false};
    const std::atomic<bool> cancel{false};
    const core::Progress progress({}, &cancel);  // cancellable: the read runs in a child
    std::thread reader([&] {
        (void)io::readVolume(tmp / "v.vti", {}, progress);
        readBeforeEnd = !loadEnded.load();
        readDone = true;
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    EXPECT_FALSE(readDone.load()) << "the read went ahead while a module load was counted";
    loadEnded = true;
    io::detail::endModuleLoad();
    reader.join();
    EXPECT_TRUE(readDone.load());
    EXPECT_FALSE(readBeforeEnd.load());
}
