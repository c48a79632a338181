// SPDX-License-Identifier: MIT
#pragma once
// The volume targets: io::readVolume as `voxlight info` calls it, then what `info --json` does
// with the result (value range, description printed as JSON: text that is not UTF-8 must have
// been escaped by the reader).
#include <nlohmann/json.hpp>

#include "fuzz_common.h"
#include "io/volume_io.h"

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
