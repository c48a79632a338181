// SPDX-License-Identifier: MIT
// The functions of volume_io.h in io: load the VTK module on first use and forward to it
// (volume_module.h says why VTK is not linked into io).
#include <mutex>

#include "core/error.h"
#include "io/module_loader.h"
#include "io/volume_io.h"
#include "io/volume_module.h"

namespace voxlight::io {

namespace {
namespace mod = volume_module;

/// The module's functions, loaded once per process (thread-safe); InputError naming `source` when
/// the module cannot be loaded.
const mod::Api& volumeModule(const std::string& source) {
    static std::once_flag once;
    static detail::LoadedModule loaded;
    std::call_once(once, [] {
        loaded = detail::loadModule(mod::kFileName, mod::kEntryPoint, mod::kAbiVersion);
        // One load counter in the process (module_loader.h): the module's reading children wait
        // for io's loads (the image preload), and its DICOM module load counts in io's counter.
        if (loaded.api)
            static_cast<const mod::Api*>(loaded.api)->useLoadCounter(detail::ownLoadCounter());
    });
    if (!loaded.api)
        throw InputError(source, "volume module",
                         "volume file support (VTK) is unavailable: " + loaded.error,
                         std::string("put ") + mod::kFileName +
                             " (built with voxlight) beside the voxlight executable");
    return *static_cast<const mod::Api*>(loaded.api);
}
}  // namespace

core::Volume readVolume(const std::filesystem::path& path, const ReadOptions& options,
                        const core::Progress& progress) {
    try {
        return volumeModule(path.string()).readVolume(path, options, progress);
    } catch (const InputError& e) {
        // core::Volume's own checks (orientation, sizes) know no file: name it here.
        if (e.source() == "volume")
            throw InputError(path.string(), e.field(), e.problem(), e.fix());
        throw;
    }
}

void writeVolume(const core::Volume& volume, const std::filesystem::path& path) {
    volumeModule(path.string()).writeVolume(volume, path);
}

void checkVolumeOutputPath(const std::filesystem::path& path) {
    volumeModule(path.string()).checkVolumeOutputPath(path);
}

std::vector<std::string> supportedVolumeFormats() {
    return volumeModule("voxlight").supportedVolumeFormats();
}

}  // namespace voxlight::io
