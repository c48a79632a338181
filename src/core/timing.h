// SPDX-License-Identifier: MIT
#pragma once
// Wall-clock timing and process memory, for stats JSON and benchmarks.
#include <chrono>

namespace voxlight::core {

class Stopwatch {
  public:
    Stopwatch() : start_(std::chrono::steady_clock::now()) {}
    double seconds() const {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    }
    void restart() { start_ = std::chrono::steady_clock::now(); }

  private:
    std::chrono::steady_clock::time_point start_;
};

/// Peak resident set size of this process in MiB (VmHWM from /proc/self/status; 0 if unavailable).
double peakRssMiB();

}  // namespace voxlight::core
