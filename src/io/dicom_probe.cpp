// SPDX-License-Identifier: MIT
// The cheap DICOM probes, without GDCM: io uses them to pick a reader (so probing a folder or an
// extension-less file does not load the GDCM module), and the GDCM module to pick the slices.
#include <array>
#include <cstring>
#include <fstream>
#include <system_error>

#include "core/files.h"
#include "io/dicom_series.h"

namespace voxlight::io::detail {

namespace fs = std::filesystem;

namespace {
/// looksLikeDicom() opens at most this many files of a directory (cheap probe; non-DICOM files such
/// as LICENSE.txt may come first in directory order).
constexpr int kProbeFiles = 16;
}  // namespace

bool looksLikeDicomFile(const fs::path& file, bool* hasPreamble) {
    if (core::isSpecialFile(file)) return false;  // a FIFO in the folder would block open()
    std::ifstream in(file, std::ios::binary);
    if (!in) return false;
    std::array<unsigned char, 132> head{};
    in.read(reinterpret_cast<char*>(head.data()), head.size());
    const std::streamsize n = in.gcount();
    if (n >= 132 && std::memcmp(head.data() + 128, "DICM", 4) == 0) {
        if (hasPreamble) *hasPreamble = true;
        return true;
    }
    if (hasPreamble) *hasPreamble = false;
    if (n < 8) return false;
    const unsigned group = head[0] | (head[1] << 8);
    const unsigned element = head[2] | (head[3] << 8);
    return (group == 0x0002 || group == 0x0008) && element < 0x0100;
}

bool looksLikeDicom(const fs::path& path) {
    std::error_code ec;
    if (fs::is_regular_file(path, ec)) return looksLikeDicomFile(path);
    if (!fs::is_directory(path, ec)) return false;
    int probed = 0;
    for (fs::directory_iterator it(path, ec), end; !ec && it != end && probed < kProbeFiles;
         it.increment(ec)) {
        std::error_code fec;
        if (!it->is_regular_file(fec)) continue;
        ++probed;
        if (looksLikeDicomFile(it->path())) return true;
    }
    return false;
}

}  // namespace voxlight::io::detail
