// SPDX-License-Identifier: MIT
#include "app/volume_options.h"

#include "app/cli_support.h"

namespace voxlight::app {

namespace {
/// --series, --strict-geometry and --nonfinite into `g`; `keys` adds the scene key each sets.
void addReadingChoices(CLI::Option_group& g, std::string& series, bool& strict,
                       std::string& nonFinite, bool keys) {
    g.add_option("--series", series,
                 std::string("DICOM: SeriesInstanceUID to read when a folder holds several "
                             "(\"none\" for files without one)") +
                     (keys ? "; --set volume.series=UID" : ""));
    g.add_flag("--strict-geometry", strict,
               std::string("DICOM: refuse a gantry-tilted or variably spaced series instead of "
                           "resampling it onto a regular grid (with a warning)") +
                   (keys ? "; --set volume.strict_geometry=true" : ""));
    g.add_option("--nonfinite", nonFinite,
                 std::string("NaN/Inf voxels: reject (default) or replace by the minimum") +
                     (keys ? "; --set volume.nonfinite=min" : ""))
        ->check(CLI::IsMember({"reject", "min"}));
}
}  // namespace

std::shared_ptr<VolumeOptions> addVolumeOptions(CLI::App& sub) {
    auto o = std::make_shared<VolumeOptions>();
    auto* g = sub.add_option_group("reading", "How to read the volume");
    g->add_option("--dims", o->dims, "Raw file: voxels per axis X,Y,Z")
        ->delimiter(',')
        ->expected(3);
    g->add_option("--type", o->type, "Raw file: voxel type")
        ->check(CLI::IsMember({"uint8", "int16", "uint16", "float32"}));
    g->add_option("--spacing", o->spacing, "Raw file: spacing X,Y,Z in mm")
        ->delimiter(',')
        ->expected(3);
    g->add_flag("--big-endian", o->bigEndian, "Raw file: big-endian voxels");
    g->add_option("--header-bytes", o->headerBytes, "Raw file: bytes to skip before the data")
        ->check(wholeNumber());
    addReadingChoices(*g, o->series, o->strictGeometry, o->nonFinite, false);
    return o;
}

std::shared_ptr<VolumeShorthands> addVolumeShorthands(CLI::App& sub) {
    auto o = std::make_shared<VolumeShorthands>();
    auto* g = sub.add_option_group("reading", "How to read the volume (scene keys volume.*)");
    addReadingChoices(*g, o->series, o->strictGeometry, o->nonFinite, true);
    return o;
}

std::vector<std::string> VolumeShorthands::overrides(const std::vector<std::string>& sets) const {
    std::vector<std::string> all;
    if (!series.empty()) all.push_back("volume.series=" + series);
    if (strictGeometry) all.push_back("volume.strict_geometry=true");
    if (!nonFinite.empty()) all.push_back("volume.nonfinite=" + nonFinite);
    all.insert(all.end(), sets.begin(), sets.end());
    return all;
}

io::ReadOptions VolumeOptions::readOptions() const {
    io::ReadOptions r;
    r.dicomSeriesUid = series;
    r.strictGeometry = strictGeometry;
    r.nonFinite =
        nonFinite == "min" ? io::NonFinitePolicy::ReplaceWithMin : io::NonFinitePolicy::Reject;
    const bool anyRaw =
        !dims.empty() || !type.empty() || !spacing.empty() || headerBytes > 0 || bigEndian;
    if (anyRaw) {
        if (dims.size() != 3 || type.empty())
            throw InputError("command line", "--dims/--type",
                             "a raw file needs both --dims X,Y,Z and --type",
                             "e.g. --dims 256,256,128 --type int16 --spacing 0.5,0.5,1");
        io::RawLayout l;
        l.dims = {dims[0], dims[1], dims[2]};
        l.type = type == "uint8"    ? core::VoxelType::UInt8
                 : type == "int16"  ? core::VoxelType::Int16
                 : type == "uint16" ? core::VoxelType::UInt16
                                    : core::VoxelType::Float32;
        if (spacing.size() == 3) l.spacing = {spacing[0], spacing[1], spacing[2]};
        l.bigEndian = bigEndian;
        l.headerBytes = headerBytes;
        r.raw = l;
    }
    return r;
}

}  // namespace voxlight::app
