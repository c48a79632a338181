// SPDX-License-Identifier: MIT
#pragma once
// Wall-clock timing and process memory, for stats JSON and benchmarks.
#include <chrono>
#include <string>

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

/// A duration for people: whole seconds under a minute ("42 s"), then minutes and seconds
/// ("3 min 05 s"), then hours and minutes ("2 h 07 min"); negative or NaN reads as 0 s, and
/// anything past 10⁹ s (an estimate from a tiny fraction) as 10⁹ s.
std::string durationText(double seconds);

/// What a progress line shows after its percentage: the stage's time so far and, once at least
/// kEstimateFraction of it is done (an earlier rate says little: set-up, the first cache misses),
/// the time left at the rate so far — "12 s, ≈ 36 s left"; "12 s" alone before, and at or past
/// the end. A linear extrapolation: work whose later part is slower (adaptive passes) reads short.
std::string progressTimes(double elapsedSeconds, double fraction);
inline constexpr double kEstimateFraction = 0.01;

/// Peak resident set size of this process in MiB (VmHWM from /proc/self/status; 0 if unavailable).
double peakRssMiB();

/// Keeps the memory large buffers free mapped for the next ones (glibc: blocks up to its largest
/// mmap threshold, 32 MiB, come from the heap, and free memory is handed back only past 1 GiB).
/// Why: a TF update allocates ~45 MB of new fields (local and global visibility) per change, and
/// with glibc's defaults each change touched them as fresh pages — ≈ 8,700 page faults, several µs
/// each on this kind of VM; with this the bonsai TF update took 0.91–0.93× the time per
/// alternating pair (README, "Where we stand"). Peak memory is unchanged; memory freed stays with
/// the process for reuse (a reading child hands it back before capping itself: child_process.h).
/// Called once at start by voxlight's main and by the benchmarks that time repeated updates.
void retainFreedMemory();

}  // namespace voxlight::core
