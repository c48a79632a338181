// SPDX-License-Identifier: MIT
#pragma once
// Command-line options that say how to read a volume (raw layout, DICOM series choice and geometry
// strictness, non-finite policy), shared by every subcommand that loads one.
#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "io/volume_io.h"

namespace voxlight::app {

class VolumeOptions {
  public:
    /// Converts the parsed options; throws InputError (source "command line") on inconsistent raw
    /// options.
    io::ReadOptions readOptions() const;

    std::vector<int> dims;
    std::string type;
    std::vector<double> spacing;
    bool bigEndian = false;
    std::uint64_t headerBytes = 0;
    std::string series;
    std::string nonFinite = "reject";
    bool strictGeometry = false;
};

std::shared_ptr<VolumeOptions> addVolumeOptions(CLI::App& sub);

}  // namespace voxlight::app
