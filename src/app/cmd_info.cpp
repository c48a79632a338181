// SPDX-License-Identifier: MIT
// voxlight info VOLUME [--json]: geometry, type, value range, orientation, modality.
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/cli_support.h"
#include "app/volume_options.h"
#include "core/timing.h"

namespace voxlight::app {

namespace {

nlohmann::json describe(const core::Volume& v, const std::string& path, double seconds) {
    const core::Geometry& g = v.geometry();
    const auto range = v.physicalRange();
    nlohmann::json j;
    j["path"] = path;
    j["format"] = v.format;
    j["dims"] = {g.dims.x, g.dims.y, g.dims.z};
    j["spacing_mm"] = {g.spacing.x, g.spacing.y, g.spacing.z};
    j["extent_mm"] = {g.extent().x, g.extent().y, g.extent().z};
    j["origin_mm"] = {g.origin.x, g.origin.y, g.origin.z};
    nlohmann::json dir = nlohmann::json::array();
    for (int c = 0; c < 3; ++c)
        dir.push_back({g.direction[c].x, g.direction[c].y, g.direction[c].z});
    j["direction_columns"] = dir;
    j["orientation"] = g.orientationCode();
    j["type"] = std::string(core::toString(v.type()));
    j["rescale"] = {{"slope", v.mapping.slope}, {"intercept", v.mapping.intercept}};
    j["unit"] = v.mapping.unit;
    j["range"] = {range[0], range[1]};
    j["modality"] = std::string(core::toString(v.modality));
    j["description"] = v.description;
    if (!v.warnings.empty()) j["warnings"] = v.warnings;  // also on stderr
    j["voxels"] = v.voxelCount();
    j["memory_mib"] = double(v.sizeBytes()) / (1024.0 * 1024.0);
    j["load_seconds"] = seconds;
    return j;
}

void printText(const nlohmann::json& j) {
    auto triple = [](const nlohmann::json& a, const char* sep) {
        std::ostringstream os;
        os << a[0].get<double>() << sep << a[1].get<double>() << sep << a[2].get<double>();
        return os.str();
    };
    std::printf("file:         %s\n", j["path"].get<std::string>().c_str());
    std::printf("format:       %s\n", j["format"].get<std::string>().c_str());
    std::printf("dims:         %d x %d x %d voxels (%.1f M)\n", j["dims"][0].get<int>(),
                j["dims"][1].get<int>(), j["dims"][2].get<int>(), j["voxels"].get<double>() / 1e6);
    std::printf("spacing:      %s mm\n", triple(j["spacing_mm"], " x ").c_str());
    std::printf("extent:       %s mm (first to last voxel centre)\n",
                triple(j["extent_mm"], " x ").c_str());
    std::printf("origin:       (%s) mm, patient LPS\n", triple(j["origin_mm"], ", ").c_str());
    std::printf("orientation:  %s  (axes i, j, k point to: ",
                j["orientation"].get<std::string>().c_str());
    for (int c = 0; c < 3; ++c)
        std::printf("%s[%s]", c ? ", " : "", triple(j["direction_columns"][c], " ").c_str());
    std::printf(")\n");
    std::printf("type:         %s, stored × %g + %g\n", j["type"].get<std::string>().c_str(),
                j["rescale"]["slope"].get<double>(), j["rescale"]["intercept"].get<double>());
    const std::string unit = j["unit"].get<std::string>();
    std::printf("range:        %g .. %g%s%s\n", j["range"][0].get<double>(),
                j["range"][1].get<double>(), unit.empty() ? "" : " ", unit.c_str());
    std::printf("modality:     %s\n", j["modality"].get<std::string>().c_str());
    std::printf("description:  %s\n", j["description"].get<std::string>().c_str());
    std::printf("memory:       %.1f MiB (loaded in %.2f s)\n", j["memory_mib"].get<double>(),
                j["load_seconds"].get<double>());
}

}  // namespace

Command addInfoCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand(
        "info", "Print a volume's geometry, type, value range, orientation and modality");
    auto path = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto quiet = std::make_shared<bool>(false);
    c.sub->add_option("VOLUME", *path, "Volume file or DICOM series folder")->required();
    c.sub->add_flag("--json", *json, "Print JSON instead of text");
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output");
    auto vopts = addVolumeOptions(*c.sub);
    c.run = [=] {
        core::Stopwatch sw;
        const core::Volume v =
            io::readVolume(*path, vopts->readOptions(), terminalProgress(*quiet || *json));
        for (const auto& w : v.warnings) std::fprintf(stderr, "voxlight: warning: %s\n", w.c_str());
        const nlohmann::json j = describe(v, *path, sw.seconds());
        if (*json)
            std::cout << jsonForStdout(j, *path) << "\n";
        else
            printText(j);
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
