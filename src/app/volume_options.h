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

/// The scene-keyed reading options as flags of the commands that take a scene or a volume
/// (render, scene, iso, view): --series, --strict-geometry and --nonfinite, each the --set of its
/// volume key, placed before the command's own --set. The loaders' messages name them ("select
/// with --series none"), and render refused them (probe).
struct VolumeShorthands {
    std::string series, nonFinite;
    bool strictGeometry = false;
    /// `sets` with the shorthands' overrides in front.
    std::vector<std::string> overrides(const std::vector<std::string>& sets) const;
};
std::shared_ptr<VolumeShorthands> addVolumeShorthands(CLI::App& sub);

}  // namespace voxlight::app
