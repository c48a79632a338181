// SPDX-License-Identifier: MIT
// readDicomSeries in io: loads the GDCM module on first use and forwards to it (dicom_series.h says
// why GDCM is not linked into io).
#include <mutex>

#include "core/error.h"
#include "io/dicom_module.h"
#include "io/dicom_series.h"
#include "io/module_loader.h"

namespace voxlight::io::detail {

core::Volume readDicomSeries(const std::filesystem::path& path, const ReadOptions& options,
                             const core::Progress& progress) {
    namespace mod = dicom_module;
    static std::once_flag once;
    static LoadedModule loaded;
    std::call_once(once,
                   [] { loaded = loadModule(mod::kFileName, mod::kEntryPoint, mod::kAbiVersion); });
    if (!loaded.api)
        throw InputError(path.string(), "dicom module",
                         "DICOM support (GDCM) is unavailable: " + loaded.error,
                         std::string("put ") + mod::kFileName +
                             " (built with voxlight) beside the voxlight executable");
    return static_cast<const mod::Api*>(loaded.api)->readSeries(path, options, progress);
}

}  // namespace voxlight::io::detail
