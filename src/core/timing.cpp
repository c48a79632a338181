// SPDX-License-Identifier: MIT
#include "core/timing.h"

#include <malloc.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

namespace voxlight::core {

std::string durationText(double seconds) {
    // Capped at 10⁹ s (32 years): an estimate from a tiny fraction can be any size.
    const long long s = seconds > 0.0 ? std::llround(std::min(seconds, 1e9)) : 0;
    char text[64];
    if (s < 60)
        std::snprintf(text, sizeof text, "%lld s", s);
    else if (s < 3600)
        std::snprintf(text, sizeof text, "%lld min %02lld s", s / 60, s % 60);
    else
        std::snprintf(text, sizeof text, "%lld h %02lld min", s / 3600, (s % 3600) / 60);
    return text;
}

std::string progressTimes(double elapsedSeconds, double fraction) {
    std::string text = durationText(elapsedSeconds);
    if (fraction >= kEstimateFraction && fraction < 1.0)
        text += ", ≈ " + durationText(elapsedSeconds * (1.0 - fraction) / fraction) + " left";
    return text;
}

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
