// SPDX-License-Identifier: MIT
// NIfTI through the .nii.gz path. An input that starts with the gzip magic is written as is (damaged
// streams); any other is gzip-compressed here first, so that mutations reach the NIfTI header and
// data behind the decompressor instead of dying on the stream's CRC.
#include <zlib.h>

#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace voxlight::fuzz;
    if (size >= 2 && data[0] == 0x1f && data[1] == 0x8b) {
        loadSingleFile(data, size, "in.nii.gz");
        return 0;
    }
    clearScratch();
    const std::filesystem::path path = scratchDir() / "in.nii.gz";
    gzFile gz = gzopen(path.c_str(), "wb1");
    if (!gz || (size > 0 && gzwrite(gz, data, unsigned(size)) != int(size)) ||
        gzclose(gz) != Z_OK) {
        std::fprintf(stderr, "voxlight fuzz: cannot write %s\n", path.c_str());
        std::abort();
    }
    loadLikeInfo(path);
    return 0;
}
