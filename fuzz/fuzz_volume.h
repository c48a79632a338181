// SPDX-License-Identifier: MIT
#pragma once
// The volume targets: io::readVolume as `voxlight info` calls it, then what `info --json` does
// with the result (value range, description printed as JSON: text that is not UTF-8 must have
// been escaped by the reader).
#include <nlohmann/json.hpp>

#include "fuzz_common.h"
#include "io/dicom_module.h"
#include "io/module_loader.h"
#include "io/volume_io.h"
#include "io/volume_module.h"

/// Before any input: the reader modules must load. A module that cannot (a stale one, or one a
/// concurrent build was rewriting) would turn every input into the same cheap InputError — a
/// run of millions of executions that tests nothing (5 December: 8.4 M dicom_series executions
/// at coverage 221 instead of ~1,700). So the target stops with one line instead.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
    using namespace voxlight::io;
    for (const auto& m : {detail::loadModule(volume_module::kFileName, volume_module::kEntryPoint,
                                             volume_module::kAbiVersion),
                          detail::loadModule(dicom_module::kFileName, dicom_module::kEntryPoint,
                                             dicom_module::kAbiVersion)})
        if (!m.api) {
            std::fprintf(stderr, "voxlight fuzz: a reader module does not load: %s\n",
                         m.error.c_str());
            std::abort();
        }
    return 0;
}

namespace voxlight::fuzz {

inline void loadLikeInfo(const std::filesystem::path& path, const io::ReadOptions& options = {}) {
    runLoader([&] {
        const core::Volume v = io::readVolume(path, options);
        const auto range = v.physicalRange();
        const nlohmann::json j = {
            {"description", v.description}, {"format", v.format}, {"range", {range[0], range[1]}}};
        (void)j.dump();
    });
}

/// One file named `name` in the scratch directory.
inline void loadSingleFile(const std::uint8_t* data, std::size_t size, const std::string& name) {
    loadLikeInfo(writeParts(data, size, {name}));
}

}  // namespace voxlight::fuzz
