// SPDX-License-Identifier: MIT
#include "core/timing.h"

#include <malloc.h>

#include <fstream>
#include <string>

namespace voxlight::core {

double peakRssMiB() {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line)) {
        if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;  // kB
    }
    return 0.0;
}

void retainFreedMemory() {
    // glibc caps M_MMAP_THRESHOLD at 32 MiB on 64-bit (HEAP_MAX_SIZE / 2); both settings are
    // needed: the threshold alone still trims the heap, the trim threshold alone still maps and
    // unmaps every block over the (adaptive) mmap threshold.
    constexpr int kMmapThreshold = 32 << 20;
    constexpr int kTrimThreshold = 1 << 30;
    mallopt(M_MMAP_THRESHOLD, kMmapThreshold);
    mallopt(M_TRIM_THRESHOLD, kTrimThreshold);
}

}  // namespace voxlight::core
