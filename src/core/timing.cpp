// SPDX-License-Identifier: MIT
#include "core/timing.h"

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

}  // namespace voxlight::core
